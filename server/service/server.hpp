// neurosim-server core: a Simulation (Model built once) stepped at the
// scene rate on its own thread with absolute deadlines, stations on DDS. Server composes:
//
//   DDS thread  : StationAdmission (station_admission.hpp): bind each station id to the writer
//                 that claims it, join/leave/reclaim stations, filter samples, hand the newest
//                 good pose to the station's slot (triple buffer, never blocks); after each pose
//                 it wakes the step thread (event step mode).
//   step thread : StepLoop (step_loop.hpp): when a pose arrives (at most 2× the scene rate) or
//                 one period after the last step: newest pose of each station →
//                 Simulation::step → ContactModel per station; a step that throws for one
//                 station's pose resets that station, the others are served. After each step
//                 the DeformationPublisher's tick at the viewer rate and the StatusPublisher
//                 (status_publisher.hpp) at the status rate.
//   field thread: DeformationPublisher (deformation_publisher.hpp): full-field solves and
//                 Deformation frames, only while a viewer is matched.
//
// Topics and QoS come from neurosim::wire (idl/wire/qos.cpp).
#pragma once

#include "common/thread_sched.hpp"
#include "server/interaction/simulation.hpp"
#include "server/service/contact_switches.hpp"
#include "server/service/tool_filter.hpp"
#include "server/model/model.hpp"
#include "server/service/step_loop.hpp"

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

namespace neurosim::service {

// step "ns-step" SCHED_FIFO 50, dds "ns-dds" SCHED_FIFO 45 (the ToolState receive path, below
// the step thread), field "ns-field" normal (full-field solves must never delay a step).
common::ThreadPlan default_server_threads();

struct ServerOptions {
  std::string scene_path;          // for messages and MeshTopology
  std::string server_id{"neurosim-server"};  // SimStatus key
  int domain{-1};                  // DDS domain id; -1: the configuration's default
  std::string topic_prefix{};      // prepended to every topic name (test isolation); "" normally
  std::uint32_t full_frame_period{30};  // Deformation FULL frame every this many frames
  // Where the model's effects.tier came from, for the start-up log line only: "scene" or
  // "--tier" (run_main's override). The tier itself is the simulation's (Simulation::tier()).
  std::string tier_source{"scene"};
  // The tiers' measured force error against strain (AccuracyTable, written by accuracy_bench);
  // empty: none (SimStatus.expected_force_error -1). A file that is given but unreadable or
  // malformed is an error.
  // --cache-dir: the disk cache of the hosts' factors and boundary operators
  // (SimulationOptions::compliance_cache_dir; a second start of the same scene reads them
  // instead of factoring); empty: none.
  std::string cache_dir{};
  // --barycentric-contact, --contact-spread, --contact-smooth-normals, --contact-near-field:
  // the live physics' contact options (the factory applies them to its SimulationOptions);
  // unset: the library's defaults.
  ContactSwitches contact{};
  std::string accuracy_table{};
  // The host meshes' measured discretization error against the converged answer
  // (DiscretizationTable, written by accuracy_bench); empty: none (SimStatus
  // discretization_error_estimate and total_error_estimate -1, unknown). A file that is given
  // but unreadable or malformed is an error.
  std::string discretization_table{};
  // Station identity and hostile input (docs/ARCHITECTURE.md "Station identity"):
  double station_idle_timeout_s{2.0};      // a station with no sample this long frees its slot, unit s
  int max_stations_per_participant{2};     // stations one DDS participant may hold at once (>= 1)
  double workspace_margin_m{kDefaultWorkspaceMarginM};  // tool tips beyond the scene's bounding box + this are rejected, unit m
  double max_future_s{1.0};                // source times further ahead of the server's clock are rejected, unit s
  double max_station_rate_hz{2000.0};      // samples per second a station may send on average (burst 200)
  int log_lines_per_second{5};             // per cause; the rest is summarised ("suppressed K lines")
  // Real-time margins (docs/ARCHITECTURE.md "Threads"):
  //   kEvent: the step thread wakes when the DDS thread hands a pose to a slot (a semaphore), at
  //           most max_step_rate_factor × rates.step_hz (a minimum gap between steps), and at the
  //           step period after the last step when no sample arrives (absolute deadlines).
  //   kClock: the free-running clock: one step every period on absolute deadlines.
  StepMode step_mode{StepMode::kEvent};
  double max_step_rate_factor{2.0};  // event mode: steps at most this × the scene rate (>= 1)
  // Server threads by role "step", "dds", "field" (names, SCHED_FIFO priorities, CPUs);
  // default_server_threads() below; --rt-priority / --rt-cpus change it.
  common::ThreadPlan threads = default_server_threads();
};

// Counters the server exposes to tests (also published in SimStatus).
struct ServerCounters {
  std::uint64_t steps{0};
  std::uint64_t deadline_misses{0};
  std::uint64_t rejected_nonfinite{0};
  std::uint64_t rejected_jump{0};
  std::uint64_t stations_refused{0};
  std::uint64_t rejected_workspace{0};
  std::uint64_t rejected_time{0};
  std::uint64_t rejected_sequence{0};
  std::uint64_t rejected_identity{0};
  std::uint64_t rejected_rate{0};
  std::uint64_t stations_reclaimed{0};
  std::uint64_t deformation_frames{0};  // all meshes
  std::uint64_t full_field_solves{0};   // displacement fields computed (per mesh)
  std::uint64_t deformation_skipped{0}; // viewer ticks skipped: the field worker was still busy
  // Which wake-up started each step: a sample handed to a slot (event mode only) or the period
  // deadline (clock mode: every step; event mode: no sample within one period).
  std::uint64_t steps_on_sample{0};
  std::uint64_t steps_on_deadline{0};
  std::uint64_t step_failures{0};    // stations reset because their pose made the step throw
  std::uint64_t writers_evicted{0};  // ToolState writers evicted from the writer table
};

class Server {
 public:
  // The simulation must have been built from `model` (mesh ids in the same order). Logs what it
  // builds to `log` (one line each). With effects.deformation_output the displacement fields are
  // solved on a field thread from a snapshot of each step's forces (Simulation::snapshot).
  // Throws std::runtime_error on a bad scene / DDS failure.
  Server(const scene::Model& model, std::unique_ptr<interaction::Simulation> sim,
         ServerOptions options, std::ostream& log);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Creates the DDS entities, publishes MeshTopology, starts the DDS and step threads.
  void start();
  // Stops the threads, disposes every instance written (clients see the server leave). Idempotent.
  void stop();
  // True while running; false after stop() or when a thread died of an error (see error()).
  bool running() const;
  std::string error() const;
  ServerCounters counters() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Builds the simulation of a compiled scene; `options` are the server's (cache_dir).
using SimulationFactory = std::function<std::unique_ptr<interaction::Simulation>(
    const scene::Model& model, const ServerOptions& options)>;

// The neurosim-server command line:
//   neurosim-server --scene FILE [--tier linear|corotational|nonlinear] [--duration SECONDS]
//                   [--domain ID] [--server-id NAME] [--topic-prefix P]
//                   [--station-idle-timeout S] [--max-stations-per-participant N]
//                   [--workspace-margin M] [--log-lines-per-second N]
//                   [--step-mode event|clock] [--max-step-rate-factor F]
//                   [--rt-priority step=50,dds=45,field=0] [--rt-cpus step=1,dds=0]
//                   [--cache-dir DIR]
// Sets OPENBLAS_NUM_THREADS=1 (unless set), installs SIGINT/SIGTERM handlers, compiles the
// scene, replaces its effects.tier by --tier if given, builds the simulation with `factory`,
// serves until a signal or the duration. SIGINT/SIGTERM are honoured in every phase: during the
// scene load and the simulation build the process exits within ~0.1 s with a message naming the
// phase (status 0, as for a signal while serving). Returns the exit status (2: usage error, e.g. an
// unknown --tier; 1: the scene, the simulation build or DDS failed).
int run_main(int argc, char** argv, const SimulationFactory& factory);

}  // namespace neurosim::service
