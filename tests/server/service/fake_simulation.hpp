// Test-only Simulation with an analytic contact law, so the DDS plumbing of the service can be
// tested without the physics: every scene mesh becomes a small structured box mesh over the
// compiled mesh's bounding box, and the FIRST mesh's +x face is a half-space
// spring: penetration d = (x_max + r_tip) - tip.x > 0 inside the face's y/z extent gives
// force (k d, 0, 0) on the tool, stiffness -k e_x e_x^T, normal +x.
// Stations feel each other: each tool's force is scaled by (1 + kCross * sum of the other
// tools' penetrations / r_tip), so results depend on all poses of a step.
// Tier: the model's effects.tier (so neurosim-server --tier reaches it); for COROTATIONAL and
// NONLINEAR it reports kTierUpdateRateHz once it has stepped (0 before, as a real tier before
// its first equilibrium update), so a test sees whether SimStatus is refilled at each publish.
#pragma once

#include "server/interaction/simulation.hpp"

#include <atomic>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace neurosim::service::testing {

class FakeSimulation : public interaction::Simulation {
 public:
  static constexpr double kStiffness = 2000.0;  // N/m
  static constexpr double kCross = 0.05;        // dimensionless
  static constexpr double kTierUpdateRateHz = 12.5;  // non-linear tiers, after the first step

  // `runs`: the tier the fake claims to run instead of the model's (tests of the server's
  // refusal of a simulation that runs another tier than asked for).
  explicit FakeSimulation(const scene::Model& model,
                          std::optional<scene::Tier> runs = std::nullopt);
  ~FakeSimulation() override;

  int num_meshes() const override { return static_cast<int>(meshes_.size()); }
  const std::string& mesh_id(int m) const override { return ids_.at(static_cast<std::size_t>(m)); }
  const mesh::TetMesh& mesh(int m) const override { return meshes_.at(static_cast<std::size_t>(m)); }
  void step(const std::vector<interaction::ToolPose>& poses,
            std::vector<interaction::ToolContact>& contacts,
            interaction::StepStats& stats) override;
  void displacements(int m, Eigen::VectorXd& u_m) const override;

  bool mesh_active(int) const override { return true; }
  double tie_residual_m() const override { return 0.0; }
  const interaction::SetupStats& setup_stats() const override { return setup_; }
  const std::vector<int>& fixed_nodes(int) const override { return no_nodes_; }
  int num_tools() const override { return 1; }
  const interaction::CoupledBody* body_of(int) const override { return nullptr; }
  void last_contact_forces(int, std::vector<int>& slots,
                           std::vector<interaction::Vec3>& forces_n) const override {
    slots.clear();
    forces_n.clear();
  }
  // No SLIDING couplings in the fake.
  void sliding_pairs(int, std::vector<interaction::SlidingPairState>& pairs) const override {
    pairs.clear();
  }
  double sliding_penetration_m() const override { return 0.0; }
  scene::Tier tier() const override { return tier_; }
  // Any thread (the server reads it on the step thread, start() on the main thread).
  double tier_update_rate_hz() const override {
    if (tier_ == scene::Tier::kLinear || !stepped_.load(std::memory_order_acquire)) return 0.0;
    return kTierUpdateRateHz;
  }

  long displacement_calls() const { return displacement_calls_.load(); }

 private:
  std::vector<std::string> ids_;
  std::vector<mesh::TetMesh> meshes_;
  double x_max_{1}, y_lo_{0}, y_hi_{1}, z_lo_{0}, z_hi_{1}, x_min_{0};
  double tip_radius_m_{0.003};
  double last_max_depth_m_{0};
  std::vector<double> depth_;  // scratch, per tool
  mutable std::atomic<long> displacement_calls_{0};
  scene::Tier tier_{scene::Tier::kLinear};
  std::atomic<bool> stepped_{false};
  interaction::SetupStats setup_{};
  std::vector<int> no_nodes_;
};

std::unique_ptr<interaction::Simulation> make_fake(const scene::Model& model);

}  // namespace neurosim::service::testing
