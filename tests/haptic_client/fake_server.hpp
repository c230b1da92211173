// Test-only stand-ins for neurosim-server: a half-space spring (tissue below a plane) answering
// ToolStates with ContactModels, in-process (simulated time) or over DDS (a thread). The
// in-process link can add rigid constraint planes (a skull) to every model.
#pragma once

#include "haptic_client/force_model.hpp"
#include "haptic_client/link.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <deque>
#include <vector>

namespace neurosim::haptic::testing {

// Tissue z < surface_z (scene frame), outward normal +z, stiffness k.
struct HalfSpace {
  double surface_z_m = 0;
  double k_n_per_m = 700;
  ContactModelData model_at(const Eigen::Vector3d& x, std::uint64_t seq, std::int64_t t_ns) const {
    ContactModelData m;
    m.tool_sequence = seq;
    m.reference_time_ns = t_ns;
    m.x0_m = x;
    const double pen = surface_z_m - x.z();
    m.in_contact = pen > 0;
    m.normal = Eigen::Vector3d::UnitZ();
    if (m.in_contact) {
      m.f0_n = k_n_per_m * pen * m.normal;
      m.k_n_per_m = -k_n_per_m * m.normal * m.normal.transpose();
    }
    m.validity_radius_m = 0.01;
    return m;
  }
  Eigen::Vector3d force(const Eigen::Vector3d& x) const {
    const double pen = surface_z_m - x.z();
    return pen > 0 ? Eigen::Vector3d(0, 0, k_n_per_m * pen) : Eigen::Vector3d::Zero();
  }
};

// Viscoelastic tissue z < surface_z: the force is the relaxation integral of the elastic one,
// F(t) = int g(t - s) dF_el(s), F_el = k pen, g(t) = g_inf + sum_i g_i e^{-t/tau_i} (Prony;
// the elastic force linear between the answered sample times, exact for that input). Answers
// as neurosim-server does: f0 = F, K the instantaneous stiffness -k n n^T, and the parts
// g_i z_i relaxing with tau_i (ContactModel.relaxing_forces). The tissue pushes only
// (F <= 0 out of contact); its history runs on the penetration. Call in time order.
struct ViscoelasticHalfSpace {
  struct Term {
    double g;      // relative modulus
    double tau_s;  // unit s
  };
  double surface_z_m = 0;
  double k_n_per_m = 700;  // instantaneous stiffness, unit N/m
  std::vector<Term> terms;
  ContactModelData model_at(const Eigen::Vector3d& x, std::uint64_t seq, std::int64_t t_ns) {
    if (z_.size() != terms.size()) z_.assign(terms.size(), 0.0);
    const double pen = surface_z_m - x.z();
    const double f_el = k_n_per_m * std::max(0.0, pen);
    const double dt = started_ ? 1e-9 * static_cast<double>(t_ns - t_prev_ns_) : 0.0;
    double g_inf = 1, f = 0;
    for (std::size_t i = 0; i < terms.size(); ++i) {
      const double e = std::exp(-dt / terms[i].tau_s);
      const double beta = dt > 0 ? (1 - e) * terms[i].tau_s / dt : 1.0;
      z_[i] = e * z_[i] + beta * (f_el - f_el_prev_);
      g_inf -= terms[i].g;
      f += terms[i].g * z_[i];
    }
    f += g_inf * f_el;
    started_ = true;
    t_prev_ns_ = t_ns;
    f_el_prev_ = f_el;
    ContactModelData m;
    m.tool_sequence = seq;
    m.reference_time_ns = t_ns;
    m.x0_m = x;
    m.normal = Eigen::Vector3d::UnitZ();
    m.in_contact = pen > 0 && f > 0;
    m.validity_radius_m = 0.01;
    if (m.in_contact) {
      m.f0_n = f * m.normal;
      m.k_n_per_m = -k_n_per_m * m.normal * m.normal.transpose();
      for (std::size_t i = 0; i < terms.size() && i < kMaxRelaxingForces; ++i)
        m.relaxing[m.num_relaxing++] = RelaxingForce{terms[i].g * z_[i] * m.normal, terms[i].tau_s};
    }
    return m;
  }

 private:
  std::vector<double> z_;
  double f_el_prev_ = 0;
  std::int64_t t_prev_ns_ = 0;
  bool started_ = false;
};

// In-process link: answers each ToolState with the half-space model `latency_ticks` later;
// keeps every published ToolState.
class FakeLink : public Link {
 public:
  HalfSpace tissue;
  std::size_t latency_ticks = 2;
  bool answering = true;
  bool alive = true;
  RigidPlaneSet planes;     // rigid obstacles sent in every model (as the server would)
  bool send_planes = true;  // false: models without planes (the obstacle went away)
  std::vector<ToolSample> published;

  void publish(const ToolSample& s) override {
    published.push_back(s);
    if (answering) pending_.push_back(s);
  }
  bool take_model(ContactModelData& out) override {
    if (pending_.size() <= latency_ticks) return false;
    const ToolSample s = pending_.front();
    pending_.pop_front();
    out = tissue.model_at(s.position_m, s.sequence_number, s.source_time_ns);
    if (send_planes) out.rigid_planes = planes;
    return true;
  }
  bool server_alive() override { return alive; }

 private:
  std::deque<ToolSample> pending_;
};

}  // namespace neurosim::haptic::testing
