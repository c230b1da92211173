// ToolProxy (the server-side god-object) on the skull of scenes/brain_skull.scene: a probe driven
// into the skull at 0.5 m/s stays outside the bone while the device goes 10 mm deep; a jump
// through the whole shell in one step is held on the side it came from; the same probe through
// the craniotomy is never blocked and reaches the cerebellum with the force of the unblocked pose.
#include "server/interaction/tool_proxy.hpp"

#include "rigid_fixtures.hpp"
#include "server/interaction/simulation.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <new>
#include <stdexcept>

#include "thread_allocation_counter.hpp"

namespace neurosim::interaction {
namespace {

using testing::probe_shape;
using testing::skull;

constexpr double kTolerance_m = 1e-4;  // accepted penetration of the physics pose: 0.1 mm

// How deep the tool at `pose` is in the bone, unit m (0: clear): tip sphere and shaft samples.
double tool_penetration(const RigidObstacle& o, const ToolPose& pose, const ToolShape& s) {
  auto part = [&](const mesh::Vec3& c, double r) {
    const double d = o.closest(c).distance_m;
    return o.inside(c) ? r + d : std::max(0.0, r - d);
  };
  double pen = part(pose.tip_m, s.tip_radius_m);
  for (double t = 0.0; t <= 0.03; t += 0.001) pen = std::max(pen, part(pose.tip_m + t * pose.axis, s.shaft_radius_m));
  return pen;
}

// The tests' 7 mm brain under the skull (test_support.hpp brain7_scene: neurosim-model --skull
// --cell-size 7, the same skull and opening as the bundled scene) for the tests that step the
// tissue: they need a brain under a skull, not the bundled 5 mm one.
struct SkullScene {
  scene::Model model;
  std::unique_ptr<const RigidObstacle> skull;
  ToolShape shape;
};
const SkullScene& brain7_skull() {
  static const SkullScene s = [] {
    SkullScene out;
    out.model = scene::load_model(::neurosim::testing::brain7_scene("brain_skull"));
    out.skull = RigidObstacle::build(out.model.rigid);
    if (!out.skull) throw std::runtime_error("the 7 mm brain_skull.scene has no rigid surface");
    const auto& t = out.model.tools.front();
    out.shape = ToolShape{t.tip_radius_m, t.shaft_radius_m, t.shaft_length_m};
    return out;
  }();
  return s;
}

mesh::Vec3 skull_centre(const RigidObstacle& o = skull()) {
  mesh::Vec3 lo = o.vertices_m().front(), hi = lo;
  for (const auto& v : o.vertices_m()) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  return 0.5 * (lo + hi);
}

TEST(interaction_tool_proxy, DrivenIntoTheSkullStaysOutside) {
  const RigidObstacle& o = skull();
  const ToolShape shape = probe_shape();
  const mesh::Vec3 down(0, 0, -1);
  const mesh::Vec3 surface = testing::first_bone(o, skull_centre() + mesh::Vec3(0, 0, 0.15), down, 0.2);
  // From 5 mm above the tip's contact to 10 mm below the outer table, 0.5 m/s at 1 kHz.
  const mesh::Vec3 start = surface - (shape.tip_radius_m + 0.005) * down;
  const double travel = shape.tip_radius_m + 0.005 + 0.010;
  ToolProxy proxy(o);
  ObstaclePlanes planes;
  double worst = 0.0, last_raw_pen = 0.0;
  int steps_blocked = 0;
  for (int k = 0; k * 0.0005 <= travel + 1e-12; ++k) {
    ToolPose pose;
    pose.tip_m = start + (k * 0.0005) * down;
    pose.axis = -down;
    const mesh::Vec3 raw = pose.tip_m;
    proxy.constrain(shape, pose, planes);
    worst = std::max(worst, tool_penetration(o, pose, shape));
    last_raw_pen = planes.max_penetration_m();
    if ((pose.tip_m - raw).norm() > 1e-6) ++steps_blocked;
    ASSERT_TRUE(proxy.has_free());
  }
  // The device went 10 mm past the outer table along the line (behind the plane of the tilted
  // surface a little more); the pose the physics steps stayed outside.
  EXPECT_GT(last_raw_pen, 0.009);
  EXPECT_LT(last_raw_pen, 0.010 + 2 * shape.tip_radius_m);
  EXPECT_LT(worst, kTolerance_m);
  EXPECT_GE(steps_blocked, 19);
}

TEST(interaction_tool_proxy, JumpThroughTheShellIsHeldWhereItCameFrom) {
  const RigidObstacle& o = skull();
  const ToolShape shape = probe_shape();
  const mesh::Vec3 down(0, 0, -1);
  const mesh::Vec3 surface = testing::first_bone(o, skull_centre() + mesh::Vec3(0, 0, 0.15), down, 0.2);
  // Past the bone: the first free point below the outer table (the gap between bone and brain).
  mesh::Vec3 below = surface;
  while (o.inside(below)) below += 5e-5 * down;
  below += 0.001 * down;
  ASSERT_FALSE(o.inside(below));
  ToolProxy proxy(o);
  ObstaclePlanes planes;
  ToolPose pose;
  pose.axis = -down;
  pose.tip_m = surface - (shape.tip_radius_m + 0.001) * down;
  proxy.constrain(shape, pose, planes);
  ASSERT_TRUE(proxy.has_free());
  // One step from 1 mm above the bone to below it: held above.
  pose.tip_m = below;
  proxy.constrain(shape, pose, planes);
  EXPECT_LT(tool_penetration(o, pose, shape), kTolerance_m);
  // Above where the line enters the bone, not in the gap under the shell (outside too).
  EXPECT_GT((pose.tip_m - surface).dot(-down), 0.0);
  EXPECT_GT(planes.max_penetration_m(), 0.005);
}

// A device that moved several steps' worth at once in free space (the server missed steps) is
// followed at once: the physics pose never lags behind an unobstructed device.
TEST(interaction_tool_proxy, FreeJumpIsFollowedAtOnce) {
  const RigidObstacle& o = skull();
  const ToolShape shape = probe_shape();
  const scene::RigidOpening& hole = testing::brain_skull_model().rigid.front().openings.front();
  ToolProxy proxy(o);
  ObstaclePlanes planes;
  ToolPose pose;
  pose.axis = hole.axis;
  pose.tip_m = hole.center_m + 0.04 * hole.axis;
  proxy.constrain(shape, pose, planes);
  for (double jump : {0.004, 0.008}) {  // 4 mm then 8 mm in one step, above the 3 mm reach
    const mesh::Vec3 raw = pose.tip_m - jump * hole.axis;
    pose.tip_m = raw;
    proxy.constrain(shape, pose, planes);
    EXPECT_EQ(pose.tip_m, raw) << jump;
    EXPECT_EQ(proxy.free_tip_m(), raw);
  }
}

// The per-step query and projection allocate nothing once the proxy exists (the server's 1 kHz
// step): the skull approach (planes, projection) and a pose beside the rim of the opening.
TEST(interaction_tool_proxy, ConstrainDoesNotAllocate) {
  const RigidObstacle& o = skull();
  const ToolShape shape = probe_shape();
  const mesh::Vec3 down(0, 0, -1);
  const mesh::Vec3 surface = testing::first_bone(o, skull_centre() + mesh::Vec3(0, 0, 0.15), down, 0.2);
  const scene::RigidOpening& hole = testing::brain_skull_model().rigid.front().openings.front();
  ToolProxy proxy(o), rim(o);
  ObstaclePlanes planes;
  ToolPose pose;
  pose.axis = -down;
  pose.tip_m = surface - 0.007 * down;
  proxy.constrain(shape, pose, planes);  // first pose: the free check
  const long before = neurosim::testing::allocations_on_this_thread();
  int with_planes = 0;
  for (int k = 0; k < 40; ++k) {
    pose.tip_m = surface + (0.0005 * k - 0.007) * down;
    pose.axis = -down;
    proxy.constrain(shape, pose, planes);
    with_planes += planes.count > 0;
  }
  const long mid = neurosim::testing::allocations_on_this_thread();
  for (int k = 0; k < 40; ++k) {
    pose.axis = hole.axis;
    pose.tip_m = hole.center_m + 0.02 * hole.axis - 0.0005 * k * hole.axis;
    rim.constrain(shape, pose, planes);
    with_planes += planes.count > 0;
  }
  const long after = neurosim::testing::allocations_on_this_thread();
  EXPECT_GT(with_planes, 30);
  // The second proxy's first pose ran the free check (no allocation either).
  EXPECT_EQ(mid - before, 0);
  EXPECT_EQ(after - mid, 0);
}

// Through the craniotomy along its axis: never blocked (the physics pose is the device's), and
// the tissue force equals a State stepped with the raw poses (the 7 mm brain under the skull).
TEST(interaction_tool_proxy, ThroughTheOpeningUnblockedToTheCerebellum) {
  const RigidObstacle& o = *brain7_skull().skull;
  const ToolShape shape = brain7_skull().shape;
  const scene::Model& model = brain7_skull().model;
  const scene::RigidOpening& hole = model.rigid.front().openings.front();
  const auto sim_model = build_model(model);
  StatePtr with_proxy = make_state(*sim_model), raw_state = make_state(*sim_model);
  ToolProxy proxy(o);
  ObstaclePlanes planes;
  std::vector<ToolPose> a(1), b(1);
  std::vector<ToolContact> ca, cb;
  StepStats sa, sb;
  int contact_steps = 0;
  double max_force = 0.0;
  const mesh::Vec3 start = hole.center_m + 0.04 * hole.axis;
  for (int k = 0; k < 160 && contact_steps < 10; ++k) {
    ToolPose pose;
    pose.tip_m = start - (k * 0.0005) * hole.axis;
    pose.axis = hole.axis;
    b[0] = pose;
    proxy.constrain(shape, pose, planes);
    ASSERT_EQ(pose.tip_m, b[0].tip_m) << "blocked at step " << k;
    EXPECT_EQ(planes.max_penetration_m(), 0.0);
    a[0] = pose;
    step(*sim_model, *with_proxy, a, ca, sa);
    step(*sim_model, *raw_state, b, cb, sb);
    ASSERT_EQ(ca[0].in_contact, cb[0].in_contact);
    EXPECT_EQ(ca[0].force_n, cb[0].force_n);
    if (ca[0].in_contact) {
      ++contact_steps;
      EXPECT_EQ(model.meshes[static_cast<std::size_t>(ca[0].mesh)].id, "brain");
      max_force = std::max(max_force, ca[0].force_n.norm());
    }
  }
  EXPECT_EQ(contact_steps, 10);
  EXPECT_GT(max_force, 0.0);
  // The contact is the cerebellum's (tissue label 2 around the touched nodes).
  const auto& brain = model.meshes.front();
  int cerebellum = -1;
  for (std::size_t i = 0; i < brain.tissues.size(); ++i)
    if (brain.tissues[i].name == "cerebellum") cerebellum = brain.tissues[i].label;
  ASSERT_GE(cerebellum, 0);
  bool touches_cerebellum = false;
  for (int n : ca[0].nodes)
    for (std::size_t t = 0; t < brain.mesh.num_tets() && !touches_cerebellum; ++t) {
      const auto& tet = brain.mesh.tets()[t];
      if (brain.mesh.tet_labels()[t] == cerebellum &&
          (tet[0] == n || tet[1] == n || tet[2] == n || tet[3] == n))
        touches_cerebellum = true;
    }
  EXPECT_TRUE(touches_cerebellum);
}

// The step's "pose" phase is this proxy, one per station (ToolPose::station): two stations
// stepped together on brain_skull, one driven into the top of the skull past where its raw pose
// reaches the brain, one through the craniotomy onto the cerebellum, give exactly what the
// service gave when it held each with its own ToolProxy and stepped the scene without the skull:
// the same held tips, planes and forces; the top station never touches the brain (the 7 mm
// brain under the skull).
TEST(interaction_tool_proxy, TheStepHoldsEachStationByItsOwnProxy) {
  const RigidObstacle& o = *brain7_skull().skull;
  const ToolShape shape = brain7_skull().shape;
  const scene::Model& model = brain7_skull().model;
  scene::Model no_skull = model;
  no_skull.rigid.clear();
  const auto with_skull = build_model(model), tissue = build_model(no_skull);
  auto stepped = Simulation::from_model(with_skull);
  StatePtr reference = make_state(*tissue), raw = make_state(*tissue);
  const mesh::Vec3 down(0, 0, -1);
  const mesh::Vec3 top = testing::first_bone(o, skull_centre(o) + mesh::Vec3(0, 0, 0.15), down, 0.2);
  const scene::RigidOpening& hole = model.rigid.front().openings.front();
  ToolProxy top_proxy(o), hole_proxy(o);
  std::vector<ToolPose> poses(2), held(2), raw_top(1);
  std::vector<ToolContact> c, ref, cr;
  StepStats stats;
  ObstaclePlanes top_planes, hole_planes;
  int raw_touches = 0, held_steps = 0, hole_contacts = 0;
  for (int k = 0; k < 140; ++k) {
    // Top: from 5 mm above the tip's contact, 0.2 mm per step (23 mm); opening: 0.5 mm per step
    // from 40 mm outside along its axis, then held.
    poses[0].tip_m = top - (shape.tip_radius_m + 0.005) * down + (0.0002 * k) * down;
    poses[0].axis = -down;
    poses[0].station = 7;
    poses[1].tip_m = hole.center_m + (0.04 - 0.0005 * std::min(k, 100)) * hole.axis;
    poses[1].axis = hole.axis;
    poses[1].station = 3;
    held = poses;
    top_proxy.constrain(shape, held[0], top_planes);
    hole_proxy.constrain(shape, held[1], hole_planes);
    stepped->step(poses, c, stats);
    step(*tissue, *reference, held, ref, stats);
    raw_top[0] = poses[0];
    step(*tissue, *raw, raw_top, cr, stats);
    raw_touches += cr[0].in_contact ? 1 : 0;
    ASSERT_EQ(c[0].held_tip_m, held[0].tip_m) << "step " << k;
    ASSERT_EQ(c[1].held_tip_m, held[1].tip_m) << "step " << k;
    ASSERT_EQ(c[0].rigid_planes.count, top_planes.count) << "step " << k;
    ASSERT_EQ(c[1].rigid_planes.count, hole_planes.count) << "step " << k;
    EXPECT_EQ(c[0].rigid_planes.max_penetration_m(), top_planes.max_penetration_m());
    for (int t = 0; t < 2; ++t) {
      ASSERT_EQ(c[static_cast<std::size_t>(t)].in_contact, ref[static_cast<std::size_t>(t)].in_contact)
          << "step " << k << " tool " << t;
      EXPECT_EQ(c[static_cast<std::size_t>(t)].force_n, ref[static_cast<std::size_t>(t)].force_n)
          << "step " << k << " tool " << t;
    }
    EXPECT_FALSE(c[0].in_contact) << "step " << k << ": the brain touched through the skull";
    held_steps += top_planes.max_penetration_m() > 1e-3 ? 1 : 0;
    hole_contacts += c[1].in_contact ? 1 : 0;
  }
  EXPECT_GT(raw_touches, 10) << "the raw top path should reach the brain through the bone";
  EXPECT_GT(held_steps, 10);
  EXPECT_GT(hole_contacts, 10);
  // A station that left is forgotten: its next pose starts afresh, as a new proxy's would.
  stepped->reset_station(7);
  top_proxy.reset();
  poses[0].tip_m = top - (shape.tip_radius_m + 0.002) * down;
  held = poses;
  top_proxy.constrain(shape, held[0], top_planes);
  stepped->step(poses, c, stats);
  EXPECT_EQ(c[0].held_tip_m, held[0].tip_m);
  // Two poses of one station in a step are refused, and the proxies are left as they were.
  std::vector<ToolPose> twice{poses[0], poses[0]};
  EXPECT_THROW(stepped->step(twice, c, stats), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::interaction
