// Uniform 1 -> 8 refinement of a tetrahedral mesh: a node at every edge's midpoint, each
// tetrahedron cut into its four corner tetrahedra and the inner octahedron's four (along the
// octahedron's shortest diagonal). The boundary surface stays exactly where it was (each
// surface triangle becomes four in its own plane): a refinement of the discretization alone,
// the geometry fixed. Used by contact_convergence_bench --split (the contact force's order
// without the mesher's change of surface) and its ctest.
#pragma once

#include "server/model/model.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace neurosim::bench {

struct SplitMesh {
  mesh::TetMesh mesh;
  // The mesh's vertices keep their indices; vertex n + k is the midpoint of edge k, whose two
  // end vertices are edge_ends[k].
  std::vector<std::array<int, 2>> edge_ends;
  std::vector<int> parent_tet;  // per new tetrahedron: the tetrahedron it came from
};

// A node set carried onto the split mesh: its nodes and the midpoint of every edge between two
// of them (a held patch stays the same surface), in ascending order of the split mesh's ids.
inline std::vector<int> split_node_set(const SplitMesh& s, const std::vector<int>& nodes) {
  const std::size_t n = s.mesh.num_vertices() - s.edge_ends.size();
  std::vector<char> in(n, 0);
  for (int v : nodes) in[static_cast<std::size_t>(v)] = 1;
  std::vector<int> out;
  for (std::size_t v = 0; v < n; ++v)
    if (in[v]) out.push_back(static_cast<int>(v));
  for (std::size_t k = 0; k < s.edge_ends.size(); ++k)
    if (in[static_cast<std::size_t>(s.edge_ends[k][0])] && in[static_cast<std::size_t>(s.edge_ends[k][1])])
      out.push_back(static_cast<int>(n + k));
  return out;
}

inline SplitMesh split_tets(const mesh::TetMesh& in) {
  std::vector<mesh::Vec3> x = in.vertices();
  std::unordered_map<std::uint64_t, int> edge_node;
  SplitMesh out{};
  auto mid = [&](int a, int b) {
    if (a > b) std::swap(a, b);
    const std::uint64_t key = (static_cast<std::uint64_t>(a) << 32) | static_cast<std::uint32_t>(b);
    const auto it = edge_node.find(key);
    if (it != edge_node.end()) return it->second;
    const int id = static_cast<int>(x.size());
    x.push_back(0.5 * (x[a] + x[b]));
    out.edge_ends.push_back({a, b});
    edge_node.emplace(key, id);
    return id;
  };
  std::vector<mesh::Tet> tets;
  tets.reserve(8 * in.tets().size());
  out.parent_tet.reserve(8 * in.tets().size());
  auto add = [&](int a, int b, int c, int d, int parent) {
    // Positive volume (TetMesh's order): swap two vertices of an inverted one.
    if ((x[b] - x[a]).cross(x[c] - x[a]).dot(x[d] - x[a]) < 0.0) std::swap(c, d);
    tets.push_back(mesh::Tet{a, b, c, d});
    out.parent_tet.push_back(parent);
  };
  for (std::size_t t = 0; t < in.tets().size(); ++t) {
    const auto& v = in.tets()[t];
    const int p = static_cast<int>(t);
    const int a = v[0], b = v[1], c = v[2], d = v[3];
    const int ab = mid(a, b), ac = mid(a, c), ad = mid(a, d), bc = mid(b, c), bd = mid(b, d), cd = mid(c, d);
    add(a, ab, ac, ad, p);
    add(ab, b, bc, bd, p);
    add(ac, bc, c, cd, p);
    add(ad, bd, cd, d, p);
    // The octahedron ab ac ad bc bd cd: three diagonals (ab-cd, ac-bd, ad-bc); the shortest.
    const std::array<std::array<int, 2>, 3> diag{{{ab, cd}, {ac, bd}, {ad, bc}}};
    int k = 0;
    for (int j = 1; j < 3; ++j)
      if ((x[diag[j][0]] - x[diag[j][1]]).squaredNorm() < (x[diag[k][0]] - x[diag[k][1]]).squaredNorm()) k = j;
    // The four other octahedron vertices form a cycle around the diagonal.
    std::array<int, 4> ring{};
    if (k == 0) ring = {ac, ad, bd, bc};
    if (k == 1) ring = {ab, ad, cd, bc};
    if (k == 2) ring = {ab, ac, cd, bd};
    for (int j = 0; j < 4; ++j) add(diag[k][0], diag[k][1], ring[j], ring[(j + 1) % 4], p);
  }
  mesh::BuildOptions options;
  options.drop_unused_vertices = false;
  options.source = "split of " + std::to_string(in.tets().size()) + " tetrahedra";
  out.mesh = mesh::TetMesh::build(std::move(x), std::move(tets), options);
  if (!in.tet_labels().empty()) {
    std::vector<int> labels(out.parent_tet.size());
    for (std::size_t t = 0; t < labels.size(); ++t) labels[t] = in.tet_labels()[out.parent_tet[t]];
    out.mesh.set_tet_labels(std::move(labels));
  }
  return out;
}

// A scene mesh takes its split: each tetrahedron's material follows its parent, the generator's
// cell size halves (the caller sets the fixed nodes).
inline void adopt_split(scene::LoadedMesh& m, SplitMesh s) {
  if (!m.materials.tet_material.empty()) {
    std::vector<int> per(s.parent_tet.size());
    for (std::size_t t = 0; t < per.size(); ++t) per[t] = m.materials.tet_material[s.parent_tet[t]];
    m.materials.tet_material = std::move(per);
  }
  m.mesh = std::move(s.mesh);
  m.generator_cell_size_m *= 0.5;
}

// A scene mesh split 1 -> 8 in place: its tetrahedra's materials follow their parents, a new
// node is fixed when both ends of its edge are (the clamped faces stay clamped, nothing more),
// the generator's cell size halves.
inline void split_loaded_mesh(scene::LoadedMesh& m) {
  SplitMesh s = split_tets(m.mesh);
  const int n = static_cast<int>(m.mesh.vertices().size());
  std::vector<char> fixed(m.mesh.vertices().size(), 0);
  for (int v : m.fixed_nodes) fixed[v] = 1;
  for (std::size_t k = 0; k < s.edge_ends.size(); ++k)
    if (fixed[s.edge_ends[k][0]] && fixed[s.edge_ends[k][1]]) m.fixed_nodes.push_back(n + static_cast<int>(k));
  std::sort(m.fixed_nodes.begin(), m.fixed_nodes.end());
  adopt_split(m, std::move(s));
}

}  // namespace neurosim::bench
