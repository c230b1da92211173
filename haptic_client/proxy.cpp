#include "haptic_client/proxy.hpp"

#include <Eigen/LU>

#include <cmath>
#include <limits>

namespace neurosim::haptic {

namespace {

constexpr double kFeasibleTol = 1e-10;     // a point this close behind a plane is on it, unit m
constexpr double kMultiplierTol = -1e-12;  // Lagrange multiplier >= 0 (KKT), unit m
constexpr double kMinGramDet = 1e-8;       // normals this close to dependent: not an active set

// Candidate for active set S (indices idx[0..k)): q = x + N lambda with N^T q = b_S, i.e.
// (N^T N) lambda = b_S - N^T x. False if the normals are (nearly) dependent.
bool solve_active(const RigidPlaneSet& s, const Eigen::Vector3d& x, const std::uint8_t* idx,
                  std::size_t k, Eigen::Vector3d& q, bool& multipliers_ok) {
  q = x;
  multipliers_ok = true;
  if (k == 0) return true;
  Eigen::Matrix3d n = Eigen::Matrix3d::Zero();
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < k; ++i) {
    const RigidPlane& p = s.planes[idx[i]];
    n.col(static_cast<Eigen::Index>(i)) = p.normal;
    r[static_cast<Eigen::Index>(i)] = -p.distance(x);  // b_i - n_i . x
  }
  Eigen::Vector3d lambda = Eigen::Vector3d::Zero();
  if (k == 1) {
    lambda[0] = r[0];
  } else if (k == 2) {
    const Eigen::Matrix2d g = n.leftCols<2>().transpose() * n.leftCols<2>();
    const double det = g.determinant();
    if (!(det > kMinGramDet)) return false;
    lambda.head<2>() = g.inverse() * r.head<2>();
  } else {
    const Eigen::Matrix3d g = n.transpose() * n;
    const double det = g.determinant();
    if (!(det > kMinGramDet)) return false;
    lambda = g.inverse() * r;
  }
  for (std::size_t i = 0; i < k; ++i)
    if (lambda[static_cast<Eigen::Index>(i)] < kMultiplierTol) multipliers_ok = false;
  q = x + n.leftCols(static_cast<Eigen::Index>(k)) * lambda.head(static_cast<Eigen::Index>(k));
  return true;
}

// Largest violation of any plane at q (<= 0: free), unit m.
double max_violation(const RigidPlaneSet& s, const Eigen::Vector3d& q) {
  double v = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < s.count; ++i) v = std::max(v, -s.planes[i].distance(q));
  return v;
}

}  // namespace

bool RigidPlaneSet::valid(const RigidPlane& p) {
  const double nn = p.normal.norm();
  return p.point_m.allFinite() && p.normal.allFinite() && std::isfinite(p.penetration_m) &&
         std::abs(nn - 1) <= kUnitNormalTolerance;
}

bool RigidPlaneSet::add(const RigidPlane& p) {
  if (count >= kMaxRigidPlanes || !valid(p)) return false;
  RigidPlane& q = planes[count++];
  q = p;
  q.normal /= p.normal.norm();
  return true;
}

bool RigidPlaneSet::add(const double point_m[3], const double normal[3], double penetration_m) {
  RigidPlane p;
  p.point_m = Eigen::Vector3d(point_m[0], point_m[1], point_m[2]);
  p.normal = Eigen::Vector3d(normal[0], normal[1], normal[2]);
  p.penetration_m = penetration_m;
  return add(p);
}

void Proxy::reset() { result_ = ProxyResult{}; }

const ProxyResult& Proxy::update(const RigidPlaneSet& s, const Eigen::Vector3d& x) {
  ProxyResult best;
  best.proxy_m = x;
  // Free already (the common case): the proxy is the device.
  if (s.count == 0 || max_violation(s, x) <= kFeasibleTol) {
    result_ = best;
    return result_;
  }
  // Active-set search for the KKT point of min |q - x|^2 s.t. n_i . (q - p_i) >= 0: q on the
  // planes of S, multipliers >= 0, all other planes satisfied. The QP is strictly convex, so the
  // first set that passes is the optimum; in 3-D one with <= 3 independent normals exists
  // (Caratheodory). The previous tick's set is tried first (the contact rarely changes).
  Eigen::Vector3d q;
  bool mult_ok = false;
  double least_violation = std::numeric_limits<double>::infinity();
  Eigen::Vector3d least_q = x;
  auto try_set = [&](const std::uint8_t* idx, std::size_t k) {
    for (std::size_t i = 0; i < k; ++i)
      if (idx[i] >= s.count) return false;
    if (!solve_active(s, x, idx, k, q, mult_ok)) return false;
    const double viol = max_violation(s, q);
    if (viol < least_violation) {
      least_violation = viol;
      least_q = q;
    }
    if (!mult_ok || viol > kFeasibleTol) return false;
    best.proxy_m = q;
    best.active = k;
    for (std::size_t i = 0; i < 3; ++i) best.active_index[i] = i < k ? idx[i] : 0;
    return true;
  };
  bool found = result_.active > 0 && try_set(result_.active_index.data(), result_.active);
  const auto n = static_cast<std::uint8_t>(s.count);
  std::uint8_t idx[3];
  for (std::uint8_t a = 0; a < n && !found; ++a) {
    idx[0] = a;
    found = try_set(idx, 1);
  }
  for (std::uint8_t a = 0; a < n && !found; ++a)
    for (std::uint8_t b = a + 1; b < n && !found; ++b) {
      idx[0] = a;
      idx[1] = b;
      found = try_set(idx, 2);
    }
  for (std::uint8_t a = 0; a < n && !found; ++a)
    for (std::uint8_t b = a + 1; b < n && !found; ++b)
      for (std::uint8_t c = b + 1; c < n && !found; ++c) {
        idx[0] = a;
        idx[1] = b;
        idx[2] = c;
        found = try_set(idx, 3);
      }
  if (!found) {
    // Contradictory planes (no free point): the least violating candidate, counted.
    best.proxy_m = least_q;
    best.active = 0;
    best.feasible = false;
    ++counters_.infeasible;
  }
  best.blocked = (best.proxy_m - x).squaredNorm() > 0;
  result_ = best;
  return result_;
}

}  // namespace neurosim::haptic
