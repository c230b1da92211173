// The proxy (god-object) against rigid constraint planes: plane, edge and corner contacts, the
// projection checked against an independent method (Dykstra's alternating projections) on
// random plane sets, plane validation on arrival (DdsLink's copy) and in the force model.
#include "haptic_client/proxy.hpp"
#include "haptic_client/dds_link.hpp"
#include "haptic_client/force_model.hpp"
#include "idl/wire/types.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace nh = neurosim::haptic;
using Eigen::Vector3d;

namespace {

nh::RigidPlane plane(const Vector3d& p, const Vector3d& n) {
  nh::RigidPlane r;
  r.point_m = p;
  r.normal = n.normalized();
  return r;
}

// Dykstra's alternating projections onto half-spaces: converges to the Euclidean projection
// onto their intersection (an independent reference for the active-set solve).
Vector3d dykstra(const nh::RigidPlaneSet& s, const Vector3d& x) {
  Vector3d q = x;
  std::vector<Vector3d> inc(s.count, Vector3d::Zero());
  for (int it = 0; it < 200000; ++it) {
    for (std::size_t i = 0; i < s.count; ++i) {
      const Vector3d y = q + inc[i];
      const double d = s.planes[i].distance(y);
      const Vector3d p = d < 0 ? Vector3d(y - d * s.planes[i].normal) : y;
      inc[i] = y - p;
      q = p;
    }
  }
  return q;
}

}  // namespace

TEST(haptic_proxy, FreeDeviceIsItsOwnProxy) {
  nh::RigidPlaneSet s;
  ASSERT_TRUE(s.add(plane(Vector3d::Zero(), Vector3d::UnitZ())));
  nh::Proxy proxy;
  const Vector3d x(0.01, -0.02, 0.003);
  const auto& r = proxy.update(s, x);
  EXPECT_EQ(r.proxy_m, x);
  EXPECT_FALSE(r.blocked);
  EXPECT_EQ(r.active, 0u);
  nh::RigidPlaneSet none;
  EXPECT_EQ(proxy.update(none, Vector3d(0, 0, -1)).proxy_m, Vector3d(0, 0, -1));
}

TEST(haptic_proxy, PlaneEdgeAndCorner) {
  nh::RigidPlaneSet s;
  ASSERT_TRUE(s.add(plane(Vector3d(0, 0, 0.01), Vector3d::UnitZ())));  // floor z >= 0.01
  ASSERT_TRUE(s.add(plane(Vector3d(0.02, 0, 0), Vector3d::UnitX())));  // wall x >= 0.02
  nh::Proxy proxy;
  // Behind the floor only: straight up onto it, one active plane.
  auto r = proxy.update(s, Vector3d(0.05, 0.3, 0.004));
  EXPECT_TRUE(r.blocked);
  EXPECT_EQ(r.active, 1u);
  EXPECT_NEAR((r.proxy_m - Vector3d(0.05, 0.3, 0.01)).norm(), 0, 1e-15);
  // Behind both: onto the edge, the free coordinate (y) follows the device.
  r = proxy.update(s, Vector3d(0.015, -0.2, 0.002));
  EXPECT_EQ(r.active, 2u);
  EXPECT_NEAR((r.proxy_m - Vector3d(0.02, -0.2, 0.01)).norm(), 0, 1e-15);
  // Behind the wall, above the floor: onto the wall only.
  r = proxy.update(s, Vector3d(0.01, 0, 0.05));
  EXPECT_EQ(r.active, 1u);
  EXPECT_NEAR((r.proxy_m - Vector3d(0.02, 0, 0.05)).norm(), 0, 1e-15);
  // A third plane y >= 0: the corner.
  ASSERT_TRUE(s.add(plane(Vector3d::Zero(), Vector3d::UnitY())));
  r = proxy.update(s, Vector3d(0.019, -0.001, 0.009));
  EXPECT_EQ(r.active, 3u);
  EXPECT_NEAR((r.proxy_m - Vector3d(0.02, 0, 0.01)).norm(), 0, 1e-15);
  // A V-groove (normals 1 rad apart), device below its bottom line: both planes hold it.
  nh::RigidPlaneSet w;
  ASSERT_TRUE(w.add(plane(Vector3d::Zero(), Vector3d(0, std::sin(0.5), std::cos(0.5)))));
  ASSERT_TRUE(w.add(plane(Vector3d::Zero(), Vector3d(0, -std::sin(0.5), std::cos(0.5)))));
  r = proxy.update(w, Vector3d(0, 0.001, -0.004));
  EXPECT_EQ(r.active, 2u);  // the groove's bottom line (the x axis)
  EXPECT_NEAR(r.proxy_m.norm(), 0, 1e-15);
  EXPECT_EQ(proxy.counters().infeasible, 0u);
}

TEST(haptic_proxy, MatchesDykstraProjectionOnRandomPlaneSets) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  std::uniform_int_distribution<int> count(1, 8);
  nh::Proxy proxy;
  int blocked = 0, edges = 0, corners = 0;
  for (int trial = 0; trial < 300; ++trial) {
    // Planes around a free region containing the origin (offsets r > 0): never empty.
    nh::RigidPlaneSet s;
    const int n = count(rng);
    for (int i = 0; i < n; ++i) {
      Vector3d nrm(u(rng), u(rng), u(rng));
      if (nrm.norm() < 0.1) nrm = Vector3d::UnitZ();
      nrm.normalize();
      const double r = 0.005 + 0.01 * (u(rng) + 1);
      ASSERT_TRUE(s.add(plane(-r * nrm, nrm)));
    }
    const Vector3d x = 0.04 * Vector3d(u(rng), u(rng), u(rng));
    const auto& res = proxy.update(s, x);
    ASSERT_TRUE(res.feasible) << "trial " << trial;
    for (std::size_t i = 0; i < s.count; ++i)
      ASSERT_GE(s.planes[i].distance(res.proxy_m), -1e-10) << "trial " << trial;
    const Vector3d ref = dykstra(s, x);
    ASSERT_NEAR((res.proxy_m - ref).norm(), 0, 1e-7) << "trial " << trial << " planes " << n;
    blocked += res.blocked ? 1 : 0;
    edges += res.active == 2 ? 1 : 0;
    corners += res.active == 3 ? 1 : 0;
  }
  // The draw really exercised all three contact kinds.
  EXPECT_GT(blocked, 100);
  EXPECT_GT(edges, 10);
  EXPECT_GT(corners, 5);
}

TEST(haptic_proxy, ContradictoryPlanesAreCountedNotTrusted) {
  nh::RigidPlaneSet s;  // z >= 0.01 and z <= -0.01: no free point
  ASSERT_TRUE(s.add(plane(Vector3d(0, 0, 0.01), Vector3d::UnitZ())));
  ASSERT_TRUE(s.add(plane(Vector3d(0, 0, -0.01), -Vector3d::UnitZ())));
  nh::Proxy proxy;
  const auto& r = proxy.update(s, Vector3d(0, 0, 0));
  EXPECT_FALSE(r.feasible);
  EXPECT_TRUE(r.proxy_m.allFinite());
  EXPECT_EQ(proxy.counters().infeasible, 1u);
}

TEST(haptic_proxy, PlaneSetRefusesInvalidPlanes) {
  nh::RigidPlaneSet s;
  const double p[3] = {0, 0, 0}, nan_p[3] = {0, std::nan(""), 0};
  const double n[3] = {0, 0, 1}, n_long[3] = {0, 0, 1.0005}, n_short[3] = {0, 0, 0.9},
               n_inf[3] = {0, std::numeric_limits<double>::infinity(), 1}, n_zero[3] = {0, 0, 0};
  EXPECT_TRUE(s.add(p, n, 0));
  EXPECT_TRUE(s.add(p, n_long, 0));  // within kUnitNormalTolerance: normalised
  EXPECT_DOUBLE_EQ(s.planes[1].normal.norm(), 1.0);
  EXPECT_FALSE(s.add(nan_p, n, 0));
  EXPECT_FALSE(s.add(p, n_short, 0));
  EXPECT_FALSE(s.add(p, n_inf, 0));
  EXPECT_FALSE(s.add(p, n_zero, 0));
  EXPECT_FALSE(s.add(p, n, std::nan("")));
  EXPECT_EQ(s.count, 2u);
  for (std::size_t i = s.count; i < nh::kMaxRigidPlanes; ++i) EXPECT_TRUE(s.add(p, n, 0));
  EXPECT_FALSE(s.add(p, n, 0)) << "full";
  EXPECT_EQ(s.count, nh::kMaxRigidPlanes);
}

TEST(haptic_proxy, ReceivedContactModelDropsAndCountsBadPlanes) {
  // DdsLink's copy of a received sample: 2 good planes, 3 bad ones (NaN point, infinite
  // penetration, normal of length 0.9).
  neurosim::wire::Sample<neurosim_ContactModel> c;
  c->tool_sequence = 12;
  c->tool_source_time_ns = 345;
  c->in_contact = false;
  c->server_step = 9;
  neurosim_RigidPlane planes[5] = {};
  auto set = [&](int i, double px, double nz, double nx, double pen) {
    planes[i].point_m[0] = px;
    planes[i].normal[0] = nx;
    planes[i].normal[2] = nz;
    planes[i].penetration_m = pen;
  };
  set(0, 0.01, 1, 0, 0);
  set(1, std::nan(""), 1, 0, 0);
  set(2, 0, 1, 0, std::numeric_limits<double>::infinity());
  set(3, 0, 0.9, 0, 0);
  set(4, 0.02, 0, 1, 0.001);
  neurosim::wire::assign(c->rigid_planes, planes, 5);
  nh::ContactModelData m;
  EXPECT_EQ(nh::copy_contact_model(*c, 999, m), 3u);
  EXPECT_EQ(m.tool_sequence, 12u);
  EXPECT_EQ(m.reference_time_ns, 345);
  EXPECT_EQ(m.server_step, 9u);
  ASSERT_EQ(m.rigid_planes.count, 2u);
  EXPECT_EQ(m.rigid_planes.planes[0].point_m, Vector3d(0.01, 0, 0));
  EXPECT_EQ(m.rigid_planes.planes[1].normal, Vector3d(1, 0, 0));
  EXPECT_EQ(m.rigid_planes.planes[1].penetration_m, 0.001);
  // A model without planes clears the previous ones (the buffer is reused).
  neurosim::wire::Sample<neurosim_ContactModel> empty;
  EXPECT_EQ(nh::copy_contact_model(*empty, 999, m), 0u);
  EXPECT_EQ(m.rigid_planes.count, 0u);
  EXPECT_EQ(m.reference_time_ns, 999) << "no echoed source time: arrival time";
  EXPECT_EQ(m.num_relaxing, 0u);
  // Viscoelastic tissue's relaxing parts are copied as sent (the force model checks them).
  neurosim_RelaxingForce parts[2] = {};
  parts[0].force_n[2] = 0.25;
  parts[0].tau_s = 0.5;
  parts[1].force_n[0] = -0.1;
  parts[1].tau_s = 50;
  neurosim::wire::assign(c->relaxing_forces, parts, 2);
  nh::copy_contact_model(*c, 999, m);
  ASSERT_EQ(m.num_relaxing, 2u);
  EXPECT_EQ(m.relaxing[0].force_n, Vector3d(0, 0, 0.25));
  EXPECT_EQ(m.relaxing[0].tau_s, 0.5);
  EXPECT_EQ(m.relaxing[1].force_n, Vector3d(-0.1, 0, 0));
  EXPECT_EQ(m.relaxing[1].tau_s, 50);
}

TEST(haptic_proxy, ForceModelDropsAndCountsBadPlanesFromAnyLink) {
  // A Link other than DdsLink may fill the set directly, bypassing RigidPlaneSet::add.
  nh::ForceModel fm(nh::ForceModelConfig{});
  nh::ContactModelData m;
  m.rigid_planes.planes[0] = plane(Vector3d::Zero(), Vector3d::UnitZ());
  m.rigid_planes.planes[1].normal = Vector3d(0, 0, 2);  // not unit
  m.rigid_planes.planes[2].point_m = Vector3d(0, std::nan(""), 0);
  m.rigid_planes.count = 3;
  nh::ForceInput in;
  in.new_model = &m;
  in.position_m = Vector3d(0, 0, -0.001);
  const nh::ForceOutput out = fm.step(in);
  EXPECT_EQ(fm.counters().planes_dropped, 2u);
  EXPECT_EQ(fm.counters().models_accepted, 1u);
  EXPECT_EQ(out.rigid_planes, 1u);
  EXPECT_TRUE(out.rigid_contact);
  EXPECT_NEAR(out.proxy_m.z(), 0, 1e-15);
}

TEST(haptic_proxy, WallStiffnessAboveThePassiveLimitIsRefused) {
  nh::ForceModelConfig c;
  c.wall_stiffness_n_per_m = 701;  // the Omni's passive limit is 700 N/m
  try {
    nh::ForceModel fm(c);
    FAIL() << "accepted a wall stiffer than the passive limit";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("wall_stiffness_n_per_m"), std::string::npos) << e.what();
  }
  c.wall_stiffness_n_per_m = 0;
  EXPECT_THROW(nh::ForceModel{c}, std::invalid_argument);
  c.wall_stiffness_n_per_m = 350;
  nh::ForceModel soft(c);
  EXPECT_DOUBLE_EQ(soft.wall_stiffness_scene(), 350);
  nh::ForceModel automatic(nh::ForceModelConfig{});
  EXPECT_DOUBLE_EQ(automatic.wall_stiffness_scene(), automatic.scene_stiffness_limit());
}
