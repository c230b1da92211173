#include "tools/model/islands.hpp"

#include "server/fem/supports.hpp"
#include "server/fusion/carve.hpp"
#include "server/fusion/inclusion.hpp"
#include "server/fusion/triangle_surface.hpp"

#include <algorithm>
#include <stdexcept>

namespace neurosim::model {

IslandReport find_islands(const mesh::TetMesh& host, const std::vector<int>& fixed_nodes,
                          const std::vector<const mesh::TetMesh*>& embedded,
                          const std::string& what, double max_fraction) {
  IslandReport r;
  std::vector<char> carve(host.num_tets(), 0);
  for (std::size_t k = 0; k < embedded.size(); ++k) {
    const auto surface =
        fusion::TriangleSurface::of(*embedded[k], what + " embedded[" + std::to_string(k) + "]");
    const fusion::NewBoundary boundary = fusion::find_new_boundary(host, surface);
    const std::vector<char> inside = fusion::tets_inside(host, boundary);
    for (std::size_t t = 0; t < inside.size(); ++t) carve[t] |= inside[t];
  }
  std::vector<mesh::Tet> kept;
  for (std::size_t t = 0; t < host.num_tets(); ++t) {
    if (carve[t]) {
      ++r.carved_tets;
    } else {
      kept.push_back(host.tets()[t]);
    }
  }
  if (kept.empty()) throw std::runtime_error(what + ": the host lies inside its embedded meshes");
  mesh::BuildOptions bo;
  bo.drop_unused_vertices = false;
  bo.source = what + " (carved)";
  const mesh::TetMesh carved = mesh::TetMesh::build(host.vertices(), kept, bo);
  // As the server: nodes left without a tetrahedron are fixed (inside the embedded mesh).
  std::vector<char> used(host.num_vertices(), 0);
  for (const auto& t : kept)
    for (int v : t) used[v] = 1;
  std::vector<int> fixed = fixed_nodes;
  for (std::size_t v = 0; v < used.size(); ++v)
    if (!used[v]) fixed.push_back(static_cast<int>(v));
  const auto parts = fem::unsupported_parts(carved, fixed, fem::Joint::kFace);
  for (const auto& p : parts) {
    if (static_cast<double>(p.nodes.size()) >
        max_fraction * static_cast<double>(host.num_vertices())) {
      throw std::runtime_error(what + ": connected part " + std::to_string(p.part) + " (" +
                               std::to_string(p.nodes.size()) + " of " +
                               std::to_string(host.num_vertices()) + " nodes, first node " +
                               std::to_string(p.nodes.front()) + ") " + p.problem +
                               ": too large to be an island; the fixed region is wrong");
    }
    r.part_nodes.push_back(static_cast<int>(p.nodes.size()));
    r.pinned_nodes.insert(r.pinned_nodes.end(), p.nodes.begin(), p.nodes.end());
  }
  std::sort(r.pinned_nodes.begin(), r.pinned_nodes.end());
  return r;
}

}  // namespace neurosim::model
