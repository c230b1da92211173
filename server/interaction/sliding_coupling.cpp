#include "server/interaction/sliding_coupling.hpp"

#include "server/fem/assembly.hpp"
#include "server/fem/static_solver.hpp"

#include <Eigen/QR>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace neurosim::interaction {

namespace {
// Right-hand sides per block solve when W_B is built.
constexpr int kBlock = 63;
}  // namespace

struct EmbeddedCompliance::Floating {
  std::vector<int> reduced;                         // dof -> index in the support's system or -1
  Eigen::SimplicialLDLT<fem::SparseMatrix> factor;  // K_B with six dofs held (determinate)
  Eigen::MatrixXd r;                                // 3N x 6 orthonormal rigid modes
  double kappa{0.0};                                // anchor stiffness per rigid mode, N/m
};

EmbeddedCompliance::EmbeddedCompliance(const mesh::TetMesh& mesh, const fem::Material& material,
                                       const std::vector<int>& fixed, double anchor_ratio,
                                       const std::string& what)
    : what_(what), dofs_(3 * static_cast<int>(mesh.num_vertices())) {
  const auto materials = fem::MaterialMap::uniform(material);
  if (!fixed.empty()) {
    try {
      solver_ = std::make_unique<fem::StaticSolver>(mesh, materials, fixed);
    } catch (const std::exception& ex) {
      throw std::runtime_error(what_ + ": " + ex.what());
    }
    return;
  }
  if (!(anchor_ratio > 0.0) || !std::isfinite(anchor_ratio))
    throw std::invalid_argument(what_ + ": sliding anchor ratio must be finite and > 0");
  floating_ = std::make_unique<Floating>();
  Floating& f = *floating_;
  const fem::SparseMatrix k = fem::assemble_stiffness(mesh, materials);
  const double mean_diag = k.diagonal().mean();
  if (!(mean_diag > 0.0) || !std::isfinite(mean_diag))
    throw std::runtime_error(what_ + ": stiffness has no positive diagonal");
  f.kappa = anchor_ratio * mean_diag;
  // Rigid modes: translations and rotations about the centroid, orthonormalized.
  const auto& x = mesh.vertices();
  const int nv = static_cast<int>(x.size());
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : x) c += p;
  c /= static_cast<double>(nv);
  Eigen::MatrixXd modes = Eigen::MatrixXd::Zero(dofs_, 6);
  for (int v = 0; v < nv; ++v) {
    const Eigen::Vector3d d = x[v] - c;
    for (int a = 0; a < 3; ++a) {
      modes(3 * v + a, a) = 1.0;
      modes.block<3, 1>(3 * v, 3 + a) = Eigen::Vector3d::Unit(a).cross(d);
    }
  }
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(modes);
  f.r = qr.householderQ() * Eigen::MatrixXd::Identity(dofs_, 6);
  // A statically determinate support (six dofs): node a held, node b (farthest from a) held
  // across ab, node c (farthest from the line ab) held against turning about ab. A
  // self-equilibrated load meets no reaction there, so K_det^-1 P f is a solution of K u = P f.
  // The vertex with the largest distance(x_v).
  auto farthest = [&](auto&& distance) {
    int arg = 0;
    double best = -1.0;
    for (int v = 0; v < nv; ++v) {
      const double d = distance(x[v]);
      if (d > best) {
        best = d;
        arg = v;
      }
    }
    return std::pair<int, double>(arg, best);
  };
  const int a = farthest([&](const Eigen::Vector3d& p) { return (p - c).squaredNorm(); }).first;
  const int b = farthest([&](const Eigen::Vector3d& p) { return (p - x[a]).squaredNorm(); }).first;
  const Eigen::Vector3d ab = (x[b] - x[a]).normalized();
  const auto [cc, off] = farthest([&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d d = p - x[a];
    return (d - d.dot(ab) * ab).squaredNorm();
  });
  const Eigen::Vector3d turn = ab.cross(x[cc] - x[a]);
  if (!(off > 0.0) || !(turn.norm() > 0.0))
    throw std::runtime_error(what_ + ": floating embedded mesh is degenerate (collinear)");
  int along = 0, spin = 0;
  ab.cwiseAbs().maxCoeff(&along);   // b keeps its dof along ab
  turn.cwiseAbs().maxCoeff(&spin);  // c is held along the turning direction
  std::vector<char> held(dofs_, 0);
  for (int d = 0; d < 3; ++d) held[3 * a + d] = 1;
  for (int d = 0; d < 3; ++d)
    if (d != along) held[3 * b + d] = 1;
  held[3 * cc + spin] = 1;
  f.reduced.assign(dofs_, -1);
  int nf = 0;
  for (int i = 0; i < dofs_; ++i)
    if (!held[i]) f.reduced[i] = nf++;
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(k.nonZeros());
  for (int col = 0; col < k.outerSize(); ++col) {
    if (f.reduced[col] < 0) continue;
    for (fem::SparseMatrix::InnerIterator it(k, col); it; ++it)
      if (f.reduced[it.row()] >= 0) t.emplace_back(f.reduced[it.row()], f.reduced[col], it.value());
  }
  fem::SparseMatrix kd(nf, nf);
  kd.setFromTriplets(t.begin(), t.end());
  f.factor.compute(kd);
  if (f.factor.info() != Eigen::Success || !(f.factor.vectorD().minCoeff() > 0.0)) {
    throw std::runtime_error(what_ +
                             ": factorization of the floating embedded mesh on a determinate "
                             "support failed");
  }
}

EmbeddedCompliance::~EmbeddedCompliance() = default;

void EmbeddedCompliance::apply(const Eigen::MatrixXd& forces_n, Eigen::MatrixXd& u_m,
                               fem::SolveWorkspace* ws) const {
  if (forces_n.rows() != dofs_ || !forces_n.allFinite())
    throw std::invalid_argument(what_ + ": EmbeddedCompliance::apply: bad forces");
  if (solver_) {
    const auto& free = solver_->free_dofs();
    const int nf = solver_->num_free_dofs();
    Eigen::MatrixXd rhs(nf, forces_n.cols()), x;
    for (int r = 0; r < nf; ++r) rhs.row(r) = forces_n.row(free[r]);
    if (ws != nullptr) solver_->solve_reduced(rhs, x, *ws);
    else solver_->solve_reduced(rhs, x);
    u_m.setZero(dofs_, forces_n.cols());
    for (int r = 0; r < nf; ++r) u_m.row(free[r]) = x.row(r);
    return;
  }
  // Pseudo-inverse on the self-equilibrated part (one solve on the determinate support, rigid
  // component projected out), anchor on the rigid part.
  const Floating& f = *floating_;
  const Eigen::MatrixXd rigid = f.r.transpose() * forces_n;  // 6 x m
  const Eigen::MatrixXd pf = forces_n - f.r * rigid;
  const int nf = static_cast<int>(f.factor.rows());
  Eigen::MatrixXd rhs(nf, forces_n.cols());
  for (int i = 0; i < dofs_; ++i)
    if (f.reduced[i] >= 0) rhs.row(f.reduced[i]) = pf.row(i);
  const Eigen::MatrixXd xr = f.factor.solve(rhs);
  Eigen::MatrixXd x = Eigen::MatrixXd::Zero(dofs_, forces_n.cols());
  for (int i = 0; i < dofs_; ++i)
    if (f.reduced[i] >= 0) x.row(i) = xr.row(f.reduced[i]);
  x -= f.r * (f.r.transpose() * x);
  if (!x.allFinite())
    throw std::runtime_error(what_ + ": compliance of the floating embedded mesh is not finite");
  u_m = x + f.r * (rigid / f.kappa);
}

SlidingCoupling::SlidingCoupling(SlidingDefinition def)
    : mesh_(def.mesh),
      geometry_(def.embedded),
      pairs_(std::move(def.pairs)),
      material_(def.material),
      fixed_(def.fixed_nodes) {
  std::sort(fixed_.begin(), fixed_.end());
  const std::string& what = def.what;
  if (geometry_ == nullptr) throw std::invalid_argument(what + ": no embedded mesh");
  const mesh::TetMesh& embedded = *geometry_;
  const int nb = static_cast<int>(embedded.num_vertices());
  if (pairs_.empty()) throw std::invalid_argument(what + ": no sliding pair");
  for (std::size_t k = 0; k < pairs_.size(); ++k) {
    const auto& p = pairs_[k];
    if (p.embedded_node < 0 || p.embedded_node >= nb || !p.normal.allFinite() ||
        std::abs(p.normal.norm() - 1.0) > 1e-9 || !std::isfinite(p.initial_gap_m) ||
        p.initial_gap_m < 0.0) {
      throw std::invalid_argument(what + ": bad sliding pair " + std::to_string(k) +
                                  " (embedded node " + std::to_string(p.embedded_node) + ")");
    }
  }
  compliance_ =
      std::make_unique<EmbeddedCompliance>(embedded, def.material, def.fixed_nodes,
                                           def.anchor_ratio, what);
  // W_B(s, t) = n_s . L_B(k_s, k_t) n_t, by block solves with unit normal forces.
  const int ns = size();
  w_b_.setZero(ns, ns);
  Eigen::MatrixXd f, u;
  for (int first = 0; first < ns; first += kBlock) {
    const int n = std::min(kBlock, ns - first);
    f.setZero(3 * nb, n);
    for (int j = 0; j < n; ++j)
      f.block<3, 1>(3 * pairs_[first + j].embedded_node, j) = pairs_[first + j].normal;
    compliance_->apply(f, u);
    for (int j = 0; j < n; ++j)
      for (int s = 0; s < ns; ++s)
        w_b_(s, first + j) = pairs_[s].normal.dot(u.block<3, 1>(3 * pairs_[s].embedded_node, j));
  }
  w_b_ = (0.5 * (w_b_ + w_b_.transpose())).eval();
  if (!w_b_.allFinite()) throw std::runtime_error(what + ": sliding compliance is not finite");
}

void SlidingCoupling::displacement(const Eigen::VectorXd& lambda_n, Eigen::VectorXd& u_m,
                                   fem::SolveWorkspace* ws) const {
  displacement(lambda_n,
               Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(geometry_->num_vertices())), u_m,
               ws);
}

void SlidingCoupling::displacement(const Eigen::VectorXd& lambda_n,
                                   const Eigen::VectorXd& forces_b_n, Eigen::VectorXd& u_m,
                                   fem::SolveWorkspace* ws) const {
  if (lambda_n.size() != size() || !lambda_n.allFinite())
    throw std::invalid_argument("SlidingCoupling::displacement: bad row forces");
  if (forces_b_n.size() != 3 * static_cast<Eigen::Index>(geometry_->num_vertices()) ||
      !forces_b_n.allFinite())
    throw std::invalid_argument("SlidingCoupling::displacement: bad forces on B's nodes");
  Eigen::MatrixXd f = forces_b_n, u;
  for (int k = 0; k < size(); ++k)
    f.block<3, 1>(3 * pairs_[k].embedded_node, 0) -= lambda_n[k] * pairs_[k].normal;
  compliance_->apply(f, u, ws);
  u_m = u.col(0);
}

double SlidingCoupling::gap(int k, const Eigen::VectorXd& u_host_m,
                            const Eigen::VectorXd& u_embedded_m) const {
  const auto& p = pairs_.at(k);
  Eigen::Vector3d ua = Eigen::Vector3d::Zero();
  for (int a = 0; a < 3; ++a) ua += p.weights[a] * u_host_m.segment<3>(3 * p.host_nodes[a]);
  return p.normal.dot(ua - u_embedded_m.segment<3>(3 * p.embedded_node)) + p.initial_gap_m;
}

}  // namespace neurosim::interaction
