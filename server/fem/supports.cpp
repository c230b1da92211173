#include "server/fem/supports.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <numeric>

namespace neurosim::fem {

// Union-find over nodes joined by tetrahedra.
std::vector<int> connected_parts(const mesh::TetMesh& mesh, int& num_parts) {
  const int n = static_cast<int>(mesh.num_vertices());
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int v) {
    while (parent[v] != v) {
      v = parent[v] = parent[parent[v]];
    }
    return v;
  };
  for (const auto& t : mesh.tets()) {
    for (int a = 1; a < 4; ++a) {
      const int r0 = find(t[0]), r1 = find(t[a]);
      if (r0 != r1) {
        parent[std::max(r0, r1)] = std::min(r0, r1);
      }
    }
  }
  std::vector<int> part(n, -1), root_part(n, -1);
  num_parts = 0;
  for (int v = 0; v < n; ++v) {
    const int r = find(v);
    if (root_part[r] < 0) {
      root_part[r] = num_parts++;
    }
    part[v] = root_part[r];
  }
  return part;
}

std::vector<UnsupportedPart> unsupported_parts(const mesh::TetMesh& mesh,
                                               const std::vector<int>& fixed_nodes, Joint joint) {
  const int n = static_cast<int>(mesh.num_vertices());
  std::vector<char> is_fixed(n, 0);
  for (int v : fixed_nodes) is_fixed[v] = 1;
  int num_parts = 0;
  std::vector<std::vector<int>> nodes;
  if (joint == Joint::kNode) {
    std::vector<char> used(n, 0);
    for (const auto& t : mesh.tets()) {
      for (int a : t) used[a] = 1;
    }
    const std::vector<int> part = connected_parts(mesh, num_parts);
    nodes.resize(num_parts);
    for (int v = 0; v < n; ++v) {
      if (used[v]) nodes[part[v]].push_back(v);
    }
  } else {
    // Tetrahedra joined through faces (flood over neighbours), then each part's nodes.
    const int nt = static_cast<int>(mesh.num_tets());
    std::vector<int> tet_part(nt, -1), stack;
    for (int t0 = 0; t0 < nt; ++t0) {
      if (tet_part[t0] >= 0) continue;
      const int p = num_parts++;
      nodes.emplace_back();
      tet_part[t0] = p;
      stack.push_back(t0);
      while (!stack.empty()) {
        const int t = stack.back();
        stack.pop_back();
        for (int a : mesh.tets()[t]) nodes[p].push_back(a);
        for (int k = 0; k < 4; ++k) {
          const int nb = mesh.neighbours()[t][k];
          if (nb >= 0 && tet_part[nb] < 0) {
            tet_part[nb] = p;
            stack.push_back(nb);
          }
        }
      }
      std::sort(nodes[p].begin(), nodes[p].end());
      nodes[p].erase(std::unique(nodes[p].begin(), nodes[p].end()), nodes[p].end());
    }
  }
  const auto& x = mesh.vertices();
  // "" when the nodes hold a part (>= 3 non-collinear), else what is free.
  auto problem_of = [&x](const std::vector<int>& held) -> std::string {
    if (held.empty()) return "has no fixed node (6 rigid-body modes)";
    if (held.size() == 1) return "has only 1 fixed node (3 rotations free)";
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (int v : held) mean += x[v];
    mean /= static_cast<double>(held.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (int v : held) cov += (x[v] - mean) * (x[v] - mean).transpose();
    const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues();
    if (!(ev(1) > 1e-12 * ev(2))) {
      return "has only collinear fixed nodes (" + std::to_string(held.size()) +
             "): rotation about their line is free";
    }
    return "";
  };
  // A part is held by its fixed nodes and, with Joint::kFace, also by the nodes it shares with
  // parts already held (a part sharing 3 non-collinear nodes with a held part is held): repeated
  // until nothing changes.
  std::vector<char> anchored = is_fixed;
  std::vector<char> held(num_parts, 0);
  std::vector<int> anchors;
  for (bool changed = true; changed;) {
    changed = false;
    for (int p = 0; p < num_parts; ++p) {
      if (held[p] || nodes[p].empty()) continue;
      anchors.clear();
      for (int v : nodes[p]) {
        if (anchored[v]) anchors.push_back(v);
      }
      if (!problem_of(anchors).empty()) continue;
      held[p] = 1;
      if (joint == Joint::kFace) {
        for (int v : nodes[p]) anchored[v] = 1;
        changed = true;
      }
    }
  }
  std::vector<UnsupportedPart> out;
  for (int p = 0; p < num_parts; ++p) {
    if (held[p] || nodes[p].empty()) continue;
    std::vector<int> fx;
    for (int v : nodes[p]) {
      if (is_fixed[v]) fx.push_back(v);
    }
    std::string problem = problem_of(fx);
    out.push_back({p, std::move(nodes[p]), static_cast<int>(fx.size()), std::move(problem)});
  }
  return out;
}

}  // namespace neurosim::fem
