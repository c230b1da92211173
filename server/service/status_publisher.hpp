// SimStatus (docs/ARCHITECTURE.md "Processes and DDS topics"): at the status rate, once at
// start, and within ~0.2 s of a new refusal, the step thread fills one sample from what the
// parts count (the step loop's steps and misses, the stations' rows and refusals, the rejection
// totals, the deformation publisher's strain) with the step-time percentiles of the period, the
// tier and its expected force error (AccuracyTable), and writes it. Warnings about accuracy and
// failed tier updates are logged once.
#pragma once

#include "idl/wire/dds.hpp"
#include "server/interaction/simulation.hpp"
#include "server/model/settings.hpp"
#include "server/service/accuracy_table.hpp"
#include "server/service/station_admission.hpp"
#include "server/service/step_loop.hpp"

#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace neurosim::service {

class DeformationPublisher;

struct StatusPublisherDef {
  std::string server_id{"neurosim-server"};
  std::string effects_text;            // "contact,coupling,deformation"
  double step_hz{1000}, viewer_hz{0}, status_hz{1};  // viewer_hz 0: no Deformation, unit Hz
  std::int64_t status_period_ns{1000000000};
  std::size_t step_times_per_period{2000};  // capacity of the step-time buffer (no allocation per step)
  // The host's discretization error against the converged answer (DiscretizationTable), a
  // fraction, -1: unknown; and the host's element and nu (the tier table's rows are theirs).
  double discretization_error{-1.0};
  std::string host_element;        // fem::element_name; "": any row (tests of the tier table)
  double host_poisson_ratio{std::numeric_limits<double>::quiet_NaN()};
};

class StatusPublisher {
 public:
  // `writer` may be null (tests: fill() only); `deformation` null without Deformation output.
  StatusPublisher(StatusPublisherDef def, const scene::Settings& settings, interaction::Simulation& sim,
                  StationAdmission& stations, const StepLoop* loop,
                  DeformationPublisher* deformation, std::optional<AccuracyTable> accuracy,
                  wire::Writer<neurosim_SimStatus>* writer, std::function<void(const std::string&)> log);

  // The period starts (step thread start, or start()).
  void begin(std::int64_t now_mono_ns);
  // Step thread, after each step: its time; publishes when the period is over, or early (>=
  // 0.2 s after the last) when a station was refused since.
  void after_step(std::int64_t t0_ns, std::int64_t t1_ns);
  // Fills the sample for now (the step-time buffer is emptied) and writes it (if a writer).
  const neurosim_SimStatus& publish(std::int64_t now_mono_ns);
  // The strain source (Deformation output); set after construction when built later.
  void set_deformation(DeformationPublisher* d) { deformation_ = d; }
  void set_loop(const StepLoop* l) { loop_ = l; }
  void dispose();

 private:
  void report_accuracy(neurosim_SimStatus& st);

  StatusPublisherDef def_;
  const scene::Settings& settings_;
  interaction::Simulation& sim_;
  StationAdmission& stations_;
  const StepLoop* loop_;
  DeformationPublisher* deformation_;
  std::optional<AccuracyTable> accuracy_;
  wire::Writer<neurosim_SimStatus>* writer_;
  std::function<void(const std::string&)> log_;

  wire::Sample<neurosim_SimStatus> status_;
  std::vector<neurosim_StationStatus> station_status_;
  std::vector<neurosim_StationRefusal> refusals_;
  std::vector<double> step_us_, step_us_sorted_;  // this status period
  std::size_t step_us_count_{0};
  std::int64_t start_mono_ns_{0}, last_status_mono_ns_{0};
  std::uint64_t steps_at_last_status_{0};
  bool error_bound_warned_{false}, beyond_table_noted_{false};
  std::uint64_t tier_failures_logged_{0};
  std::uint64_t rows_dropped_logged_{0};   // Simulation::steps_with_rows_dropped logged so far
  std::uint64_t not_converged_logged_{0};  // Simulation::steps_not_converged logged so far
  // Per mesh: the column cache's raised bound last logged (ColumnCacheStats::raised_capacity_slots).
  std::vector<std::size_t> raised_logged_;
};

}  // namespace neurosim::service
