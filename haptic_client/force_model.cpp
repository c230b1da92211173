#include "haptic_client/force_model.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::haptic {

namespace {

void require(bool ok, const char* field, double value, const char* rule) {
  if (!ok)
    throw std::invalid_argument(std::string("haptic force model: ") + field + " = " +
                                std::to_string(value) + " must be " + rule);
}

// The part of v across the active planes of a proxy result, N (N^T N)^-1 N^T v (the proxy's
// active set has independent normals); zero along them. Fixed sizes: no allocation.
Eigen::Vector3d across_active(const RigidPlaneSet& s, const ProxyResult& r,
                              const Eigen::Vector3d& v) {
  const auto normal = [&](std::size_t i) -> const Eigen::Vector3d& {
    return s.planes[r.active_index[i]].normal;
  };
  if (r.active == 1) return normal(0) * normal(0).dot(v);
  if (r.active == 2) {
    Eigen::Matrix<double, 3, 2> n;
    n << normal(0), normal(1);
    const Eigen::Matrix2d g = n.transpose() * n;
    return n * (g.inverse() * (n.transpose() * v));
  }
  if (r.active == 3) return v;  // three independent normals span space
  return Eigen::Vector3d::Zero();
}

bool finite(const ContactModelData& m) {
  if (m.num_relaxing > kMaxRelaxingForces) return false;
  for (std::size_t i = 0; i < m.num_relaxing; ++i)
    if (!m.relaxing[i].force_n.allFinite() || !std::isfinite(m.relaxing[i].tau_s) ||
        !(m.relaxing[i].tau_s > 0))
      return false;
  return m.x0_m.allFinite() && m.f0_n.allFinite() && m.k_n_per_m.allFinite() &&
         m.normal.allFinite() && std::isfinite(m.validity_radius_m);
}

}  // namespace

void ForceModelConfig::validate() const {
  auto pos = [](double v) { return std::isfinite(v) && v > 0; };
  auto nonneg = [](double v) { return std::isfinite(v) && v >= 0; };
  require(pos(period_s), "period_s", period_s, "finite and > 0");
  require(pos(max_force_n), "max_force_n", max_force_n, "finite and > 0");
  require(pos(max_stiffness_n_per_m), "max_stiffness_n_per_m", max_stiffness_n_per_m,
          "finite and > 0");
  require(nonneg(max_damping_n_s_per_m), "max_damping_n_s_per_m", max_damping_n_s_per_m,
          "finite and >= 0");
  require(std::isfinite(damping_n_s_per_m), "damping_n_s_per_m", damping_n_s_per_m, "finite");
  require(pos(passivity_margin), "passivity_margin", passivity_margin, "finite and > 0");
  require(pos(force_scale), "force_scale", force_scale, "finite and > 0");
  require(pos(workspace_scale), "workspace_scale", workspace_scale, "finite and > 0");
  require(nonneg(blend_s), "blend_s", blend_s, "finite and >= 0");
  require(nonneg(ramp_in_s), "ramp_in_s", ramp_in_s, "finite and >= 0");
  require(pos(model_timeout_s), "model_timeout_s", model_timeout_s, "finite and > 0");
  require(nonneg(fade_s), "fade_s", fade_s, "finite and >= 0");
  require(pos(max_force_step_n), "max_force_step_n", max_force_step_n, "finite and > 0");
  require(std::isfinite(wall_stiffness_n_per_m) && wall_stiffness_n_per_m != 0,
          "wall_stiffness_n_per_m", wall_stiffness_n_per_m, "finite and > 0 (or < 0: automatic)");
}

ForceModel::ForceModel(const ForceModelConfig& config) : cfg_(config) {
  cfg_.validate();
  const double T = cfg_.period_s;
  // Virtual damping b (device side): enough for K < 2b/T with margin, within what the device can
  // render.
  damping_ = cfg_.damping_n_s_per_m >= 0
                 ? cfg_.damping_n_s_per_m
                 : std::min(cfg_.max_damping_n_s_per_m,
                            cfg_.passivity_margin * cfg_.max_stiffness_n_per_m * T / 2);
  double k_device = cfg_.max_stiffness_n_per_m;
  if (cfg_.enforce_passivity)
    k_device = std::min(k_device, 2 * damping_ / (T * cfg_.passivity_margin));
  // Device stiffness = force_scale * K_scene * workspace_scale.
  k_limit_scene_ = k_device / (cfg_.force_scale * cfg_.workspace_scale);
  // The rigid wall may be as stiff as the device renders passively, not stiffer.
  if (cfg_.wall_stiffness_n_per_m > k_device)
    throw std::invalid_argument("haptic force model: wall_stiffness_n_per_m = " +
                                std::to_string(cfg_.wall_stiffness_n_per_m) +
                                " must be <= the passivity-limited device stiffness " +
                                std::to_string(k_device) + " N/m (K < 2b/T with margin)");
  const double k_wall_device =
      cfg_.wall_stiffness_n_per_m > 0 ? cfg_.wall_stiffness_n_per_m : k_device;
  k_wall_scene_ = k_wall_device / (cfg_.force_scale * cfg_.workspace_scale);
}

Eigen::Vector3d ForceModel::wall_spring(const RigidPlaneSet& planes, const Eigen::Vector3d& x,
                                        Proxy& proxy) const {
  if (planes.count == 0) return Eigen::Vector3d::Zero();
  return k_wall_scene_ * (proxy.update(planes, x).proxy_m - x);
}

void ForceModel::reset() {
  has_current_ = false;
  proxy_.reset();
  blend_offset_.setZero();
  blend_rate_ = 0;
  gain_ = 0;
  stale_ = false;
  last_force_.setZero();
}

Eigen::Vector3d ForceModel::extrapolate(const ContactModelData& m, const Eigen::Vector3d& x,
                                        double age_s) {
  if (!m.in_contact) return Eigen::Vector3d::Zero();
  Eigen::Vector3d d = x - m.x0_m;
  const double r = m.validity_radius_m;
  const double dn = d.norm();
  if (r > 0 && dn > r) d *= r / dn;  // extrapolate only within the validity radius
  Eigen::Vector3d f = m.f0_n + m.k_n_per_m * d;
  // Viscoelastic tissue: f0 relaxes since the model's time (each part by at most all of it).
  const double s = std::max(0.0, age_s);
  for (std::size_t i = 0; i < m.num_relaxing; ++i)
    f += std::expm1(-s / m.relaxing[i].tau_s) * m.relaxing[i].force_n;
  // Unilateral: tissue pushes, never pulls the tool in.
  if (m.normal.squaredNorm() > 0 && f.dot(m.normal) < 0) return Eigen::Vector3d::Zero();
  return f;
}

namespace {
// Age of a model at loop time now_ns (>= 0), unit s.
double age_of(const ContactModelData& m, std::int64_t now_ns) {
  return std::max(0.0, 1e-9 * static_cast<double>(now_ns - m.reference_time_ns));
}
}  // namespace

bool ForceModel::accept(const ContactModelData& m, const Eigen::Vector3d& x, std::int64_t now_ns) {
  if (!finite(m) || m.validity_radius_m < 0) {
    ++counters_.nan_models;
    return false;
  }
  ContactModelData next = m;
  // Rigid planes: keep the valid ones (any Link may fill them; DdsLink has checked already).
  next.rigid_planes.clear();
  for (std::size_t i = 0; i < m.rigid_planes.count && i < kMaxRigidPlanes; ++i)
    if (!next.rigid_planes.add(m.rigid_planes.planes[i])) ++counters_.planes_dropped;
  const double nn = next.normal.norm();
  if (nn > 0) next.normal /= nn;
  // Passivity: the rendered stiffness may not exceed the limit (operator norm, scene frame).
  // The whole model is scaled, f0 with K: from one model to the next f0 changes at the
  // tissue's true stiffness, so scaling K alone would still render the tissue's stiffness
  // (a bang-bang limit cycle against a stiff mesh). Scaled, the device feels the tissue
  // softened to the limit, consistently between and within models.
  const double k = next.k_n_per_m.operatorNorm();
  if (k > k_limit_scene_) {
    const double s = k_limit_scene_ / k;
    next.k_n_per_m *= s;
    next.f0_n *= s;
    for (std::size_t i = 0; i < next.num_relaxing; ++i) next.relaxing[i].force_n *= s;
    ++counters_.stiffness_limited;
  }
  if (has_current_ && cfg_.blend_s > 0 && x.allFinite()) {
    // Keep rendering what we rendered: the jump becomes an offset that fades out. The wall's
    // spring too (planes moved, appeared or vanished), each plane set on its own proxy.
    Proxy old_proxy = proxy_, new_proxy = proxy_;
    blend_offset_ += extrapolate(current_, x, age_of(current_, now_ns)) +
                     wall_spring(current_.rigid_planes, x, old_proxy) -
                     extrapolate(next, x, age_of(next, now_ns)) -
                     wall_spring(next.rigid_planes, x, new_proxy);
    blend_rate_ = std::max(blend_rate_, blend_offset_.norm() / cfg_.blend_s);
  }
  current_ = next;
  has_current_ = true;
  ++counters_.models_accepted;
  return true;
}

ForceOutput ForceModel::step(const ForceInput& in) {
  ForceOutput out;
  // Elapsed loop time (not ticks): late ticks still fade within fade_s of wall time.
  const double T = have_last_now_
                       ? std::clamp(1e-9 * static_cast<double>(in.now_ns - last_now_ns_), 0.0, 0.1)
                       : cfg_.period_s;
  last_now_ns_ = in.now_ns;
  have_last_now_ = true;
  // Blend offset shrinks linearly (rate fixed at the latest jump, never slower).
  const double off = blend_offset_.norm();
  if (off > 0) {
    const double left = std::max(0.0, off - blend_rate_ * T);
    blend_offset_ *= left / off;
    if (left == 0) blend_rate_ = 0;
  }
  if (in.new_model != nullptr) accept(*in.new_model, in.position_m, in.now_ns);

  // Server gone (liveliness): the model is treated as stale at once, so the force fades to zero
  // within fade_s with bounded steps; then the model is dropped and a returning server ramps in.
  if (!in.server_alive && !server_gone_) ++counters_.server_lost;
  server_gone_ = !in.server_alive;

  if (!in.position_m.allFinite() || !in.velocity_m_per_s.allFinite()) {
    ++counters_.nan_inputs;
    gain_ = 0;  // ramp in again once inputs are sane: no kick
    last_force_.setZero();
    out.has_model = has_current_;
    return out;
  }

  double age = 0;
  if (has_current_) age = age_of(current_, in.now_ns);
  const bool stale = !has_current_ || age > cfg_.model_timeout_s || server_gone_;
  if (stale && has_current_ && !stale_) ++counters_.timeouts;
  stale_ = stale;
  // One gain for ramp-in and watchdog fade: up over ramp_in_s, down over fade_s.
  if (stale) {
    gain_ = cfg_.fade_s > 0 ? gain_ - T / cfg_.fade_s : 0;
    // Tied to the model's age as well, so late ticks cannot stretch it: zero at timeout + fade.
    if (has_current_ && !server_gone_ && cfg_.fade_s > 0)
      gain_ = std::min(gain_, 1 - (age - cfg_.model_timeout_s) / cfg_.fade_s);
  } else
    gain_ = cfg_.ramp_in_s > 0 ? gain_ + T / cfg_.ramp_in_s : 1;
  gain_ = std::clamp(gain_, 0.0, 1.0);
  if (gain_ < 1e-9) gain_ = 0;  // rounding of the fade steps must not leave a residue

  out.has_model = has_current_;
  out.gain = gain_;
  out.model_age_s = age;
  out.model_sequence = has_current_ ? current_.tool_sequence : 0;
  out.in_contact = has_current_ && current_.in_contact;

  // Rigid obstacles: the proxy follows the device on the free side of the newest model's planes
  // (stale planes too: they are rigid, valid until replaced; the gain fades them with the
  // tissue force on a timeout).
  out.proxy_m = in.position_m;
  if (has_current_ && current_.rigid_planes.count > 0) {
    const std::uint64_t infeasible = proxy_.counters().infeasible;
    const ProxyResult& pr = proxy_.update(current_.rigid_planes, in.position_m);
    counters_.planes_infeasible += proxy_.counters().infeasible - infeasible;
    out.proxy_m = pr.proxy_m;
    out.rigid_contact = pr.blocked;
    out.active_planes = pr.active;
    out.rigid_planes = current_.rigid_planes.count;
  }

  Eigen::Vector3d fd = Eigen::Vector3d::Zero();
  if (has_current_ && gain_ > 0) {
    // Extrapolate the newest model; blend offset from the model change.
    const Eigen::Vector3d f = extrapolate(current_, in.position_m, age) + blend_offset_;
    fd = cfg_.force_scale * f;
    const Eigen::Vector3d& n = current_.normal;
    if (current_.in_contact && n.squaredNorm() > 0 && fd.squaredNorm() > 0) {
      // Virtual-coupling damping along the normal (device velocity = scene velocity / scale).
      const double vn = in.velocity_m_per_s.dot(n) / cfg_.workspace_scale;
      fd -= damping_ * vn * n;
      const double fn = fd.dot(n);
      if (fn < 0) fd -= fn * n;  // still unilateral
    }
    if (out.rigid_contact) {
      // Wall: proxy spring k_wall (proxy - x) plus the passivity damping b on the velocity
      // across the active planes (none along them: frictionless sliding). Device side.
      const Eigen::Vector3d d = out.proxy_m - in.position_m;
      Eigen::Vector3d fw = cfg_.force_scale * k_wall_scene_ * d;
      const Eigen::Vector3d vd = in.velocity_m_per_s / cfg_.workspace_scale;
      fw -= damping_ * across_active(current_.rigid_planes, proxy_.last(), vd);
      // Unilateral: the wall pushes out, never pulls the hand in (damping while leaving).
      const double dn = d.norm();
      if (dn > 0) {
        const double along = fw.dot(d) / dn;
        if (along < 0) fw -= along * d / dn;
      }
      fd += fw;
      out.wall_force_n = gain_ * fw;
    }
    // Clamp to the device first, then the gain: ramp-in and fade scale what the device renders.
    const double mag = fd.norm();
    if (mag > cfg_.max_force_n) fd *= cfg_.max_force_n / mag;
    fd *= gain_;
    if (!fd.allFinite()) {
      ++counters_.nan_outputs;
      gain_ = 0;
      last_force_.setZero();
      out.force_n.setZero();
      return out;
    }
  }
  // Bound the step (ramp, blend and fade stay below it normally). It is a rate, per nominal
  // period: a late tick may move as far as the ticks it replaced, so the fade is never late.
  // NaN input is the one exception (zero at once, above).
  const double bound = cfg_.max_force_step_n * std::max(1.0, T / cfg_.period_s);
  const Eigen::Vector3d delta = fd - last_force_;
  const double dm = delta.norm();
  if (dm > bound) fd = last_force_ + delta * (bound / dm);
  last_force_ = fd;
  out.force_n = fd;
  if (server_gone_ && gain_ <= 0 && fd.squaredNorm() == 0) reset();  // drop the dead server's model
  return out;
}

}  // namespace neurosim::haptic
