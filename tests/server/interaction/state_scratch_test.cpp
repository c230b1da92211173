// No scratch in the Model: the step's first touches of compliance columns (the State's
// ContactColumns) and the field thread's solves (the FieldSnapshot's workspace) each solve on
// their own fem::SolveWorkspace, so neither takes the lock of the host solver's shared workspace.
// Checked by count, not by time: the shared workspace is used zero times while fields and first
// touches run together, and every field equals the one solved alone.
#include "server/fem/static_solver.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/simulation.hpp"
#include "tests/server/interaction/interaction_fixtures.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <thread>
#include <vector>

namespace neurosim::interaction {
namespace {

using testing::make_scene;
using testing::push_right;
using testing::SceneSpec;

// What happened while fields of the first `meshes` meshes were solved again and again on another
// thread (from one snapshot taken after a first press) and the stepping thread pressed at each
// of `presses`: first touches solved inside the steps, rounds of fields, and the largest
// difference of any field from the one solved alone before.
struct Concurrent {
  int first_touches{0};
  int rounds{0};
  double max_field_difference_m{0.0};
};

Concurrent fields_beside_presses(Simulation& sim, int meshes, const std::vector<ToolPose>& presses,
                                 const std::function<void()>& after_each_step) {
  std::vector<ToolContact> contacts;
  StepStats stats;
  sim.step({push_right(0.002)}, contacts, stats);
  EXPECT_TRUE(contacts.at(0).in_contact);
  FieldSnapshot reference_snapshot, field_snapshot;
  sim.snapshot(reference_snapshot);
  sim.snapshot(field_snapshot);
  std::vector<Eigen::VectorXd> reference(meshes);
  for (int m = 0; m < meshes; ++m) sim.displacements(reference_snapshot, m, reference[m]);

  Concurrent out;
  std::atomic<bool> stepping{true};
  std::atomic<int> rounds{0};
  std::thread field_thread([&] {
    Eigen::VectorXd u;
    while (stepping.load() || rounds.load() < 2) {
      for (auto& b : field_snapshot.bodies) b.host_done = false;  // solve again
      for (int m = 0; m < meshes; ++m) {
        sim.displacements(field_snapshot, m, u);
        out.max_field_difference_m =
            std::max(out.max_field_difference_m, (u - reference[m]).cwiseAbs().maxCoeff());
      }
      ++rounds;
    }
  });
  while (rounds.load() < 1) std::this_thread::yield();
  for (const ToolPose& p : presses) {
    sim.step({p}, contacts, stats);
    out.first_touches += stats.columns_computed;
    after_each_step();
  }
  stepping = false;
  field_thread.join();
  out.rounds = rounds.load();
  return out;
}

// Presses over the right face on an n x n grid `pitch_m` apart: every new contact node is a
// first touch inside the step.
std::vector<ToolPose> presses_over_right_face(int n, double pitch_m) {
  std::vector<ToolPose> out;
  for (int iy = 0; iy < n; ++iy)
    for (int iz = 0; iz < n; ++iz) {
      ToolPose p = push_right(0.003);
      p.tip_m.y() = 0.02 + pitch_m * iy;
      p.tip_m.z() = 0.02 + pitch_m * iz;
      out.push_back(p);
    }
  return out;
}

TEST(interaction_state_scratch, FieldsAndFirstTouchesRunTogetherWithoutALockInTheModel) {
  SimulationOptions options;
  options.precompute_contact_columns = false;  // columns are computed on first touch, in the step
  auto sim = Simulation::build(make_scene(SceneSpec{}), options);
  const CoupledBody* body = sim->body_of(0);
  ASSERT_NE(body, nullptr);
  const fem::StaticSolver& host = body->host_solver();
  const std::uint64_t shared_before = host.shared_workspace_uses();

  const Concurrent run = fields_beside_presses(*sim, 1, presses_over_right_face(5, 0.015), [] {});

  EXPECT_GT(run.first_touches, 0) << "the presses touched new contact nodes inside the step";
  EXPECT_GE(run.rounds, 2);
  EXPECT_EQ(host.shared_workspace_uses(), shared_before)
      << "a step or a field solved on the host solver's shared (locked) workspace";
  EXPECT_EQ(run.max_field_difference_m, 0.0)
      << "a field solved beside the steps differs from the one solved alone";
}

// The tied cylinder's interior (K_ii) and the sliding rod's compliance solve on the field
// snapshot's and the State's scratch too: with fields of every mesh solved on another thread
// while the steps press new nodes, no solver in the Model is used on its own locked workspace.
TEST(interaction_state_scratch, TiedAndSlidingFieldsTakeNoLockInTheModel) {
  SceneSpec spec;
  spec.embedded_fixed = true;  // K_ii has free interior nodes and the rod a fixed support
  spec.rod_kind = "SLIDING";
  SimulationOptions options;
  options.precompute_contact_columns = false;
  auto sim = Simulation::build(make_scene(spec), options);
  ASSERT_EQ(sim->num_meshes(), 3);
  const std::uint64_t shared_before = sim->shared_workspace_uses();

  Eigen::VectorXd u_stepping;
  const Concurrent run = fields_beside_presses(*sim, 3, presses_over_right_face(4, 0.02), [&] {
    // The stepping thread's own field queries: the State's scratch.
    for (int m = 0; m < 3; ++m) sim->displacements(m, u_stepping);
    EXPECT_TRUE(std::isfinite(sim->tie_residual_m()));
    EXPECT_TRUE(std::isfinite(sim->sliding_penetration_m()));
  });

  EXPECT_GT(run.first_touches, 0);
  EXPECT_GE(run.rounds, 2);
  EXPECT_EQ(sim->shared_workspace_uses(), shared_before)
      << "a step or a field solved on a solver's shared (locked) workspace in the Model";
  EXPECT_EQ(run.max_field_difference_m, 0.0)
      << "a field solved beside the steps differs from the one solved alone";
}

// The counter the test above relies on sees a solve on a tied interior's own workspace.
TEST(interaction_state_scratch, SharedWorkspaceUsesCountsATiedInteriorSolve) {
  SceneSpec spec;
  spec.embedded_fixed = true;
  auto sim = Simulation::build(make_scene(spec), SimulationOptions{});
  const CoupledBody* body = sim->body_of(0);
  ASSERT_NE(body, nullptr);
  ASSERT_FALSE(body->ties().empty());
  const std::uint64_t before = sim->shared_workspace_uses();
  Eigen::VectorXd u_host = Eigen::VectorXd::Zero(3 * static_cast<int>(body->host().num_vertices()));
  Eigen::VectorXd u_b;
  body->ties()[0].displacement(u_host, u_b);  // no workspace: the interior's own
  EXPECT_GT(sim->shared_workspace_uses(), before);
}

TEST(interaction_state_scratch, ColumnsFromTheStatesWorkspaceEqualTheSharedOnes) {
  auto sim = Simulation::build(make_scene(SceneSpec{}), SimulationOptions{});
  const CoupledBody* body = sim->body_of(0);
  ASSERT_NE(body, nullptr);
  const std::vector<int> slots{0, 1, 2};
  Eigen::MatrixXd shared, own;
  fem::SolveWorkspace ws;
  body->solve_contact_columns(slots, shared);
  const std::uint64_t uses = body->host_solver().shared_workspace_uses();
  body->solve_contact_columns(slots, own, &ws);
  EXPECT_EQ(body->host_solver().shared_workspace_uses(), uses);
  ASSERT_EQ(own.rows(), shared.rows());
  EXPECT_EQ((own - shared).cwiseAbs().maxCoeff(), 0.0);
}

}  // namespace
}  // namespace neurosim::interaction
