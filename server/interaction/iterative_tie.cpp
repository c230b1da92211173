#include "server/interaction/iterative_tie.hpp"

#include "server/interaction/coupled_body.hpp"
#include "server/fem/power_iteration.hpp"

#include <Eigen/LU>

#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

IterativeTie::IterativeTie(const CoupledBody& body, const IterativeOptions& options)
    : body_(body), options_(options) {
  const auto& l_bb = body.boundary_compliance();
  const auto& k_add = body.boundary_stiffness();
  if (l_bb.rows() == 0) throw std::invalid_argument("IterativeTie: the body has no tie");
  p_ = l_bb * k_add;
  omega_ = options_.relaxation;
  if (!(omega_ > 0.0)) {
    // rho(L_bb K_add) by power iteration; its eigenvalues are real and >= 0 (similar to an SPD
    // form).
    const double rho =
        fem::power_iteration([&](const Eigen::VectorXd& x, Eigen::VectorXd& y) { y.noalias() = p_ * x; },
                             Eigen::VectorXd::Ones(p_.rows()), 500, 1e-6)
            .lambda;
    omega_ = 2.0 / (2.0 + rho);
  }
}

Eigen::VectorXd IterativeTie::load(const std::vector<int>& slots,
                                   const std::vector<Eigen::Vector3d>& forces_n) const {
  const auto& l_sb = body_.contact_boundary_compliance();
  Eigen::VectorXd v = Eigen::VectorXd::Zero(l_sb.cols());
  for (std::size_t k = 0; k < slots.size(); ++k) {
    // L_A's rows at the host's contact slots only (an exposed tie's slot loads A through the
    // tie's equivalent load: not this comparison's).
    if (slots[k] < 0 || 3 * slots[k] + 3 > l_sb.rows())
      throw std::invalid_argument("IterativeTie: contact slot " + std::to_string(slots[k]) +
                                  " is not one of the host's");
    v.noalias() += l_sb.middleRows(3 * slots[k], 3).transpose() * forces_n[k];
  }
  return v;
}

Eigen::VectorXd IterativeTie::exact(const std::vector<int>& slots,
                                    const std::vector<Eigen::Vector3d>& forces_n) const {
  Eigen::MatrixXd a = Eigen::MatrixXd::Identity(p_.rows(), p_.cols()) + p_;
  return a.partialPivLu().solve(load(slots, forces_n));
}

IterativeResult IterativeTie::solve(const std::vector<int>& slots,
                                    const std::vector<Eigen::Vector3d>& forces_n,
                                    const Eigen::VectorXd& u_b_exact, Eigen::VectorXd& u_b) const {
  IterativeResult r;
  r.relaxation = omega_;
  const Eigen::VectorXd v = load(slots, forces_n);
  const double scale = std::max(v.norm(), 1e-300);
  u_b = v;  // first guess: the host alone (the embedded mesh not yet felt)
  Eigen::VectorXd next(v.size());
  r.residual.reserve(options_.max_iterations);
  for (int it = 0; it < options_.max_iterations; ++it) {
    next.noalias() = v - p_ * u_b;
    u_b = (1.0 - omega_) * u_b + omega_ * next;
    r.iterations = it + 1;
    const double res = (u_b - u_b_exact).norm() / scale;
    r.residual.push_back(res);
    if (!std::isfinite(res)) break;
    if (res <= options_.tolerance) {
      r.converged = true;
      break;
    }
  }
  return r;
}

void IterativeTie::apply(const Eigen::MatrixXd& in, Eigen::MatrixXd& out, IterativeReport* counts) const {
  Eigen::MatrixXd u = in;
  for (Eigen::Index c = 0; c < in.cols(); ++c) {
    const double scale = std::max(in.col(c).norm(), 1e-300);
    bool converged = false;
    int it = 0;
    while (it < options_.max_iterations) {
      ++it;
      const Eigen::VectorXd target = in.col(c) - p_ * u.col(c);
      const double change = omega_ * (target - u.col(c)).norm();
      u.col(c) = (1.0 - omega_) * u.col(c) + omega_ * target;
      if (change <= options_.tolerance * scale) {
        converged = true;
        break;
      }
    }
    if (counts != nullptr) {
      counts->max_iterations = std::max(counts->max_iterations, it);
      ++counts->solves;
      if (!converged) ++counts->unconverged;
    }
  }
  out.noalias() = body_.boundary_stiffness() * u;
}

}  // namespace neurosim::interaction
