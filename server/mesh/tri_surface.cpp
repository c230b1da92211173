// Closedness of a triangle surface: every undirected edge counted with its directions.
#include "server/mesh/tri_surface.hpp"

#include <algorithm>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <utility>

namespace neurosim::mesh {

ClosedSurfaceReport check_closed(const std::vector<Vec3>& x, const std::vector<Tri>& tris) {
  ClosedSurfaceReport r;
  r.triangles = static_cast<int>(tris.size());
  const long long nv = static_cast<long long>(x.size());
  // (low, high, +1 when traversed low -> high else -1), sorted to group each edge.
  struct HalfEdge {
    int lo, hi, dir, tri;
  };
  std::vector<HalfEdge> half;
  half.reserve(3 * tris.size());
  for (std::size_t t = 0; t < tris.size(); ++t) {
    const Tri& f = tris[t];
    bool bad = false;
    for (int k = 0; k < 3; ++k) bad = bad || f[k] < 0 || f[k] >= nv || f[k] == f[(k + 1) % 3];
    if (bad) {
      if (r.degenerate_triangles++ == 0)
        r.first_problem = "triangle " + std::to_string(t) + " repeats a vertex or indexes none";
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      const int a = f[k], b = f[(k + 1) % 3];
      half.push_back({std::min(a, b), std::max(a, b), a < b ? 1 : -1, static_cast<int>(t)});
    }
    // Divergence theorem: sum of a . (b x c) / 6 over outward triangles.
    r.volume_m3 += x[f[0]].dot(x[f[1]].cross(x[f[2]])) / 6.0;
  }
  std::sort(half.begin(), half.end(), [](const HalfEdge& p, const HalfEdge& q) {
    return std::tie(p.lo, p.hi, p.dir) < std::tie(q.lo, q.hi, q.dir);
  });
  auto note = [&](const char* what, const HalfEdge& e, std::size_t uses) {
    if (!r.first_problem.empty()) return;
    std::ostringstream m;
    m << "edge (" << e.lo << ", " << e.hi << ") of triangle " << e.tri << " is " << what << " ("
      << uses << " triangle" << (uses == 1 ? "" : "s") << ")";
    r.first_problem = m.str();
  };
  for (std::size_t i = 0; i < half.size();) {
    std::size_t j = i;
    int sum = 0;
    while (j < half.size() && half[j].lo == half[i].lo && half[j].hi == half[i].hi)
      sum += half[j++].dir;
    const std::size_t uses = j - i;
    ++r.edges;
    if (uses == 1) {
      ++r.boundary_edges;
      note("on a hole", half[i], uses);
    } else if (uses > 2) {
      ++r.nonmanifold_edges;
      note("non-manifold", half[i], uses);
    } else if (sum != 0) {
      ++r.misoriented_edges;
      note("traversed twice in the same direction (inconsistent orientation)", half[i], uses);
    }
    i = j;
  }
  return r;
}

void require_closed_outward(const std::vector<Vec3>& vertices_m, const std::vector<Tri>& triangles,
                            const std::string& source) {
  const ClosedSurfaceReport r = check_closed(vertices_m, triangles);
  if (r.triangles == 0) throw std::runtime_error(source + ": not a closed surface: no triangles");
  if (!r.closed()) {
    std::ostringstream m;
    m << source << ": not a closed, consistently oriented surface: " << r.boundary_edges
      << " boundary, " << r.nonmanifold_edges << " non-manifold and " << r.misoriented_edges
      << " inconsistently oriented edges, " << r.degenerate_triangles
      << " degenerate triangles; first: " << r.first_problem;
    throw std::runtime_error(m.str());
  }
  if (!(r.volume_m3 > 0.0)) {
    std::ostringstream m;
    m << source << ": closed surface with enclosed volume " << r.volume_m3
      << " m^3 <= 0: its triangles face inward (reverse their orientation)";
    throw std::runtime_error(m.str());
  }
}

}  // namespace neurosim::mesh
