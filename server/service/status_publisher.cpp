#include "server/service/status_publisher.hpp"

#include "common/stats.hpp"
#include "server/service/deformation_publisher.hpp"

#include <algorithm>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace neurosim::service {

namespace {

constexpr std::int64_t kEarlyStatusGapNs = 200000000;  // a refusal is told within ~0.2 s

neurosim_Tier wire_tier(scene::Tier t) {
  switch (t) {
    case scene::Tier::kLinear: return neurosim_TIER_LINEAR;
    case scene::Tier::kCorotational: return neurosim_TIER_COROTATIONAL;
    case scene::Tier::kNonlinear: return neurosim_TIER_NONLINEAR;
  }
  throw std::invalid_argument("unknown elasticity tier");
}

}  // namespace

StatusPublisher::StatusPublisher(StatusPublisherDef def, const scene::Settings& settings,
                                 interaction::Simulation& sim, StationAdmission& stations,
                                 const StepLoop* loop, DeformationPublisher* deformation,
                                 std::optional<AccuracyTable> accuracy,
                                 wire::Writer<neurosim_SimStatus>* writer,
                                 std::function<void(const std::string&)> log)
    : def_(std::move(def)),
      settings_(settings),
      sim_(sim),
      stations_(stations),
      loop_(loop),
      deformation_(deformation),
      accuracy_(std::move(accuracy)),
      writer_(writer),
      log_(std::move(log)) {
  // Strings and buffers set once.
  auto& st = *status_;
  wire::set_string(st.server_id, def_.server_id, "server_id");
  wire::set_string(st.scene_name, settings_.name);
  wire::set_string(st.effects, def_.effects_text);
  st.step_rate_target_hz = def_.step_hz;
  st.viewer_rate_hz = def_.viewer_hz;
  st.status_rate_hz = def_.status_hz;
  st.max_stations = static_cast<std::uint32_t>(settings_.max_stations);
  const std::size_t slots = stations_.slots().size();
  station_status_.resize(slots);
  wire::reserve(st.stations, slots);
  wire::reserve(st.refused, StationAdmission::kMaxRefusals);
  refusals_.resize(StationAdmission::kMaxRefusals);
  step_us_.assign(def_.step_times_per_period, 0.0);
  step_us_sorted_.assign(def_.step_times_per_period, 0.0);
}

void StatusPublisher::begin(std::int64_t now) {
  start_mono_ns_ = now;
  last_status_mono_ns_ = now;
  step_us_count_ = 0;
}

void StatusPublisher::after_step(std::int64_t t0, std::int64_t t1) {
  if (step_us_count_ < step_us_.size()) step_us_[step_us_count_++] = 1e-3 * static_cast<double>(t1 - t0);
  if (t1 - last_status_mono_ns_ >= def_.status_period_ns) {
    publish(t1);
  } else if (stations_.status_soon() && t1 - last_status_mono_ns_ >= kEarlyStatusGapNs) {
    // A station was refused: tell its client now, not at the next status period.
    publish(t1);
  }
}

const neurosim_SimStatus& StatusPublisher::publish(std::int64_t now_mono) {
  const std::size_t n = step_us_count_;
  auto& st = *status_;
  if (n > 0) {
    std::copy(step_us_.begin(), step_us_.begin() + static_cast<std::ptrdiff_t>(n), step_us_sorted_.begin());
    auto b = step_us_sorted_.begin();
    auto e = b + static_cast<std::ptrdiff_t>(n);
    const auto at = [&](double q) { return common::percentile_in_place(b, e, q); };
    st.step_time_p50_us = at(0.5);
    st.step_time_p99_us = at(0.99);
    st.step_time_max_us = *std::max_element(b, e);
  }
  const std::uint64_t s_now = loop_ != nullptr ? loop_->counters().steps.load(std::memory_order_relaxed) : 0;
  const double dt = 1e-9 * static_cast<double>(now_mono - last_status_mono_ns_);
  st.step_rate_measured_hz = dt > 0 ? static_cast<double>(s_now - steps_at_last_status_) / dt : 0.0;
  steps_at_last_status_ = s_now;
  last_status_mono_ns_ = now_mono;
  step_us_count_ = 0;
  // Tier and its update rate from the simulation at every publish: the rate changes while it
  // runs (it is measured over the last second by the tier's own thread).
  st.tier = wire_tier(sim_.tier());
  st.tier_update_rate_hz = sim_.tier_update_rate_hz();
  report_accuracy(st);
  st.steps = s_now;
  st.deadline_misses = loop_ != nullptr ? loop_->counters().deadline_misses.load() : 0;
  st.server_time_ns = dds_time();
  st.uptime_s = 1e-9 * static_cast<double>(now_mono - start_mono_ns_);
  std::size_t k = 0;
  for (const auto& s : stations_.slots()) {
    if (s.state.load(std::memory_order_acquire) != kSlotActive) continue;
    auto& ss = station_status_[k++];
    std::memcpy(ss.station_id, s.station_id, sizeof(ss.station_id));
    ss.alive = true;
    ss.in_contact = s.in_contact.load(std::memory_order_relaxed);
    ss.samples_accepted = s.accepted.load(std::memory_order_relaxed);
    ss.samples_rejected_nonfinite = s.rejected_nonfinite.load(std::memory_order_relaxed);
    ss.samples_rejected_jump = s.rejected_jump.load(std::memory_order_relaxed);
    ss.last_sequence = s.last_sequence.load(std::memory_order_relaxed);
    ss.samples_rejected_workspace = s.rejected_workspace.load(std::memory_order_relaxed);
    ss.samples_rejected_time = s.rejected_time.load(std::memory_order_relaxed);
    ss.samples_rejected_sequence = s.rejected_sequence.load(std::memory_order_relaxed);
    ss.samples_rejected_identity = s.rejected_identity.load(std::memory_order_relaxed);
  }
  wire::assign(st.stations, station_status_.data(), k);
  const auto& c = stations_.counters;
  st.samples_rejected_nonfinite = c.rejected_nonfinite.load();
  st.samples_rejected_jump = c.rejected_jump.load();
  st.stations_refused = c.stations_refused.load();
  st.samples_rejected_workspace = c.rejected_workspace.load();
  st.samples_rejected_time = c.rejected_time.load();
  st.samples_rejected_sequence = c.rejected_sequence.load();
  st.samples_rejected_identity = stations_.rejected_identity();
  st.samples_rejected_rate = c.rejected_rate.load();
  st.stations_reclaimed = c.stations_reclaimed.load();
  st.unknown_ids_dropped = c.unknown_ids_dropped.load();
  st.log_lines_suppressed = stations_.log_lines_suppressed();
  stations_.clear_status_soon();
  const std::size_t nr = stations_.copy_refusals(refusals_.data(), refusals_.size());
  wire::assign(st.refused, refusals_.data(), nr);
  if (writer_ != nullptr) writer_->write(st);
  return st;
}

// At each status: the strain the field thread measured in the fields it solved for the viewers
// since the last one (no viewer: no field is solved, nothing is measured: -1), the tier's
// expected error there, failed equilibrium updates; warnings logged once.
void StatusPublisher::report_accuracy(neurosim_SimStatus& st) {
  const double strain = deformation_ != nullptr ? deformation_->take_max_strain() : -1.0;
  st.max_strain = strain;
  st.expected_force_error = -1.0;
  if (accuracy_ && strain >= 0.0) {
    const ExpectedError e = accuracy_->expected(sim_.tier(), strain, settings_.name,
                                                def_.host_element, def_.host_poisson_ratio);
    if (e.known) {
      st.expected_force_error = e.force_rel_error;
      if (e.beyond_table && !beyond_table_noted_) {
        beyond_table_noted_ = true;
        std::ostringstream msg;
        msg << "note: strain " << 100.0 * strain << " % is beyond the accuracy table's measured "
            << "strains for tier " << scene::tier_name(sim_.tier()) << " (" << e.basis
            << "): the expected force error reported is the largest measured, "
            << 100.0 * e.force_rel_error << " %, and may be exceeded";
        if (log_) log_(msg.str());
      }
      const double bound = settings_.effects.max_expected_force_error;
      if (bound > 0.0 && e.force_rel_error > bound && !error_bound_warned_) {
        error_bound_warned_ = true;
        std::ostringstream msg;
        msg << "warning: tier " << scene::tier_name(sim_.tier()) << " at strain " << 100.0 * strain
            << " %: expected tool-force error ~" << 100.0 * e.force_rel_error
            << " % exceeds the scene's bound effects.max_expected_force_error = " << 100.0 * bound
            << " % (measured table, " << e.basis << "); a higher tier would be closer "
            << "(docs/accuracy.md)";
        if (log_) log_(msg.str());
      }
    }
  }
  // Against the converged answer: the host's discretization error (set-up) + the tier's.
  st.discretization_error_estimate = def_.discretization_error;
  st.total_error_estimate = def_.discretization_error >= 0.0 && st.expected_force_error >= 0.0
                                ? def_.discretization_error + st.expected_force_error
                                : -1.0;
  st.columns_not_ready = sim_.columns_not_ready();
  st.columns_solved_ahead = sim_.columns_solved_ahead();
  // A column cache bound below one pose's reach: the worker raised it (column_worker.hpp).
  raised_logged_.resize(static_cast<std::size_t>(std::max(0, sim_.num_meshes())), 0);
  for (int m = 0; m < sim_.num_meshes(); ++m) {
    const int body = sim_.body_index(m);
    bool first = body >= 0;  // a body's meshes share its cache: logged under its first mesh
    for (int e = 0; first && e < m; ++e) first = sim_.body_index(e) != body;
    if (!first) continue;
    const auto c = sim_.column_cache(m);
    std::size_t& logged = raised_logged_[static_cast<std::size_t>(m)];
    if (c.raised_capacity_slots <= logged) continue;
    logged = c.raised_capacity_slots;
    if (log_)
      log_("warning: the column cache of '" + sim_.mesh_id(m) + "' is bounded at " +
           std::to_string(c.capacity_slots) + " nodes (column_cache_budget_mb), below the " +
           std::to_string(c.raised_capacity_slots) +
           " nodes within the column worker's reach of the tools: raised to them (" +
           std::to_string(static_cast<double>(c.raised_capacity_slots * c.bytes_per_slot) / 1e6) +
           " MB)");
  }
  // Steps that did not solve the whole contact: said once per status period in which they rose.
  st.steps_with_rows_dropped = sim_.steps_with_rows_dropped();
  st.steps_not_converged = sim_.steps_not_converged();
  if (st.steps_with_rows_dropped > rows_dropped_logged_) {
    if (log_)
      log_("warning: " + std::to_string(st.steps_with_rows_dropped - rows_dropped_logged_) +
           " step(s) since the last status left touching contact rows out: a tool's patch has more "
           "rows than the per-tool limit (the deepest are kept; cells much finer than the tip; "
           "raise --contact-max-rows)");
    rows_dropped_logged_ = st.steps_with_rows_dropped;
  }
  if (st.steps_not_converged > not_converged_logged_) {
    if (log_)
      log_("warning: " + std::to_string(st.steps_not_converged - not_converged_logged_) +
           " step(s) since the last status did not converge the contact LCP (each kept the last "
           "good answer; raise --lcp-max-iterations for patches of many rows)");
    not_converged_logged_ = st.steps_not_converged;
  }
  const std::uint64_t failures = sim_.tier_update_failures();
  st.tier_update_failures = failures;
  if (failures > tier_failures_logged_) {
    if (log_)
      log_("warning: " + std::to_string(failures - tier_failures_logged_) + " equilibrium update(s) of tier " +
           scene::tier_name(sim_.tier()) +
           " failed since the last status (the previous equilibrium stays); last: " + sim_.tier_last_error());
    tier_failures_logged_ = failures;
  }
}

void StatusPublisher::dispose() {
  if (writer_ != nullptr) writer_->dispose(*status_);
}

}  // namespace neurosim::service
