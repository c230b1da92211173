// The hereditary integral of a viscoelastic body in contact-slot space, so the contact step stays
// a small LCP on the same compliance columns (docs/accuracy.md, "Viscoelastic tissue").
//
// Model: one relaxation kernel g for the whole body (fem/viscoelastic.hpp; the host's when meshes
// are tied). With sigma = int g(t - s) d(D eps)(s) and the supports held, the body's equilibrium
// is K (g * du) = f for the history of external forces f, hence u(t) = C (J * df)(t): the
// displacement is the ELASTIC response (the precomputed coupled compliance C) to the creep-
// equivalent force
//   f~(t) = int J(t - s) df(s) = f(t) + sum_k a_k (f(t) - q_k(t)),  q_k(t) = int e^{-(t-s)/rho_k} df(s)
// (J(t) = 1 + sum_k a_k (1 - e^{-t/rho_k}), fem::CreepSpectrum). The contact forces live on the
// contact slots, so f~ and the internal variables q_k do too: per slot and creep term, one Vec3,
// nonzero only at slots that carried a force within the last few rho_k.
//
// Step from t_{n-1} to t_n = t_{n-1} + dt with f linear in between (the usual exponential
// integrator of Taylor-Pister-Goudreau / Simo, exact for that input):
//   q_k,n = E_k q_k,n-1 + beta_k (f_n - f_n-1),  E_k = e^{-dt/rho_k},  beta_k = (1 - E_k) rho_k / dt
// so f~_n = alpha f_n + h_n with
//   alpha = 1 + sum_k a_k (1 - beta_k)            (the instantaneous scaling of C over the step)
//   h_n   = -sum_k a_k (E_k q_k,n-1 - beta_k f_n-1)   (history, known before the step).
// The step's LCP is then W' = alpha W on the same rows and columns and a depth shifted by the
// history displacement C h_n along each row: exact for the model and a force linear between the
// step times; the only error is that interpolation (relative (dt / rho_min)^2 / 12 at most on a
// step's increment of the hereditary integral). dt = 0 is a jump (alpha = 1, J(0) = 1) for the
// first step; after a committed step it REPLACES that step: a step at the time of the last one
// (a newer pose for the same instant, or the same pose stepped again on a deadline) goes back to
// the history before it and solves that step again from there with its dt. One instant has one
// state: a pose stepped again at its own time gives the same answer bit for bit, so a live server
// that repeats a step while it waits for the next sample and a replay that steps each sample time
// once give the same forces.
//
// What a held tool feels next (the haptic client's extrapolation between models): per slot the
// actual force is the relaxation integral of the creep-equivalent one, f = int g(t - s) df~(s)
// (g and J are inverse kernels), so with the Prony terms
//   f_n = g_inf f~_n + sum_i g_i z_i,n,  z_i(t) = int e^{-(t-s)/tau_i} df~(s),
// integrated with f~ linear between the step times (z_i,n = E_i z_i,n-1 + beta_i (f~_n - f~_n-1)
// with E_i, beta_i of tau_i). Held from t_n with f~ held (the slot's displacement held),
// f(t_n + s) = f_n + sum_i (e^{-s/tau_i} - 1) g_i z_i,n: relaxing(slot, i) = g_i z_i,n is the
// part of the slot's force that relaxes with tau_i.
#pragma once

#include "server/fem/viscoelastic.hpp"
#include "server/interaction/contact_columns.hpp"

#include <Eigen/Core>

#include <vector>

namespace neurosim::interaction {

class ViscoelasticHistory {
 public:
  using Vec3 = Eigen::Vector3d;

  // The body's relaxation kernel (validated), its creep function and its number of contact
  // slots; sizes everything (no allocation afterwards).
  ViscoelasticHistory(const fem::Viscoelastic& kernel, const fem::CreepSpectrum& creep,
                      int num_slots);

  // The step to t_n = t_n-1 + dt_s (dt_s >= 0): alpha and the history forces h_n. dt_s = 0 after
  // a committed step: that step is taken back and solved again (see above); a step begun and
  // not committed (it failed) leaves the committed history as it was.
  void begin(double dt_s);
  double alpha() const { return alpha_; }
  // Slots with a history force, and h_n per slot (unit N; the force the elastic body would need
  // for the displacement the history leaves).
  const std::vector<int>& slots() const { return slots_; }
  const std::vector<Vec3>& forces_n() const { return h_; }
  // Whether `slot` has a history force (its columns are read by displacement()).
  bool holds(int slot) const { return index_[slot] >= 0; }
  // The history force of `slot` (zero when it has none).
  Vec3 force_of(int slot) const { return index_[slot] >= 0 ? h_[index_[slot]] : Vec3::Zero(); }
  // Displacement of `slot` from the history forces, C h_n (unit m); columns of slots() cached.
  Vec3 displacement(const ContactColumns& columns, int slot) const;

  // The step converged with the creep-equivalent forces `equivalent_n` (= alpha f_n + h_n) on
  // `slots`: recover f_n and advance the internal variables. Slots whose history has decayed
  // below 1e-12 of the largest force seen leave it.
  void commit(const std::vector<int>& slots, const std::vector<Vec3>& equivalent_n);
  // The contact force of the last committed step at `slot` (unit N).
  Vec3 force_at(int slot) const { return f_prev_[slot]; }
  // The part of that force relaxing with the kernel's term `term` (g_i z_i, unit N): held from
  // the last committed step, the slot's force is force_at + sum_i (e^{-s/tau_i} - 1) relaxing.
  Vec3 relaxing(int slot, int term) const {
    return kernel_[term].g * z_[static_cast<std::size_t>(slot) * num_kernel_ + term];
  }
  const std::vector<fem::PronyTerm>& kernel() const { return kernel_; }
  // The step in the relaxation form, for a compliance whose partner relaxes with its
  // displacement driven (the NONLINEAR tier's quasi-linear equilibrium): with f~ (the slot's
  // elastic force for its displacement) linear over the step, f_n = gamma f~_n + r_n,
  //   gamma = g_inf + sum_i g_i beta_i,  r_n = sum_i g_i (E_i z_i,n-1 - beta_i f~_n-1)
  // (E_i, beta_i of tau_i): exact at any dt for a held displacement, where the creep form above
  // (f linear over the step) is not for a step much longer than the relaxation times. The step's
  // creep-equivalent force is then f~_n = f_n / gamma - r_n / gamma; commit() takes it as above.
  double relaxation_gamma() const { return gamma_; }
  Vec3 relaxation_history(int slot) const;

 private:
  // The relaxation variables of `slot` for its creep-equivalent force of this step.
  void relax(int slot, const Vec3& equivalent_n);
  // Exchanges the per-slot state of the slots the last commit touched (and the slot list) with
  // the copy kept of it: before that commit <-> after it.
  void swap_last_commit();

  std::vector<fem::CreepTerm> terms_;
  int num_terms_;
  std::vector<fem::PronyTerm> kernel_;
  int num_kernel_;
  // Per step.
  double alpha_{1.0};
  double gamma_{1.0};
  std::vector<double> e_, beta_;   // creep terms
  std::vector<double> er_, br_;    // relaxation (Prony) terms
  // Per slot: previous force, the internal variables q_k (slot-major), index into slots_ or -1;
  // previous creep-equivalent force and the relaxation variables z_i (slot-major).
  std::vector<Vec3> f_prev_, q_;
  std::vector<Vec3> eq_prev_, z_;
  std::vector<int> index_;
  std::vector<int> slots_;  // slots with history (force or internal variable nonzero)
  std::vector<Vec3> h_;     // per slots_ entry
  std::vector<int> next_slots_;
  std::vector<char> seen_;
  double force_scale_n_{0.0};
  // The last commit, to replace it (dt = 0): its dt, the slots it touched and their state on the
  // other side of it (packed in touched_ order), the slot list and force scale likewise.
  bool has_last_{false}, taken_back_{false};
  double dt_s_{0.0}, last_dt_s_{0.0};
  std::vector<int> touched_;
  std::vector<Vec3> last_f_, last_q_, last_eq_, last_z_;
  std::vector<int> last_slots_;
  double last_force_scale_n_{0.0};
};

}  // namespace neurosim::interaction
