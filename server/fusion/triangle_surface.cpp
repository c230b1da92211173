#include "server/fusion/triangle_surface.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace neurosim::fusion {

TriangleSurface TriangleSurface::of(const mesh::TetMesh& mesh, std::string name) {
  TriangleSurface s;
  s.vertices_m = mesh.vertices();
  s.triangles = mesh.surface();
  s.name = name.empty() ? mesh.source() : std::move(name);
  return s;
}

std::vector<OpenEdge> open_edges(const TriangleSurface& surface) {
  // Sort the undirected edges; a run of odd length is an open edge.
  std::vector<std::pair<int, int>> edges;
  edges.reserve(surface.triangles.size() * 3);
  for (const Tri& t : surface.triangles) {
    for (int k = 0; k < 3; ++k) {
      const int a = t[k];
      const int b = t[(k + 1) % 3];
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  std::vector<OpenEdge> open;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i + 1;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if ((j - i) % 2 == 1) {
      open.push_back({edges[i].first, edges[i].second, static_cast<int>(j - i)});
    }
    i = j;
  }
  return open;
}

void validate_closed(const TriangleSurface& surface) {
  const std::string& name = surface.name;
  if (surface.triangles.empty()) {
    throw std::invalid_argument("surface '" + name + "': no triangles");
  }
  const int n = static_cast<int>(surface.vertices_m.size());
  for (std::size_t i = 0; i < surface.triangles.size(); ++i) {
    const Tri& t = surface.triangles[i];
    for (int k = 0; k < 3; ++k) {
      if (t[k] < 0 || t[k] >= n) {
        throw std::invalid_argument("surface '" + name + "': triangle " + std::to_string(i) +
                                    " has vertex index " + std::to_string(t[k]) +
                                    " out of range [0, " + std::to_string(n) + ")");
      }
      if (!surface.vertices_m[t[k]].allFinite()) {
        throw std::invalid_argument("surface '" + name + "': vertex " + std::to_string(t[k]) +
                                    " (triangle " + std::to_string(i) +
                                    ") has a non-finite coordinate");
      }
    }
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      throw std::invalid_argument("surface '" + name + "': triangle " + std::to_string(i) +
                                  " repeats a vertex");
    }
  }
  const std::vector<OpenEdge> open = open_edges(surface);
  if (!open.empty()) {
    std::ostringstream msg;
    msg << "surface '" << name << "' is not closed: " << open.size()
        << " open edge(s) (vertex pairs used by an odd number of triangles):";
    const std::size_t shown = std::min<std::size_t>(open.size(), 20);
    for (std::size_t i = 0; i < shown; ++i) {
      msg << " (" << open[i].v0 << "," << open[i].v1 << ")x" << open[i].triangles;
    }
    if (shown < open.size()) msg << " ... (" << open.size() - shown << " more)";
    throw std::invalid_argument(msg.str());
  }
}

}  // namespace neurosim::fusion
