#include "server/fem/tet_element.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace neurosim::fem {

namespace {
constexpr double kPi = 3.14159265358979323846;

std::string element_label(int element_id) {
  return element_id >= 0 ? "tetrahedron " + std::to_string(element_id) : std::string("tetrahedron");
}
}  // namespace

TetGeometry tet_geometry(const TetNodes& x, int element_id) {
  for (int a = 0; a < 4; ++a) {
    if (!x[a].allFinite()) {
      std::ostringstream msg;
      msg << element_label(element_id) << ": non-finite coordinate at local node " << a << " ("
          << x[a].transpose() << ")";
      throw std::invalid_argument(msg.str());
    }
  }
  Eigen::Matrix3d j;  // columns: edges from node 0, so barycentric coords are J^-1 (x - x0)
  j.col(0) = x[1] - x[0];
  j.col(1) = x[2] - x[0];
  j.col(2) = x[3] - x[0];
  const double det = j.determinant();
  const double volume = det / 6.0;
  double longest2 = 0.0;
  for (int a = 0; a < 4; ++a) {
    for (int b = a + 1; b < 4; ++b) {
      longest2 = std::max(longest2, (x[a] - x[b]).squaredNorm());
    }
  }
  const double longest = std::sqrt(longest2);
  if (!(volume > kDegenerateVolumeRatio * longest * longest * longest)) {
    std::ostringstream msg;
    msg << element_label(element_id) << ": " << (volume < 0.0 ? "inverted" : "degenerate")
        << " (volume " << volume << " m^3, longest edge " << longest << " m)";
    throw std::invalid_argument(msg.str());
  }
  TetGeometry g;
  const Eigen::Matrix3d jinv = j.inverse();
  g.gradients.bottomRows<3>() = jinv;  // row k of J^-1 = grad N_{k+1}
  g.gradients.row(0) = -jinv.colwise().sum();
  g.volume_m3 = volume;
  return g;
}

Eigen::Matrix<double, 6, 12> strain_displacement(const TetGeometry& g) {
  Eigen::Matrix<double, 6, 12> b = Eigen::Matrix<double, 6, 12>::Zero();
  for (int a = 0; a < 4; ++a) {
    const double bx = g.gradients(a, 0), by = g.gradients(a, 1), bz = g.gradients(a, 2);
    const int c = 3 * a;
    b(0, c) = bx;
    b(1, c + 1) = by;
    b(2, c + 2) = bz;
    b(3, c) = by;
    b(3, c + 1) = bx;
    b(4, c + 1) = bz;
    b(4, c + 2) = by;
    b(5, c) = bz;
    b(5, c + 2) = bx;
  }
  return b;
}

void tet_stiffness(const TetGeometry& g, double lambda_pa, double mu_pa, ElementMatrix& k) {
  double grad[4][3];
  for (int a = 0; a < 4; ++a) {
    for (int i = 0; i < 3; ++i) {
      grad[a][i] = g.gradients(a, i);
    }
  }
  const double vl = g.volume_m3 * lambda_pa, vm = g.volume_m3 * mu_pa;
  double kab[3][3];
  for (int a = 0; a < 4; ++a) {
    for (int b = a; b < 4; ++b) {
      tet_stiffness_block(grad[a], grad[b], vl, vm, kab);
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          k(3 * a + i, 3 * b + j) = kab[i][j];
          k(3 * b + j, 3 * a + i) = kab[i][j];
        }
      }
    }
  }
}

ElementMatrix tet_stiffness(const TetNodes& x, const Material& material, int element_id) {
  material.validate();
  const TetGeometry g = tet_geometry(x, element_id);
  ElementMatrix k;
  tet_stiffness(g, material.lame_lambda_pa(), material.shear_modulus_pa(), k);
  return k;
}

double tet_strain_energy(const TetNodes& x, const Material& material, const ElementVector& u_m,
                         int element_id) {
  if (!u_m.allFinite()) {
    throw std::invalid_argument(element_label(element_id) + ": non-finite displacement");
  }
  const TetGeometry g = tet_geometry(x, element_id);
  const Eigen::Matrix<double, 6, 1> eps = strain_displacement(g) * u_m;
  return 0.5 * g.volume_m3 * eps.dot(elasticity_matrix(material) * eps);
}

TetQuality tet_quality(const TetNodes& x) {
  TetQuality q;
  q.volume_m3 = (x[1] - x[0]).cross(x[2] - x[0]).dot(x[3] - x[0]) / 6.0;
  double sum_sq = 0.0;
  q.shortest_edge_m = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 4; ++a) {
    for (int b = a + 1; b < 4; ++b) {
      const double l = (x[a] - x[b]).norm();
      sum_sq += l * l;
      q.longest_edge_m = std::max(q.longest_edge_m, l);
      q.shortest_edge_m = std::min(q.shortest_edge_m, l);
    }
  }
  const double l_rms = std::sqrt(sum_sq / 6.0);
  q.mean_ratio = l_rms > 0.0 ? 6.0 * std::sqrt(2.0) * q.volume_m3 / (l_rms * l_rms * l_rms) : 0.0;
  // Dihedral angle at edge (a, b) is the angle between the two faces through it; face k is
  // opposite node k, so edge (a, b) is shared by the faces opposite the other two nodes c, d.
  static constexpr int kPairs[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  std::array<Eigen::Vector3d, 4> n;  // outward-ish face normals (direction sign fixed below)
  for (int k = 0; k < 4; ++k) {
    const int i = (k + 1) % 4, j = (k + 2) % 4, l = (k + 3) % 4;
    Eigen::Vector3d nk = (x[j] - x[i]).cross(x[l] - x[i]);
    if (nk.dot(x[k] - x[i]) > 0.0) {
      nk = -nk;  // point away from the opposite node
    }
    const double len = nk.norm();
    n[k] = len > 0.0 ? Eigen::Vector3d(nk / len) : Eigen::Vector3d::Zero();
  }
  q.min_dihedral_deg = 180.0;
  q.max_dihedral_deg = 0.0;
  for (const auto& p : kPairs) {
    int c = -1, d = -1;
    for (int k = 0; k < 4; ++k) {
      if (k == p[0] || k == p[1]) {
        continue;
      }
      (c < 0 ? c : d) = k;
    }
    const double cosang = std::clamp(-n[c].dot(n[d]), -1.0, 1.0);
    const double deg = std::acos(cosang) * 180.0 / kPi;
    q.min_dihedral_deg = std::min(q.min_dihedral_deg, deg);
    q.max_dihedral_deg = std::max(q.max_dihedral_deg, deg);
  }
  return q;
}

}  // namespace neurosim::fem
