#include "server/service/step_loop.hpp"

#include "common/clock.hpp"
#include "common/tool_pose.hpp"

#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace neurosim::service {

using common::monotonic_ns;
using interaction::ToolContact;
using interaction::ToolPose;

const char* step_mode_name(StepMode m) { return m == StepMode::kEvent ? "event" : "clock"; }

void StepLoopDef::validate() const {
  if (period_ns < 1000) throw std::invalid_argument("step period " + std::to_string(period_ns) + " ns is below 1 us");
  if (!(max_step_rate_factor >= 1.0 && max_step_rate_factor <= 100.0))
    throw std::invalid_argument("max_step_rate_factor " + std::to_string(max_step_rate_factor) +
                                " must be in [1, 100]");
  if (step_failure_holdoff_ns < 0) throw std::invalid_argument("step_failure_holdoff_ns is negative");
}

StepLoop::StepLoop(StepLoopDef def, interaction::Simulation& sim, StationAdmission& stations,
                   ContactModelSink& out, std::function<void(const std::string&)> log)
    : def_((def.validate(), def)),
      sim_(sim),
      stations_(stations),
      slots_(stations.slots()),
      out_(out),
      log_(std::move(log)) {
  if (sem_init(&wake_, 0, 0) != 0) throw std::runtime_error("sem_init failed");
  const std::size_t m = slots_.size();
  slot_step_.resize(m);
  models_out_.resize(m);
  poses_by_count_.resize(m + 1);
  contacts_by_count_.resize(m + 1);
  for (std::size_t n = 0; n <= m; ++n) {
    poses_by_count_[n].resize(n);
    contacts_by_count_[n].resize(n);
  }
  // Room for a viscoelastic tissue's relaxing parts (no allocation in the step).
  for (std::size_t i = 0; i < m; ++i)
    wire::reserve(models_out_[i]->relaxing_forces, interaction::kMaxRelaxingForces);
  slot_of_pose_.resize(m);
  all_poses_.resize(m);
  all_slots_.resize(m);
  if (m > static_cast<std::size_t>(interaction::kMaxStations))
    throw std::invalid_argument(std::to_string(m) + " station slots: the simulation tells at most " +
                                std::to_string(interaction::kMaxStations) + " apart");
  if (sim_.rigid_obstacle() != nullptr)
    for (std::size_t i = 0; i < m; ++i) wire::reserve(models_out_[i]->rigid_planes, interaction::kMaxObstaclePlanes);
  step_error_.reserve(256);
}

StepLoop::~StepLoop() { sem_destroy(&wake_); }

void StepLoop::wake() { sem_post(&wake_); }
void StepLoop::stop() { sem_post(&wake_); }

// Event step mode: waits until a pose was handed to a slot (true) or deadline_ns passes (false);
// takes every pending post, so one step serves all the samples that arrived meanwhile.
bool StepLoop::wait_for_sample(std::int64_t deadline_ns) {
  const timespec ts = common::to_timespec(std::max<std::int64_t>(deadline_ns, 0));
  int rc = 0;
  while ((rc = sem_clockwait(&wake_, CLOCK_MONOTONIC, &ts)) != 0 && errno == EINTR) {
  }
  if (rc != 0) return false;  // ETIMEDOUT
  while (sem_trywait(&wake_) == 0) {
  }
  return true;
}

void StepLoop::run(const std::atomic<bool>& running) {
  const bool event = def_.mode == StepMode::kEvent;
  const std::int64_t period_ns = def_.period_ns;
  // Event mode: at most max_step_rate_factor × the scene rate, so a fast station (or a burst)
  // cannot take the CPU from the others; one step serves every station's newest pose.
  const auto min_gap_ns =
      event ? static_cast<std::int64_t>(std::llround(static_cast<double>(period_ns) / def_.max_step_rate_factor))
            : period_ns;
  const std::int64_t start = monotonic_ns();
  std::int64_t next = start + period_ns;  // this step's deadline
  std::int64_t last_start = start - min_gap_ns;
  while (running.load(std::memory_order_relaxed)) {
    bool on_sample = false;
    if (event) {
      on_sample = wait_for_sample(next);
      if (on_sample && monotonic_ns() < last_start + min_gap_ns) common::sleep_until_ns(last_start + min_gap_ns);
    } else {
      common::sleep_until_ns(next);
    }
    if (!running.load(std::memory_order_relaxed)) break;
    const std::int64_t t0 = monotonic_ns();
    // A deadline miss: the step starts more than one period after its deadline (clock: the
    // absolute tick; event: one period after the previous step, i.e. no step for 2 periods).
    const std::int64_t late = t0 - next;
    if (late > period_ns) {
      ++counters_.deadline_misses;
      // Far behind (e.g. the machine stalled): restart the schedule instead of bursting.
      if (late > 20 * period_ns) next = t0;
    }
    (on_sample ? counters_.steps_on_sample : counters_.steps_on_deadline).fetch_add(1, std::memory_order_relaxed);
    step_once();
    last_start = t0;
    // After a sample the deadline restarts from this step; idle: absolute deadlines.
    next = on_sample ? t0 + period_ns : next + period_ns;
    if (after_timing) after_timing(t0, monotonic_ns());
  }
}

void StepLoop::retire(std::size_t i) {
  auto& s = slots_[i];
  if (slot_step_[i].model_written) out_.dispose(*models_out_[i]);
  s.pose.consume();  // drop whatever the last session left
  slot_step_[i] = SlotStep{};
  s.in_contact.store(false, std::memory_order_relaxed);
  sim_.reset_station(static_cast<int>(i));
  s.state.store(kSlotFree, std::memory_order_release);
}

bool StepLoop::try_step(std::size_t n, const std::string** error) {
  interaction::StepStats stats;
  try {
    sim_.step_at(step_time_s_, poses_by_count_[n], contacts_by_count_[n], stats);
    return true;
  } catch (const std::exception& e) {
    step_error_ = e.what();
    if (error != nullptr) *error = &step_error_;
    return false;
  }
}

// The step threw for the poses of n stations (all_poses_/all_slots_): each is stepped alone; the
// ones that fail alone are reset, the rest stepped together again (their answers are this step's).
// On return n is the number of stations answered, in poses_by_count_[n] / contacts_by_count_[n].
void StepLoop::contain_failure(std::size_t& n, const std::string& error) {
  const std::string first_error = error;
  const std::int64_t now_mono = monotonic_ns();
  const std::int64_t now = dds_time();
  const std::uint64_t step = counters_.steps.load(std::memory_order_relaxed) + 1;
  auto reset = [&](std::size_t i, const std::string& why) {
    ++counters_.step_failures;
    auto& ss = slot_step_[i];
    ss.has_pose = false;
    ss.hold_until_ns = now_mono + def_.step_failure_holdoff_ns;
    sim_.reset_station(static_cast<int>(i));
    const PoseSample& p = slots_[i].pose.newest();
    if (log_)
      log_("station '" + std::string(slots_[i].station_id) + "': the step failed for its pose (sequence " +
           std::to_string(p.sequence) + "): " + why + "; the station is reset (zero force, no step for " +
           std::to_string(1e-6 * static_cast<double>(def_.step_failure_holdoff_ns)) +
           " ms), the other stations are served");
    write_model(i, nullptr, step, now);
  };
  std::size_t kept = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const auto i = static_cast<std::size_t>(all_slots_[k]);
    poses_by_count_[1][0] = all_poses_[k];
    const std::string* err = nullptr;
    if (n == 1 || !try_step(1, &err)) {
      reset(i, n == 1 ? first_error : *err);
      continue;
    }
    all_poses_[kept] = all_poses_[k];
    all_slots_[kept] = all_slots_[k];
    ++kept;
  }
  if (kept > 0) {
    for (std::size_t k = 0; k < kept; ++k) {
      poses_by_count_[kept][k] = all_poses_[k];
      slot_of_pose_[k] = all_slots_[k];
    }
    const std::string* err = nullptr;
    if (!try_step(kept, &err)) {
      // Each alone steps, together they do not: none of them is answered this step.
      const std::string why = "together with the others: " + *err;
      for (std::size_t k = 0; k < kept; ++k) reset(static_cast<std::size_t>(all_slots_[k]), why);
      kept = 0;
    }
  }
  n = kept;
}

// The station's ContactModel answering its newest pose: the contact `c`, or (null) a reset
// answer: zero force and stiffness, flagged rejected.
void StepLoop::write_model(std::size_t i, const ToolContact* c, std::uint64_t step, std::int64_t now) {
  auto& s = slots_[i];
  const PoseSample& p = s.pose.newest();
  neurosim_ContactModel& cm = *models_out_[i];
  const bool touching = c != nullptr && c->in_contact;
  cm.tool_sequence = p.sequence;
  cm.tool_source_time_ns = p.source_time_ns;
  for (int d = 0; d < 3; ++d) {
    cm.x0_position_m[d] = touching ? c->reference_tip_m[d] : p.position_m[d];
    cm.f0_n[d] = touching ? c->force_n[d] : 0.0;
    cm.normal[d] = touching ? c->normal[d] : 0.0;
  }
  for (int d = 0; d < 4; ++d) cm.x0_orientation[d] = p.orientation[d];
  for (int r = 0; r < 3; ++r)
    for (int q = 0; q < 3; ++q) cm.stiffness_n_per_m[3 * r + q] = touching ? c->stiffness_n_per_m(r, q) : 0.0;
  cm.in_contact = touching;
  cm.validity_radius_m = c != nullptr ? c->validity_radius_m : 0.0;
  cm.server_step = step;
  cm.server_time_ns = now;
  const char* mid = (touching && c->mesh >= 0 && c->mesh < sim_.num_meshes()) ? sim_.mesh_id(c->mesh).c_str() : "";
  std::strncpy(cm.contact_mesh_id, mid, neurosim_ID_MAX);
  cm.contact_mesh_id[neurosim_ID_MAX] = '\0';
  cm.tool_sample_rejected = c == nullptr || s.last_rejected.load(std::memory_order_relaxed);
  cm.relaxing_forces._length = 0;
  if (touching) {
    cm.relaxing_forces._length = static_cast<std::uint32_t>(c->num_relaxing);
    for (int j = 0; j < c->num_relaxing; ++j) {
      const interaction::RelaxingForce& src = c->relaxing[static_cast<std::size_t>(j)];
      neurosim_RelaxingForce& dst = cm.relaxing_forces._buffer[j];
      for (int d = 0; d < 3; ++d) dst.force_n[d] = src.force_n[d];
      dst.tau_s = src.tau_s;
    }
  }
  cm.rigid_planes._length = 0;
  if (sim_.rigid_obstacle() != nullptr && c != nullptr) {
    const interaction::ObstaclePlanes& rp = c->rigid_planes;
    cm.rigid_planes._length = static_cast<std::uint32_t>(rp.count);
    for (int j = 0; j < rp.count; ++j) {
      const auto& src = rp.planes[static_cast<std::size_t>(j)];
      neurosim_RigidPlane& dst = cm.rigid_planes._buffer[j];
      for (int d = 0; d < 3; ++d) {
        dst.point_m[d] = src.point_m[d];
        dst.normal[d] = src.normal[d];
      }
      dst.penetration_m = src.penetration_m;
    }
  }
  s.in_contact.store(touching, std::memory_order_relaxed);
  out_.write(cm);
  slot_step_[i].model_written = true;
}

void StepLoop::step_once() {
  const std::uint64_t step = counters_.steps.load(std::memory_order_relaxed) + 1;
  const std::int64_t now_mono = monotonic_ns();
  std::size_t n = 0;
  std::int64_t newest_ns = 0;
  for (std::size_t i = 0; i < slots_.size(); ++i) {
    auto& s = slots_[i];
    auto& ss = slot_step_[i];
    const int st = s.state.load(std::memory_order_acquire);
    if (st == kSlotLeaving) {
      retire(i);
      continue;
    }
    if (st != kSlotActive) continue;
    if (!ss.joined) {
      ss.joined = true;
      std::memcpy(models_out_[i]->station_id, s.station_id, sizeof(s.station_id));
    }
    if (s.pose.consume()) ss.has_pose = true;
    if (!ss.has_pose || ss.hold_until_ns > now_mono) continue;
    const PoseSample& p = s.pose.newest();
    if (!time_origin_set_) {
      time_origin_set_ = true;
      time_origin_ns_ = p.source_time_ns;
    }
    newest_ns = n == 0 ? p.source_time_ns : std::max(newest_ns, p.source_time_ns);
    ToolPose& tp = all_poses_[n];
    tp.tip_m = interaction::Vec3(p.position_m[0], p.position_m[1], p.position_m[2]);
    // Shaft axis: the tool frame's +z rotated into the scene frame by q (unit: the filter's).
    const std::array<double, 3> a = common::rotated_z(p.orientation);
    tp.axis = interaction::Vec3(a[0], a[1], a[2]);
    tp.tool = p.tool;
    // The slot is the station: with rigid obstacles the step holds the tool outside the bone by
    // the slot's proxy.
    tp.station = static_cast<int>(i);
    all_slots_[n++] = static_cast<int>(i);
  }
  if (n > 0) {
    step_time_s_ = 1e-9 * static_cast<double>(newest_ns - time_origin_ns_);
    auto& poses = poses_by_count_[n];
    for (std::size_t k = 0; k < n; ++k) {
      poses[k] = all_poses_[k];
      slot_of_pose_[k] = all_slots_[k];
    }
    const std::string* err = nullptr;
    if (!try_step(n, &err)) contain_failure(n, *err);
    const std::int64_t now = dds_time();
    const auto& contacts = contacts_by_count_[n];
    for (std::size_t k = 0; k < n; ++k) write_model(static_cast<std::size_t>(slot_of_pose_[k]), &contacts[k], step, now);
  }
  counters_.steps.store(step, std::memory_order_relaxed);
  if (after_step) after_step(step);
}

void StepLoop::dispose_all() {
  for (std::size_t i = 0; i < slots_.size(); ++i)
    if (slot_step_[i].model_written) {
      out_.dispose(*models_out_[i]);
      slot_step_[i].model_written = false;
    }
}

}  // namespace neurosim::service
