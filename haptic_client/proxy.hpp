// Rigid obstacles (the skull) at 1 kHz: the god-object / proxy of Zilles & Salisbury (1995).
//
// The server sends, in each ContactModel, up to 8 constraint planes of rigid obstacles near the
// tool (idl/neurosim.idl, ContactModel.rigid_planes): the tool tip must stay on the free side of
// every plane, n . (x - p) >= 0. The free space is therefore the intersection of half-spaces, a
// convex polyhedron. The proxy is the point of that polyhedron closest to the device position
// x: it follows the device in free space and slides frictionlessly along the planes when the
// device is behind them (Zilles & Salisbury's constrained minimisation of |proxy - x|, with at
// most 3 active constraints in 3-D: plane, edge, corner). For a convex free space the path the
// god-object takes from its previous position ends at exactly this projection, so the proxy
// needs no history; the previous active set is only tried first.
//
// Pure and allocation-free (fixed arrays), no clock: the wall force (stiffness, damping, gain,
// clamp) is applied by ForceModel.
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>

namespace neurosim::haptic {

// Capacity of ContactModel.rigid_planes (idl/neurosim.idl: sequence<RigidPlane, 8>).
constexpr std::size_t kMaxRigidPlanes = 8;
// A received normal is accepted when | |n| - 1 | <= this (then normalised), else dropped.
constexpr double kUnitNormalTolerance = 1e-3;

// One constraint plane of a rigid obstacle (scene frame, SI).
struct RigidPlane {
  Eigen::Vector3d point_m = Eigen::Vector3d::Zero();  // a point of the surface, unit m
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, out of the obstacle into free space
  double penetration_m = 0;  // server's depth of its newest pose behind the plane, unit m
  // Signed distance of x to the plane, > 0 on the free side, unit m.
  double distance(const Eigen::Vector3d& x) const { return normal.dot(x - point_m); }
};

// The planes of one ContactModel: fixed capacity, no allocation.
struct RigidPlaneSet {
  std::array<RigidPlane, kMaxRigidPlanes> planes{};
  std::size_t count = 0;
  void clear() { count = 0; }
  // Checks and appends one received plane: finite point, normal and penetration, unit normal
  // within kUnitNormalTolerance (normalised), room left. False: dropped (the caller counts it).
  bool add(const double point_m[3], const double normal[3], double penetration_m);
  bool add(const RigidPlane& p);
  // The same checks on a plane already in a set (a Link other than DdsLink may fill it).
  static bool valid(const RigidPlane& p);
};

struct ProxyResult {
  Eigen::Vector3d proxy_m = Eigen::Vector3d::Zero();  // closest free point to the device, unit m
  std::size_t active = 0;                             // planes the proxy lies on (0..3)
  std::array<std::uint8_t, 3> active_index{};         // their indices in the set
  bool feasible = true;  // false: the planes leave no free point (proxy = least violating)
  // The device is behind at least one active plane (proxy != device): rigid contact.
  bool blocked = false;
};

struct ProxyCounters {
  std::uint64_t infeasible = 0;  // plane sets with no free point (contradictory planes)
};

// The proxy (god-object): projection of the device position onto the free polyhedron by an
// active-set search over at most 3 active planes (warm-started from the previous tick's set).
class Proxy {
 public:
  // Free point closest to x under `planes` (all planes; x itself when it is free).
  const ProxyResult& update(const RigidPlaneSet& planes, const Eigen::Vector3d& x);
  const ProxyResult& last() const { return result_; }
  const ProxyCounters& counters() const { return counters_; }
  void reset();

 private:
  ProxyResult result_{};
  ProxyCounters counters_{};
};

}  // namespace neurosim::haptic
