// A sub-model of a scene mesh: the tetrahedra whose centroid lies within a radius of a point (the
// face-connected piece holding the tetrahedron nearest the point), every node of a cut face
// clamped, the mesh's own surface and material kept. Used by contact_convergence_bench --region
// (a press's neighbourhood cut once, then split 1 -> 8 by tet_split.hpp as often as the memory
// allows: the refinement below the whole brain's reach, the surface fixed) and its ctest.
#pragma once

#include "tet_split.hpp"
#include "server/model/model.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace neurosim::bench {

// Cuts m in place to its tetrahedra with centroid within radius_m of centre_m (the
// face-connected piece of them around the tetrahedron whose centroid is nearest centre_m).
// Nodes on a cut face (a face whose neighbour across it was dropped) are the fixed nodes; a
// region holding a fixed node of the mesh (the brain's clamped base) is refused unless
// keep_pinned, when such a node stays fixed (the bundled brain pins the nodes of a fragment that
// carving around the artery cuts off, one of them 16 mm from the top); the tetrahedra keep their
// labels and materials.
// Returns the cut faces (the clamp: split_region keeps exactly these clamped, and the pinned
// nodes).
inline std::vector<mesh::Tri> cut_region(scene::LoadedMesh& m, const mesh::Vec3& centre_m, double radius_m,
                                         bool keep_pinned = false) {
  const auto& x = m.mesh.vertices();
  const auto& tets = m.mesh.tets();
  const auto& nb = m.mesh.neighbours();
  const std::size_t nt = tets.size();
  auto centroid = [&](std::size_t t) {
    return 0.25 * (x[tets[t][0]] + x[tets[t][1]] + x[tets[t][2]] + x[tets[t][3]]);
  };
  std::vector<char> inside(nt, 0);
  std::size_t seed = nt;
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t t = 0; t < nt; ++t) {
    const double d = (centroid(t) - centre_m).norm();
    inside[t] = d <= radius_m;
    if (d < best) best = d, seed = t;
  }
  if (seed == nt || !inside[seed]) throw std::invalid_argument("cut_region: no tetrahedron within the radius");
  // The face-connected piece around the seed.
  std::vector<char> kept(nt, 0);
  std::vector<std::size_t> stack{seed};
  kept[seed] = 1;
  while (!stack.empty()) {
    const std::size_t t = stack.back();
    stack.pop_back();
    for (int k = 0; k < 4; ++k) {
      const int u = nb[t][k];
      if (u >= 0 && inside[u] && !kept[u]) kept[u] = 1, stack.push_back(static_cast<std::size_t>(u));
    }
  }
  // New numbering; the cut faces' nodes clamped.
  std::vector<int> id(x.size(), -1);
  std::vector<char> fixed(x.size(), 0);
  for (int v : m.fixed_nodes) fixed[v] = 1;
  std::vector<char> cut(x.size(), 0);
  std::vector<mesh::Tri> cut_faces;
  std::vector<mesh::Vec3> nx;
  std::vector<mesh::Tet> nt_list;
  std::vector<int> labels, materials;
  for (std::size_t t = 0; t < nt; ++t) {
    if (!kept[t]) continue;
    for (int k = 0; k < 4; ++k) {
      const int u = nb[t][k];
      if (u >= 0 && !kept[u]) {
        mesh::Tri f{};
        int c = 0;
        for (int j = 0; j < 4; ++j)
          if (j != k) cut[tets[t][j]] = 1, f[c++] = tets[t][j];
        cut_faces.push_back(f);  // old numbering until below
      }
    }
    mesh::Tet q{};
    for (int j = 0; j < 4; ++j) {
      int& v = id[tets[t][j]];
      if (v < 0) v = static_cast<int>(nx.size()), nx.push_back(x[tets[t][j]]);
      q[j] = v;
    }
    nt_list.push_back(q);
    if (!m.mesh.tet_labels().empty()) labels.push_back(m.mesh.tet_labels()[t]);
    if (!m.materials.tet_material.empty()) materials.push_back(m.materials.tet_material[t]);
  }
  std::vector<int> fixed_nodes;
  for (std::size_t v = 0; v < x.size(); ++v) {
    if (id[v] >= 0 && fixed[v] && !cut[v] && !keep_pinned)
      throw std::invalid_argument("cut_region: the region holds a clamped node of the mesh (mesh node " +
                                  std::to_string(v) + ")");
    if (id[v] >= 0 && (cut[v] || fixed[v])) fixed_nodes.push_back(id[v]);
  }
  for (auto& f : cut_faces)
    for (int& v : f) v = id[v];
  std::sort(fixed_nodes.begin(), fixed_nodes.end());
  mesh::BuildOptions options;
  options.drop_unused_vertices = false;
  options.source = "region of " + std::to_string(nt) + " tetrahedra";
  mesh::TetMesh out = mesh::TetMesh::build(std::move(nx), std::move(nt_list), options);
  if (!labels.empty()) out.set_tet_labels(std::move(labels));
  m.mesh = std::move(out);
  m.fixed_nodes = std::move(fixed_nodes);
  if (!materials.empty()) m.materials.tet_material = std::move(materials);
  return cut_faces;
}

// A sub-model split 1 -> 8 in place (tet_split.hpp): materials follow their parents, and a new
// node is fixed exactly when it is the midpoint of an edge of a cut face (each cut face becomes
// its four children in cut_faces), not of any other edge between two clamped nodes (the rim of
// the cut on the surface, edges through the inside: split_loaded_mesh would clamp those), so the
// clamp is the same surface at every split.
inline void split_region(scene::LoadedMesh& m, std::vector<mesh::Tri>& cut_faces) {
  SplitMesh s = split_tets(m.mesh);
  const int n = static_cast<int>(m.mesh.vertices().size());
  auto key = [](int a, int b) {
    if (a > b) std::swap(a, b);
    return (static_cast<std::uint64_t>(a) << 32) | static_cast<std::uint32_t>(b);
  };
  std::unordered_map<std::uint64_t, int> mid;
  for (std::size_t k = 0; k < s.edge_ends.size(); ++k) mid.emplace(key(s.edge_ends[k][0], s.edge_ends[k][1]), n + static_cast<int>(k));
  std::vector<char> fixed(s.mesh.num_vertices(), 0);
  for (int v : m.fixed_nodes) fixed[v] = 1;
  std::vector<mesh::Tri> children;
  children.reserve(4 * cut_faces.size());
  for (const auto& f : cut_faces) {
    const int a = f[0], b = f[1], c = f[2];
    const int ab = mid.at(key(a, b)), bc = mid.at(key(b, c)), ca = mid.at(key(c, a));
    fixed[ab] = fixed[bc] = fixed[ca] = 1;
    children.push_back({a, ab, ca});
    children.push_back({ab, b, bc});
    children.push_back({ca, bc, c});
    children.push_back({ab, bc, ca});
  }
  cut_faces = std::move(children);
  m.fixed_nodes.clear();
  for (std::size_t v = 0; v < fixed.size(); ++v)
    if (fixed[v]) m.fixed_nodes.push_back(static_cast<int>(v));
  adopt_split(m, std::move(s));
}

}  // namespace neurosim::bench
