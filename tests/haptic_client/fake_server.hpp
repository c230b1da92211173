// Test-only stand-ins for neurosim-server: a half-space spring (tissue below a plane) answering
// ToolStates with ContactModels, in-process (simulated time) or over DDS (a thread). The
// in-process link can add rigid constraint planes (a skull) to every model.
#pragma once

#include "haptic_client/force_model.hpp"
#include "haptic_client/link.hpp"

#include <Eigen/Core>

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
