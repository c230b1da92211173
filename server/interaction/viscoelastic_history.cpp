#include "server/interaction/viscoelastic_history.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace neurosim::interaction {

namespace {

// E = e^{-x} and beta = (1 - e^{-x}) / x for x = dt / time, accurate for x -> 0 (expm1), 1 at 0.
void decay(double dt_s, double time_s, double& e, double& beta) {
  const double x = dt_s / time_s;
  e = std::exp(-x);
  beta = x > 0.0 ? -std::expm1(-x) / x : 1.0;
}

}  // namespace

ViscoelasticHistory::ViscoelasticHistory(const fem::Viscoelastic& kernel,
                                         const fem::CreepSpectrum& creep, int num_slots)
    : terms_(creep.terms),
      num_terms_(static_cast<int>(creep.terms.size())),
      kernel_(kernel.terms),
      num_kernel_(static_cast<int>(kernel.terms.size())) {
  e_.assign(num_terms_, 1.0);
  beta_.assign(num_terms_, 1.0);
  er_.assign(num_kernel_, 1.0);
  br_.assign(num_kernel_, 1.0);
  f_prev_.assign(num_slots, Vec3::Zero());
  q_.assign(static_cast<std::size_t>(num_slots) * num_terms_, Vec3::Zero());
  eq_prev_.assign(num_slots, Vec3::Zero());
  z_.assign(static_cast<std::size_t>(num_slots) * num_kernel_, Vec3::Zero());
  index_.assign(num_slots, -1);
  seen_.assign(num_slots, 0);
  slots_.reserve(num_slots);
  h_.reserve(num_slots);
  next_slots_.reserve(num_slots);
  touched_.reserve(num_slots);
  last_f_.assign(num_slots, Vec3::Zero());
  last_q_.assign(q_.size(), Vec3::Zero());
  last_eq_.assign(num_slots, Vec3::Zero());
  last_z_.assign(z_.size(), Vec3::Zero());
  last_slots_.reserve(num_slots);
}

void ViscoelasticHistory::swap_last_commit() {
  for (std::size_t j = 0; j < touched_.size(); ++j) {
    const auto s = static_cast<std::size_t>(touched_[j]);
    std::swap(f_prev_[s], last_f_[j]);
    std::swap(eq_prev_[s], last_eq_[j]);
    for (int k = 0; k < num_terms_; ++k)
      std::swap(q_[s * num_terms_ + k], last_q_[j * num_terms_ + k]);
    for (int i = 0; i < num_kernel_; ++i)
      std::swap(z_[s * num_kernel_ + i], last_z_[j * num_kernel_ + i]);
  }
  for (int s : slots_) index_[s] = -1;
  slots_.swap(last_slots_);  // both reserved for every slot: no allocation
  for (std::size_t i = 0; i < slots_.size(); ++i) index_[slots_[i]] = static_cast<int>(i);
  h_.resize(slots_.size());
  std::swap(force_scale_n_, last_force_scale_n_);
}

void ViscoelasticHistory::begin(double dt_s) {
  if (!(dt_s >= 0.0) || !std::isfinite(dt_s))
    throw std::invalid_argument("ViscoelasticHistory: time step must be finite and >= 0");
  // A step taken back and not solved again (it failed): the committed history comes back.
  if (taken_back_) {
    swap_last_commit();
    taken_back_ = false;
  }
  // The time of the last step again: that step is replaced (taken back, solved again with its dt).
  if (dt_s == 0.0 && has_last_) {
    swap_last_commit();
    taken_back_ = true;
    dt_s = last_dt_s_;
  }
  dt_s_ = dt_s;
  alpha_ = 1.0;
  for (int k = 0; k < num_terms_; ++k) {
    decay(dt_s, terms_[k].rho_s, e_[k], beta_[k]);
    alpha_ += terms_[k].a * (1.0 - beta_[k]);
  }
  gamma_ = 1.0;
  for (int i = 0; i < num_kernel_; ++i) {
    decay(dt_s, kernel_[i].tau_s, er_[i], br_[i]);
    gamma_ -= kernel_[i].g * (1.0 - br_[i]);  // g_inf + sum g_i beta_i, sum g_i = 1 - g_inf
  }
  for (std::size_t i = 0; i < slots_.size(); ++i) {
    const int s = slots_[i];
    Vec3 h = Vec3::Zero();
    for (int k = 0; k < num_terms_; ++k)
      h -= terms_[k].a * (e_[k] * q_[static_cast<std::size_t>(s) * num_terms_ + k] -
                          beta_[k] * f_prev_[s]);
    h_[i] = h;
  }
}

ViscoelasticHistory::Vec3 ViscoelasticHistory::displacement(const ContactColumns& columns,
                                                            int slot) const {
  Vec3 u = Vec3::Zero();
  for (std::size_t i = 0; i < slots_.size(); ++i)
    u.noalias() += columns.block(slot, slots_[i]) * h_[i];
  return u;
}

ViscoelasticHistory::Vec3 ViscoelasticHistory::relaxation_history(int slot) const {
  Vec3 r = Vec3::Zero();
  if (index_[slot] < 0) return r;
  for (int i = 0; i < num_kernel_; ++i)
    r += kernel_[i].g * (er_[i] * z_[static_cast<std::size_t>(slot) * num_kernel_ + i] -
                         br_[i] * eq_prev_[slot]);
  return r;
}

void ViscoelasticHistory::commit(const std::vector<int>& slots,
                                 const std::vector<Vec3>& equivalent_n) {
  // f_n = (f~_n - h_n) / alpha on the loaded slots; zero on history slots not listed.
  next_slots_.clear();
  for (std::size_t i = 0; i < slots.size(); ++i) {
    const int s = slots[i];
    if (seen_[s]) continue;
    seen_[s] = 1;
    next_slots_.push_back(s);
  }
  for (int s : slots_) {
    if (seen_[s]) continue;
    seen_[s] = 1;
    next_slots_.push_back(s);
  }
  // What this commit changes, as it was (a step at the same time replaces this one).
  touched_.assign(next_slots_.begin(), next_slots_.end());
  for (std::size_t j = 0; j < touched_.size(); ++j) {
    const auto s = static_cast<std::size_t>(touched_[j]);
    last_f_[j] = f_prev_[s];
    last_eq_[j] = eq_prev_[s];
    for (int k = 0; k < num_terms_; ++k) last_q_[j * num_terms_ + k] = q_[s * num_terms_ + k];
    for (int i = 0; i < num_kernel_; ++i) last_z_[j * num_kernel_ + i] = z_[s * num_kernel_ + i];
  }
  last_slots_.assign(slots_.begin(), slots_.end());
  last_force_scale_n_ = force_scale_n_;
  has_last_ = true;
  taken_back_ = false;
  last_dt_s_ = dt_s_;
  // The new forces, kept in h_'s place per slot until the internal variables are updated.
  for (std::size_t i = 0; i < slots.size(); ++i) {
    const int s = slots[i];
    const Vec3 f = (equivalent_n[i] - force_of(s)) / alpha_;
    force_scale_n_ = std::max(force_scale_n_, f.norm());
    seen_[s] = 2;  // loaded this step
    for (int k = 0; k < num_terms_; ++k) {
      Vec3& q = q_[static_cast<std::size_t>(s) * num_terms_ + k];
      q = e_[k] * q + beta_[k] * (f - f_prev_[s]);
    }
    f_prev_[s] = f;
    relax(s, equivalent_n[i]);
  }
  // History slots without a force this step: f_n = 0.
  for (int s : next_slots_) {
    if (seen_[s] == 2) continue;
    for (int k = 0; k < num_terms_; ++k) {
      Vec3& q = q_[static_cast<std::size_t>(s) * num_terms_ + k];
      q = e_[k] * q - beta_[k] * f_prev_[s];
    }
    f_prev_[s] = Vec3::Zero();
    relax(s, force_of(s));  // f~ = alpha 0 + h
  }
  // The slots that keep a history, in a deterministic order (first loaded, then older).
  for (int s : slots_) index_[s] = -1;
  slots_.clear();
  h_.clear();
  const double floor = 1e-12 * force_scale_n_;
  for (int s : next_slots_) {
    seen_[s] = 0;
    double left = f_prev_[s].norm();
    for (int k = 0; k < num_terms_; ++k)
      left += terms_[k].a * q_[static_cast<std::size_t>(s) * num_terms_ + k].norm();
    for (int i = 0; i < num_kernel_; ++i)
      left += z_[static_cast<std::size_t>(s) * num_kernel_ + i].norm();
    if (left <= floor) {
      for (int k = 0; k < num_terms_; ++k) q_[static_cast<std::size_t>(s) * num_terms_ + k].setZero();
      for (int i = 0; i < num_kernel_; ++i) z_[static_cast<std::size_t>(s) * num_kernel_ + i].setZero();
      f_prev_[s].setZero();
      eq_prev_[s].setZero();
      continue;
    }
    index_[s] = static_cast<int>(slots_.size());
    slots_.push_back(s);
    h_.push_back(Vec3::Zero());  // begin() fills it
  }
}

void ViscoelasticHistory::relax(int slot, const Vec3& equivalent_n) {
  const Vec3 d = equivalent_n - eq_prev_[slot];
  for (int i = 0; i < num_kernel_; ++i) {
    Vec3& z = z_[static_cast<std::size_t>(slot) * num_kernel_ + i];
    z = er_[i] * z + br_[i] * d;
  }
  eq_prev_[slot] = equivalent_n;
}

}  // namespace neurosim::interaction
