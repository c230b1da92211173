// scale_bench: the brain/artery scene at several brain cell sizes. Per size (the scene built by
// `neurosim-model --cell-size C --out-dir DIR/cC` when DIR/cC/brain_artery.scene is missing):
// - setup_cold_s: Simulation::build with an empty compliance cache folder (factorization,
//   carving, tie, boundary operator; the factor and the operator written to the cache);
//   setup_cached_s: the same build again, the host's factor (fem/factor_cache) and the boundary
//   operator read from that disk cache (files just written: from the page cache, as on a
//   second start soon after the first; the set-up's parts are printed on stderr without --csv);
// - rss_mb: the peak resident memory of a cached start: from the cached build through the slide
//   and the fields (VmHWM reset after the cold build was freed, /proc/self/clear_refs; the whole
//   process's peak where that is refused); on stderr without --csv also the cold start's peak and
//   the resident memory after each stage, the host factor's size and the column cache's nodes,
//   bytes per node, bound and evictions;
// - step_p50/p99/max_us: the contact step (one probe, LINEAR tier, the step's own thread) along a
//   10 s slide at 20 mm/s over fresh brain surface, 1000 steps per second of the slide paced by
//   the clock (as the server steps): the tip 2 mm deep under the right lateral surface, sweeping
//   anteroposteriorly, moving 6 mm up at each end so the way back is fresh surface as well; the
//   step's rows are triangle rows (contact_step.cpp). With --column-solves worker (the default,
//   the live server's SimulationOptions::column_worker) the compliance columns are solved ahead
//   of the tool on the worker thread, which starts at the slide's first pose (as when a station
//   joins; the slide starts after --first-reach-max-s even if the worker has not finished that
//   pose, said on stderr); with --column-solves step (the old way) a first touch is solved inside the step;
// - columns_not_ready: worker: contact nodes whose row took the fallback because their columns
//   were not ready yet, summed over the slide's steps (StepStats::columns_not_ready); step: the
//   first touches solved inside the step (StepStats::columns_computed, summed);
// - field_hz: 1 / mean time of the fields of every mesh as the server's field thread makes them
//   (a FieldSnapshot: with SimulationOptions::field_column_budget_mb a sum of the loaded nodes'
//   full columns, field_columns.hpp) for the forces of the slide's last viewer frame that
//   loaded a node (held), after the first such field (which solves the columns of nodes not kept yet); on stderr also that first
//   field, the plain sparse solve, and the slide's first --field-frames viewer frames (30 Hz)
//   replayed in order (each newly loaded node's columns solved once: a moving tool's rate);
// - nonlinear_update_hz: the NONLINEAR tier's equilibrium updates per second of its worker while
//   the probe presses at the slide's first pose, paced at 1 kHz: the mean rate over every update
//   of the press after the first (their count / their summed time,
//   Simulation::tier_update_totals; the first waits for the rest tangent's factor, its time on
//   stderr), the press lasting --nonlinear-seconds after the first update finished (at most
//   --nonlinear-max-s in all; nan if no update followed the first by then; a held press stops
//   updating at its fixed point, ~20 updates at 7 mm). Not Simulation::tier_update_rate_hz (the
//   last second's one or two updates: too few for a 5 Hz verdict). The same scene with
//   effects.tier = NONLINEAR, built (from the disk cache) after the LINEAR simulation was freed;
//   its set-up time and memory on stderr. --nonlinear-seconds 0 skips it (nan).
// - with --nonlinear-inline N (stderr only): the same NONLINEAR press with the updates inline
//   (SimulationOptions::tier_worker_thread = false, no column worker: deterministic), one update
//   per step for N steps: the first's time (it waits for the rest tangent's factor), the
//   second's, the mean, median and max of the others (StepStats::tier_update_us), and the
//   contact force after them (to 17 digits: old and new code compared); then every update's time.
#include "patient_models.hpp"
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/stats.hpp"
#include "server/interaction/field_columns.hpp"
#include "server/interaction/simulation.hpp"
#include "server/fem/static_solver.hpp"
#include "server/scene/compile.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <Eigen/Core>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <string>
#include <thread>
#include <vector>

namespace fs = std::filesystem;
namespace ni = neurosim::interaction;
using Clock = neurosim::common::Clock;
using Vec3 = Eigen::Vector3d;

namespace {

using neurosim::bench::status_mb;

double rss_mb() { return status_mb("VmRSS"); }
double peak_rss_mb() { return status_mb("VmHWM"); }
// The peak so far forgotten (Linux: clear_refs 5 resets VmHWM to the current RSS); false if not.
bool reset_peak_rss() {
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
  out.flush();
  return static_cast<bool>(out);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> cells;
  std::string dir = "/tmp/neurosim_scale_bench";
  double seconds = 10.0, speed = 0.020, depth = 0.002;
  bool csv = false;
  int field_frames = 60;
  double nonlinear_seconds = 3.0, nonlinear_max_s = 900.0;
  double first_reach_max_s = 120.0;
  int nonlinear_inline = 0;
  std::string column_solves = "worker";
  neurosim::cli::Parser p("scale_bench", "The brain/artery scene at several cell sizes.");
  p.add_option("--cell-size", cells, "brain cell size, unit mm (repeat; coarse to fine)");
  p.add_option("--models", dir, "folder of the built scenes")->capture_default_str();
  p.add_option("--seconds", seconds, "slide duration, unit s")->capture_default_str();
  p.add_option("--speed", speed, "slide speed, unit m/s")->capture_default_str();
  p.add_option("--field-frames", field_frames,
               "viewer frames of the slide (30 Hz from its start) whose fields are replayed")
      ->capture_default_str();
  p.add_option("--nonlinear-seconds", nonlinear_seconds,
               "NONLINEAR press this long after its first update, unit s (0: not measured); "
               "nonlinear_update_hz = the mean rate over the press's updates after the first "
               "(their count / their summed time)")
      ->capture_default_str();
  p.add_option(
       "--nonlinear-max-s", nonlinear_max_s,
       "NONLINEAR press at most this long in all (waiting for a first update included), unit s")
      ->capture_default_str();
  p.add_option("--first-reach-max-s", first_reach_max_s,
               "wait at most this long for the worker to solve the first pose's reach before the "
               "timed slide starts anyway (the rows without columns take the fallback and count in "
               "columns_not_ready), unit s")
      ->check(neurosim::cli::non_negative_number())
      ->capture_default_str();
  p.add_option("--nonlinear-inline", nonlinear_inline,
               "NONLINEAR updates inline (SimulationOptions::tier_worker_thread = false, no column "
               "worker: deterministic), one per step at the slide's first pose: their times on "
               "stderr (0: not run)")
      ->check(neurosim::cli::non_negative_number())
      ->capture_default_str();
  p.add_flag("--csv", csv, "CSV only (the default adds comments on stderr)");
  p.add_option("--column-solves", column_solves,
               "worker: compliance columns solved ahead of the tool (the live server); step: "
               "first touches solved inside the step (the old way)")
      ->check(neurosim::cli::one_of({"worker", "step"}))
      ->capture_default_str();
  if (auto rc = p.parse(argc, argv)) return *rc;
  if (cells.empty()) cells = {7.0};
  std::cout << "cell_mm,host_vertices,host_tets,setup_cold_s,setup_cached_s,rss_mb,step_p50_us,"
               "step_p99_us,step_max_us,columns_not_ready,field_hz,nonlinear_update_hz\n";
  try {
    for (double cell : cells) {
      const fs::path scene = neurosim::bench::scene_at(cell, dir, "scale_bench");
      const neurosim::scene::Model model = neurosim::scene::load_model(scene);
      ni::SimulationOptions options;
      options.column_worker = column_solves == "worker";
      const fs::path cache = fs::path(dir) / ("cache_" + std::to_string(::getpid()));
      fs::remove_all(cache);
      options.compliance_cache_dir = cache.string();
      auto t0 = Clock::now();
      auto cold = ni::Simulation::build(model, options);
      const double cold_s = neurosim::common::seconds_since(t0);
      const ni::SetupStats cold_setup = cold->setup_stats();
      const double cold_peak_mb = peak_rss_mb();
      cold.reset();
      const double after_cold_mb = rss_mb();
      // From here the peak of a cached start: the process as a server started with the cache.
      const bool peak_reset = reset_peak_rss();
      t0 = Clock::now();
      auto sim = ni::Simulation::build(model, options);
      const double after_cached_mb = rss_mb();
      const double cached_s = neurosim::common::seconds_since(t0);
      const ni::SetupStats cached_setup = sim->setup_stats();
      const int host = 0;
      const auto& mesh = sim->mesh(host);
      const std::size_t num_vertices = mesh.num_vertices(), num_tets = mesh.num_tets();
      // Lateral surface profile: per 1 mm of y, the largest x of the surface nodes within
      // +-3 mm of the slide's height z.
      Vec3 lo, hi;
      mesh.bounds(lo, hi);
      const double z0 = lo.z() + 0.55 * (hi.z() - lo.z());
      const double y_min = lo.y() + 0.25 * (hi.y() - lo.y()), y_max = lo.y() + 0.75 * (hi.y() - lo.y());
      auto lateral_x = [&](double y, double z) {
        double best = -std::numeric_limits<double>::infinity();
        for (int v : mesh.surface_vertices()) {
          const Vec3& x = mesh.vertices()[v];
          if (std::abs(x.y() - y) <= 0.003 && std::abs(x.z() - z) <= 0.003) best = std::max(best, x.x());
        }
        return best;
      };
      std::map<long, double> profile;  // key: (pass, y in mm)
      const int steps = static_cast<int>(std::lround(seconds * 1000.0));
      const double length = y_max - y_min;
      std::vector<ni::ToolPose> one(1);
      std::vector<ni::ToolContact> contacts;
      ni::StepStats stats;
      std::vector<double> times;
      times.reserve(steps);
      long not_ready = 0;
      int steps_not_ready = 0;
      double first_reach_mb = -1.0;
      // The worker's first pose: done within --first-reach-max-s, how long, nodes ready then.
      bool first_reach_done = false;
      double first_reach_s = 0.0;
      std::size_t first_reach_nodes = 0;
      std::vector<ni::FieldSnapshot> frames;
      ni::FieldSnapshot held, probe;
      ni::ToolPose first;
      bool has_first = false;
      auto next = Clock::now();
      bool started = false;
      for (int k = 0; k < steps; ++k) {
        const double s = speed * k * 1e-3;  // path length so far, m
        const int pass = static_cast<int>(s / length);
        const double f = s / length - pass;
        const double y = (pass % 2 == 0) ? y_min + f * length : y_max - f * length;
        const double z = z0 + 0.006 * pass;
        const long key = pass * 100000L + std::lround(y * 1e3);
        auto it = profile.find(key);
        if (it == profile.end()) it = profile.emplace(key, lateral_x(std::round(y * 1e3) * 1e-3, z)).first;
        if (!std::isfinite(it->second)) continue;
        one[0].tip_m = Vec3(it->second + 0.002 - depth, y, z);  // tip radius 2 mm, centre inside
        one[0].axis = Vec3::UnitX();
        if (!has_first) {
          first = one[0];
          has_first = true;
        }
        if (!started && options.column_worker) {
          // The worker starts at the first pose (a station joining), before the timed slide.
          sim->step(one, contacts, stats);
          const auto tw = Clock::now();
          first_reach_done = sim->wait_columns_ready(first_reach_max_s);
          first_reach_s = neurosim::common::seconds_since(tw);
          first_reach_nodes = sim->column_cache(host).ready_slots;
          first_reach_mb = rss_mb();
          next = Clock::now();
        }
        started = true;
        next += std::chrono::microseconds(1000);
        std::this_thread::sleep_until(next);
        const auto ts = Clock::now();
        sim->step(one, contacts, stats);
        times.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
        // The viewer's frames along the slide (30 Hz), for the field replay below.
        if (times.size() % 33 == 1) {
          if (frames.size() < static_cast<std::size_t>(field_frames)) {
            frames.emplace_back();
            sim->snapshot(frames.back());
          }
          // The held forces measured below: the last frame with a loaded node.
          sim->snapshot(probe);
          if (!probe.bodies[host].slots.empty()) std::swap(held, probe);
        }
        const int missed = options.column_worker ? stats.columns_not_ready : stats.columns_computed;
        not_ready += missed;
        steps_not_ready += missed > 0;
      }
      const double after_slide_mb = rss_mb();
      const auto columns = sim->column_cache(host);
      // Fields as the server's field thread makes them (a FieldSnapshot per frame, every mesh):
      // (1) the slide's frames replayed in order, the full columns kept from frame to frame
      // (each newly loaded node solved once); (2) held forces: the slide's last snapshot, its
      // first field (the columns of nodes not kept yet) then field_repeats more (sums);
      // (3) the plain solve (Simulation::displacements without a snapshot: a sparse solve).
      Eigen::VectorXd u;
      auto fields_of = [&](ni::FieldSnapshot& snap) {
        for (int m = 0; m < sim->num_meshes(); ++m) sim->displacements(snap, m, u);
      };
      std::shared_ptr<ni::FieldColumns> kept;
      std::shared_ptr<neurosim::fem::SolveWorkspace> ws;
      auto tr = Clock::now();
      for (auto& f : frames) {
        if (kept) f.bodies[host].field_columns = kept;
        if (ws) f.bodies[host].workspace = ws;
        fields_of(f);
        kept = f.bodies[host].field_columns;
        ws = f.bodies[host].workspace;
      }
      const double replay_s = neurosim::common::seconds_since(tr);
      if (held.bodies.empty()) sim->snapshot(held);  // never loaded: the last step's (zero) forces
      auto tf = Clock::now();
      fields_of(held);
      const double held_first_s = neurosim::common::seconds_since(tf);
      const int field_repeats = 20;
      tf = Clock::now();
      for (int k = 0; k < field_repeats; ++k) {
        held.bodies[host].host_done = false;  // the same forces again: a field per frame
        fields_of(held);
      }
      const double field_s = neurosim::common::seconds_since(tf) / field_repeats;
      tf = Clock::now();
      sim->displacements(host, u);
      const double solve_s = neurosim::common::seconds_since(tf);
      const std::size_t held_nodes = held.bodies[host].slots.size();
      const double rss_peak_mb = peak_rss_mb();
      const double after_fields_mb = rss_mb();
      const std::uint64_t solved_ahead = sim->columns_solved_ahead();
      const ni::ToolPose first_pose = first;
      // The NONLINEAR tier on the same mesh: its worker's update rate under a held press.
      double nonlinear_hz = std::numeric_limits<double>::quiet_NaN();
      double nonlinear_setup_s = 0.0, nonlinear_press_s = 0.0, nonlinear_mb = 0.0;
      double nonlinear_first_s = 0.0;  // the press's first update (first ones, if several)
      long nonlinear_updates = 0;      // the press's updates after it
      sim.reset();
      std::string nonlinear_error;
      if (nonlinear_seconds > 0.0 && has_first) try {
        neurosim::scene::Model nl_model = model;
        nl_model.effects.tier = neurosim::fem::Tier::kNonlinear;
        fs::create_directories(cache);
        const auto tn = Clock::now();
        auto nl = ni::Simulation::build(nl_model, options);
        nonlinear_setup_s = neurosim::common::seconds_since(tn);
        nl->step({first_pose}, contacts, stats);
        if (options.column_worker) nl->wait_columns_ready(first_reach_max_s);
        const auto tp = Clock::now();
        auto due = Clock::now();
        // The rate over the press's updates after the first (which waits for the rest
        // tangent's factor): their count over their summed time.
        ni::Simulation::TierUpdateTotals at_first{}, at_end{};
        double first_done_s = -1.0;
        for (;;) {
          due += std::chrono::microseconds(1000);
          std::this_thread::sleep_until(due);
          nl->step({first_pose}, contacts, stats);
          const double t = neurosim::common::seconds_since(tp);
          const auto totals = nl->tier_update_totals();
          if (first_done_s < 0.0 && totals.updates > 0) {
            first_done_s = t;
            at_first = totals;
          }
          if ((first_done_s >= 0.0 && t - first_done_s >= nonlinear_seconds) ||
              t >= nonlinear_max_s) {
            at_end = totals;
            nonlinear_press_s = t;
            break;
          }
        }
        nonlinear_first_s = at_first.busy_s;
        nonlinear_updates = static_cast<long>(at_end.updates - at_first.updates);
        if (nonlinear_updates > 0)
          nonlinear_hz = static_cast<double>(nonlinear_updates) / (at_end.busy_s - at_first.busy_s);
        nonlinear_mb = rss_mb();
      } catch (const std::exception& e) {
        nonlinear_error = e.what();  // refused (memory): the row says nan, stderr says why
      }
      // The same press with the updates inline: each step one update (at most tier_update_steps
      // Newton steps), its time StepStats::tier_update_us; the first factorizes the rest tangent.
      std::vector<double> inline_ms;
      double inline_force_n = std::numeric_limits<double>::quiet_NaN();
      std::string inline_error;
      if (nonlinear_inline > 0 && has_first) try {
        neurosim::scene::Model nl_model = model;
        nl_model.effects.tier = neurosim::fem::Tier::kNonlinear;
        ni::SimulationOptions o = options;
        o.tier_worker_thread = false;
        o.column_worker = false;
        fs::create_directories(cache);
        auto nl = ni::Simulation::build(nl_model, o);
        for (int k = 0; k < nonlinear_inline; ++k) {
          nl->step({first_pose}, contacts, stats);
          if (stats.tier_updated) inline_ms.push_back(1e-3 * stats.tier_update_us);
        }
        if (!contacts.empty()) inline_force_n = contacts[0].force_n.norm();
      } catch (const std::exception& e) {
        inline_error = e.what();
      }
      fs::remove_all(cache);
      const auto pc = neurosim::common::percentiles(times);
      std::printf("%g,%zu,%zu,%.2f,%.2f,%.0f,%.1f,%.1f,%.1f,%ld,%.1f,%.2f\n", cell, num_vertices,
                  num_tets, cold_s, cached_s, rss_peak_mb, pc.p50, pc.p99, pc.max,
                  not_ready, 1.0 / field_s, nonlinear_hz);
      std::fflush(stdout);
      if (!csv) {
        for (const auto* st : {&cold_setup, &cached_setup})
          std::cerr << "scale_bench: cell " << cell << " mm, set-up " << (st == &cold_setup ? "cold" : "cached")
                    << ": meshes " << st->load_meshes_s << " s, factor " << st->factor_s << " s, fusion "
                    << st->fusion_s << " s, condense " << st->condense_s << " s, boundary " << st->boundary_s
                    << " s, operator " << st->operator_s << " s, columns " << st->columns_s << " s, total "
                    << st->total_s << " s, cache hits " << st->cache_hits << " (factor " << st->factor_cache_hits
                    << "), host factor " << st->factor_bytes / 1e6 << " MB\n";
      }
      if (!csv) {
        std::cerr << "scale_bench: cell " << cell << " mm, fields (every mesh): held forces on "
                  << held_nodes << " nodes " << 1e3 * field_s << " ms each (the first "
                  << 1e3 * held_first_s << " ms), the plain solve of the host " << 1e3 * solve_s
                  << " ms; the slide's first " << frames.size() << " viewer frames (30 Hz) replayed: "
                  << (frames.empty() ? 0.0 : 1e3 * replay_s / static_cast<double>(frames.size()))
                  << " ms per frame, " << (kept ? kept->columns_solved() : 0)
                  << " nodes' full columns solved, " << (kept ? kept->evicted() : 0) << " evicted\n";
        std::cerr << "scale_bench: cell " << cell << " mm, NONLINEAR: set-up " << nonlinear_setup_s
                  << " s, pressed " << nonlinear_press_s << " s at the slide's first pose, "
                  << nonlinear_hz << " updates/s (" << nonlinear_updates
                  << " updates after the first, which took " << nonlinear_first_s << " s), resident "
                  << nonlinear_mb << " MB"
                  << (nonlinear_error.empty() ? "" : "; not measured: " + nonlinear_error) << "\n";
        if (nonlinear_inline > 0) {
          std::vector<double> rest(inline_ms.size() > 1 ? inline_ms.begin() + 1 : inline_ms.end(),
                                   inline_ms.end());
          double mean = 0.0;
          for (double t : rest) mean += t / static_cast<double>(rest.size());
          const auto pr = neurosim::common::percentiles(rest);
          std::cerr << "scale_bench: cell " << cell << " mm, NONLINEAR inline: " << inline_ms.size()
                    << " updates in " << nonlinear_inline << " steps, the first "
                    << (inline_ms.empty() ? 0.0 : inline_ms[0]) << " ms, the second "
                    << (inline_ms.size() > 1 ? inline_ms[1] : 0.0) << " ms, the rest mean " << mean
                    << " ms (median " << pr.p50 << ", max " << pr.max << "), contact force "
                    << std::setprecision(17) << inline_force_n << std::setprecision(6) << " N"
                    << (inline_error.empty() ? "" : "; stopped: " + inline_error) << "\n";
          std::cerr << "scale_bench: cell " << cell << " mm, NONLINEAR inline, every update (ms):";
          for (double t : inline_ms) std::cerr << " " << t;
          std::cerr << "\n";
        }
        std::cerr << "scale_bench: cell " << cell << " mm, memory (MB): cold start peak " << cold_peak_mb
                  << ", after the cold one freed " << after_cold_mb << ", after the cached start "
                  << after_cached_mb << ", after the first pose's reach " << first_reach_mb
                  << ", after the slide " << after_slide_mb << ", after the fields " << after_fields_mb
                  << ", peak since the cached start " << rss_peak_mb
                  << (peak_reset ? "" : " (peak not reset: the whole process's)") << "; column cache "
                  << columns.ready_slots << " nodes x " << columns.bytes_per_slot / 1e6 << " MB, bound "
                  << columns.capacity_slots << " nodes, evicted " << columns.evicted << "\n";
      }
      // Always said (also with --csv): the slide started before the worker had the first pose.
      if (options.column_worker && !first_reach_done)
        std::cerr << "scale_bench: cell " << cell << " mm, the worker had not solved the first pose's "
                  << "reach after " << first_reach_s << " s (--first-reach-max-s): " << first_reach_nodes
                  << " nodes ready; the slide ran with the rest on the fallback (columns_not_ready)\n";
      else if (!csv && options.column_worker)
        std::cerr << "scale_bench: cell " << cell << " mm, the first pose's reach solved in "
                  << first_reach_s << " s (" << first_reach_nodes << " nodes)\n";
      if (!csv)
        std::cerr << "scale_bench: cell " << cell << " mm, column solves " << column_solves << ": "
                  << times.size() << " steps, " << steps_not_ready
                  << (options.column_worker ? " with columns not ready (" : " with first touches solved in the step (")
                  << not_ready << " nodes), " << solved_ahead
                  << " columns solved by the worker\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "scale_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
