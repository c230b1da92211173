#include "server/fem/quasi_linear_viscoelastic.hpp"

#include "server/fem/elastic_forces.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

QuasiLinearViscoelastic::QuasiLinearViscoelastic(const ElasticForces& forces,
                                                 const Viscoelastic& kernel,
                                                 const std::string& what)
    : forces_(forces),
      kernel_(kernel),
      num_terms_(static_cast<int>(kernel.terms.size())),
      num_tets_(forces.num_tets()) {
  kernel_.validate(what);
  if (kernel_.empty()) throw std::invalid_argument(what + ": no relaxation terms");
  if (forces.tier() != Tier::kNonlinear) {
    throw std::invalid_argument(what + ": quasi-linear viscoelasticity is implemented in the "
                                "NONLINEAR tier only (tier " + std::string(tier_name(forces.tier())) +
                                ")");
  }
  if (forces.element() != Element::kLinearTet) {
    throw std::invalid_argument(
        what + ": viscoelastic terms in the NONLINEAR tier need material.element linear-tet (the "
        "internal variables are per element; " + std::string(element_name(forces.element())) +
        " holds part of the energy per node or smoothing cell, not implemented)");
  }
  step_.history_stress_pa.assign(num_tets_, Eigen::Matrix3d::Zero());
  e_.assign(num_terms_, 1.0);
  beta_.assign(num_terms_, 1.0);
  se_.assign(num_tets_, Eigen::Matrix3d::Zero());
  last_se_ = se_;
  h_.assign(num_tets_ * num_terms_, Eigen::Matrix3d::Zero());
  last_h_ = h_;
}

void QuasiLinearViscoelastic::take_back() {
  se_.swap(last_se_);
  h_.swap(last_h_);
  std::swap(unrelaxed_, last_unrelaxed_);
}

void QuasiLinearViscoelastic::begin(double dt_s) {
  if (!(dt_s >= 0.0) || !std::isfinite(dt_s))
    throw std::invalid_argument("QuasiLinearViscoelastic: time step must be finite and >= 0");
  if (taken_back_) {  // the replacing step was not committed: the committed state comes back
    take_back();
    taken_back_ = false;
  }
  if (dt_s == 0.0 && has_last_) {
    take_back();
    taken_back_ = true;
    dt_s = last_dt_s_;
  }
  dt_s_ = dt_s;
  step_.gamma = kernel_.relaxed_fraction();
  for (int i = 0; i < num_terms_; ++i) {
    const double x = dt_s / kernel_.terms[i].tau_s;
    e_[i] = std::exp(-x);
    beta_[i] = x > 0.0 ? -std::expm1(-x) / x : 1.0;  // accurate as x -> 0; -> 0 as x -> inf
    step_.gamma += kernel_.terms[i].g * beta_[i];
  }
  for (std::size_t e = 0; e < num_tets_; ++e) {
    Eigen::Matrix3d s = Eigen::Matrix3d::Zero();
    for (int i = 0; i < num_terms_; ++i)
      s.noalias() += kernel_.terms[i].g * (e_[i] * h_[e * num_terms_ + i] - beta_[i] * se_[e]);
    step_.history_stress_pa[e] = s;
  }
}

void QuasiLinearViscoelastic::commit(const Eigen::VectorXd& u_m) {
  // The state before this step (after a take-back: before the step it replaces).
  last_se_ = se_;
  last_h_ = h_;
  last_unrelaxed_ = unrelaxed_;
  taken_back_ = false;
  double top = 0.0, scale = 0.0;
  for (std::size_t e = 0; e < num_tets_; ++e) {
    const Eigen::Matrix3d s_new = forces_.elastic_second_piola(e, u_m);
    const Eigen::Matrix3d ds = s_new - se_[e];
    Eigen::Matrix3d left = Eigen::Matrix3d::Zero();
    for (int i = 0; i < num_terms_; ++i) {
      Eigen::Matrix3d& h = h_[e * num_terms_ + i];
      h = e_[i] * h + beta_[i] * ds;
      left += kernel_.terms[i].g * h;
    }
    se_[e] = s_new;
    top = std::max(top, left.norm());
    scale = std::max(scale, s_new.norm());
  }
  unrelaxed_ = scale > 0.0 ? top / scale : (top > 0.0 ? 1.0 : 0.0);
  last_dt_s_ = dt_s_;
  has_last_ = true;
}

Eigen::Matrix3d QuasiLinearViscoelastic::stress(std::size_t tet) const {
  Eigen::Matrix3d s = kernel_.relaxed_fraction() * se_[tet];
  for (int i = 0; i < num_terms_; ++i) s += kernel_.terms[i].g * h_[tet * num_terms_ + i];
  return s;
}

}  // namespace neurosim::fem
