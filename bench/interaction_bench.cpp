// interaction_bench: time per contact step with the exact tie (compliance columns
// cached), full-field displacement, the iterative baseline on the same rows, and the same scene
// with the coupling kind SLIDING (frictionless unilateral pairs solved with the tool contact).
//   interaction_bench [--csv] [--steps N] [--sliding-steps N] [--quick] [--residual-csv FILE]
//                     [--only SCENARIO] [--no-sliding-ref]
//   interaction_bench --brain-contact [--steps N] [--smooth-contact] [--contact-spread C]
//   interaction_bench --four-probes [--steps N]   (see four_probes below)
// --csv prints only the table; set-up times and notes go to stderr. SLIDING rows: `sliding` (the
// default LCP path, inverse of the sliding block at load) and `sliding_ref` (the reference path,
// factor of the active rows), unless --no-sliding-ref.
// --brain-contact: scenes/brain_artery.scene as it is (TIE, LINEAR, the 2 mm probe): a press
// breathing 0.6-1.4 mm deep on a 4 mm circle (after 200 warm-up steps; the axis the normal of
// the triangle under the tip, `brain_press`, then the same tip path with the axis held at the
// circle centre's normal, `brain_press_held_axis`), and a 10 s slide at
// 20 mm/s, 1 mm deep, over fresh surface (five 36 mm lines 5 mm apart joined by 4 mm moves),
// paced at 1 kHz by the clock, twice side by side: `brain_slide_step_solves` (the old way: a
// first touch's compliance columns solved inside the step) and `brain_slide_worker`
// (SimulationOptions::column_worker, the live server's: solved ahead of the tool on the worker
// thread, which starts at the slide's first pose as it does when a station joins): per-step
// p50 / p99 / max (us) of the wall time and of the thread's CPU time (the step's own work: on a
// loaded machine the wall time of a preempted step includes another process's time slice), rows
// and LCPs per step, steps with no force, columns computed in the step, and columns not ready
// (nodes whose row took the worker's fallback, summed over the steps); the steps without force
// and their tips to stderr. --smooth-contact: contact_spread 1, smooth normals, the near field
// (the library's defaults); --barycentric-contact: the rows on their triangle's three nodes
// (contact_spread 0, no smooth normals, no near field: the default before them); without
// --brain-contact it sets the same for every scenario (the step without the contact options).
// Only the Simulation contract.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/stats.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/iterative_tie.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/surface_probe.hpp"
#include "server/scene/compile.hpp"

#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace ni = neurosim::interaction;
using Clock = std::chrono::steady_clock;

namespace {

struct Scenario {
  std::string name;
  neurosim::scene::Model model;
  Eigen::Vector3d centre;  // where the tool presses (on the top face), unit m
  double radius_m;         // tool tip radius, unit m
  double depth_m;          // mean indentation, unit m
};

using neurosim::common::percentile;

std::string brain_like_scene() {
  // Paper Table 2b sizes: brain 5367 vertices / 25103 tets, artery 1644 / 4449. Stand-ins: a box
  // the size of a brain and a thin oblique tube inside it.
  return R"(name: "brain_like"
meshes { id: "brain" generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.14 y: 0.11 z: 0.09 } } target_vertices: 5367 seed: 1 }
  material { name: "brain" youngs_modulus_pa: 1.0e6 poisson_ratio: 0.4 }
  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-6 } } } priority: 0 }
meshes { id: "artery" generate { cylinder { base_center_m { x: 0.02 y: 0.03 z: 0.03 } axis_m { x: 0.1 y: 0.05 z: 0.03 } radius_m: 0.0025 } target_vertices: 1644 seed: 1 }
  material { name: "artery" youngs_modulus_pa: 1.0e5 poisson_ratio: 0.4 } priority: 1 }
couplings { host: "brain" embedded: "artery" kind: TIE method: EXACT }
tools { id: "probe" tip_radius_m: 0.025 shaft_radius_m: 0.0015 shaft_length_m: 0.12 }
effects { tier: LINEAR coupling: true tool_contact: true deformation_output: true }
)";
}


// CPU time of the calling thread, unit us: a step's own work, without the time the scheduler
// gave other processes (on a loaded machine a preempted step's wall time includes a time slice).
double thread_cpu_us() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e6 * static_cast<double>(t.tv_sec) + 1e-3 * static_cast<double>(t.tv_nsec);
}

struct RunTimes {
  std::vector<double> us;
  std::vector<double> cpu_us;  // thread CPU time per step
  double lcps{0.0};            // LCPs per step (StepStats::geometry_iterations)
  double rows{0.0};
  int zero_force{0};
  std::vector<std::size_t> zero_force_at;  // the steps without force (the first 8)
  int columns{0};
  long not_ready{0};  // StepStats::columns_not_ready summed over the steps
};

// --dump FILE: every step's answer of the deterministic paths, the floating point values in %a
// (bit for bit: two builds give the same file when their answers are identical): the case, the
// step, contact rows, LCP iterations (geometries, the answer's), whether it converged, and per
// tool the force, the stiffness K, the validity radius and the loaded nodes.
FILE* dump_file = nullptr;
// --step-csv FILE: one line per timed step (case, step, wall and thread CPU time, rows, LCPs,
// pivots, warm starts taken, columns computed / not ready, candidate triangles tested): which
// steps make the tail.
FILE* step_csv = nullptr;
void dump_step(const char* name, std::size_t k, const std::vector<ni::ToolContact>& contacts,
               const ni::StepStats& stats) {
  if (dump_file == nullptr) return;
  std::fprintf(dump_file, "%s %zu rows=%d geo=%d conv=%d", name, k, stats.contact_rows,
               stats.geometry_iterations, stats.converged ? 1 : 0);
  for (const auto& c : contacts) {
    std::fprintf(dump_file, " | it=%d ic=%d F=%a %a %a K=", c.iterations, c.in_contact ? 1 : 0,
                 c.force_n[0], c.force_n[1], c.force_n[2]);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) std::fprintf(dump_file, "%a ", c.stiffness_n_per_m(i, j));
    std::fprintf(dump_file, "vr=%a nodes=", c.validity_radius_m);
    for (int v : c.nodes) std::fprintf(dump_file, "%d,", v);
  }
  std::fprintf(dump_file, "\n");
}

// Steps the poses, timing each step (paced: one step per millisecond of the clock, as the server
// steps, so that a worker thread beside the step runs in real time).
RunTimes run_poses(ni::Simulation& sim, const std::vector<ni::ToolPose>& poses, bool paced = false,
                   const char* dump_name = nullptr) {
  RunTimes r;
  std::vector<ni::ToolContact> contacts;
  ni::StepStats stats;
  std::vector<ni::ToolPose> one(1);
  auto next = Clock::now();
  for (const auto& p : poses) {
    one[0] = p;
    if (paced) {
      next += std::chrono::microseconds(1000);
      std::this_thread::sleep_until(next);
    }
    const auto ts = Clock::now();
    const double c0 = thread_cpu_us();
    sim.step(one, contacts, stats);
    const double c1 = thread_cpu_us();
    r.us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
    r.cpu_us.push_back(c1 - c0);
    r.lcps += stats.geometry_iterations;
    r.rows += stats.contact_rows;
    r.columns += stats.columns_computed;
    r.not_ready += stats.columns_not_ready;
    if (dump_name) dump_step(dump_name, r.us.size() - 1, contacts, stats);
    if (step_csv && dump_name)
      std::fprintf(step_csv, "%s,%zu,%.2f,%.2f,%d,%d,%d,%d,%d,%d,%d\n", dump_name,
                   r.us.size() - 1, r.us.back(), r.cpu_us.back(), stats.contact_rows,
                   stats.geometry_iterations, stats.lcp_pivots, stats.lcp_warm_taken,
                   stats.columns_computed, stats.columns_not_ready, stats.candidate_tests);
    if (!(contacts[0].force_n.norm() > 0.0)) {
      if (r.zero_force < 8) r.zero_force_at.push_back(r.us.size() - 1);
      ++r.zero_force;
    }
  }
  r.rows /= static_cast<double>(std::max<std::size_t>(1, poses.size()));
  r.lcps /= static_cast<double>(std::max<std::size_t>(1, poses.size()));
  return r;
}

int brain_contact(int steps, const ni::SimulationOptions& contact) {
  const std::string path = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/brain_artery.scene";
  const neurosim::scene::Model model = neurosim::scene::load_model(path);
  const double r = model.tools.at(0).tip_radius_m;
  auto sim = ni::Simulation::build(model, contact);
  const auto& mesh = sim->mesh(0);
  auto pose_at = [&](double x, double y, double depth, ni::ToolPose& pose) {
    const auto on = ni::top_of_surface(mesh, x, y);
    if (!on) return false;
    pose.tip_m = on->point_m + (r - depth) * on->normal;
    pose.axis = on->normal;
    return true;
  };
  // Press: breathing 0.6-1.4 mm on a 4 mm circle around (60, 100) mm.
  std::vector<ni::ToolPose> warm, press;
  for (int k = 0; k < 200 + steps; ++k) {
    const double a = 2.0 * M_PI * k / 200.0, b = 2.0 * M_PI * k / 50.0;
    ni::ToolPose pose;
    if (!pose_at(0.060 + 0.004 * std::cos(a), 0.100 + 0.004 * std::sin(a),
                 0.001 * (1.0 + 0.4 * std::sin(b)), pose)) {
      std::cerr << "brain-contact: the press path leaves the surface\n";
      return 1;
    }
    (k < 200 ? warm : press).push_back(pose);
  }
  run_poses(*sim, warm, false, "brain_press_warm");
  const RunTimes tp = run_poses(*sim, press, false, "brain_press");
  // The press's axis is the normal of the triangle under the tip, and the tip is offset along
  // it: both jump where the tip crosses an edge onto a differently inclined triangle (the 150 mm
  // shaft's end by centimetres, the tip by up to a millimetre), which no hand does in a
  // millisecond. The same circle and depths with the tool translated by the hand, its axis held
  // (the normal at the circle's centre, the tip offset along it) is the press without jumps.
  double turn = 0.0, jump = 0.0;
  for (std::size_t k = 1; k < press.size(); ++k) {
    turn = std::max(turn, std::acos(std::clamp(press[k].axis.dot(press[k - 1].axis), -1.0, 1.0)));
    jump = std::max(jump, (press[k].tip_m - press[k - 1].tip_m).norm());
  }
  std::fprintf(stderr,
               "brain_press: in a step the axis turns by up to %.1f degrees, the tip moves by up "
               "to %.3f mm\n",
               turn * 180.0 / M_PI, 1e3 * jump);
  const auto centre = ni::top_of_surface(mesh, 0.060, 0.100);
  if (!centre) {
    std::cerr << "brain-contact: the press's centre is off the surface\n";
    return 1;
  }
  for (int k = 0; k < 200 + steps; ++k) {
    const double a = 2.0 * M_PI * k / 200.0, b = 2.0 * M_PI * k / 50.0;
    const auto on =
        ni::top_of_surface(mesh, 0.060 + 0.004 * std::cos(a), 0.100 + 0.004 * std::sin(a));
    auto& pose = k < 200 ? warm[k] : press[k - 200];
    pose.tip_m = on->point_m + (r - 0.001 * (1.0 + 0.4 * std::sin(b))) * centre->normal;
    pose.axis = centre->normal;
  }
  run_poses(*sim, warm, false, "brain_press_held_axis_warm");
  const RunTimes th = run_poses(*sim, press, false, "brain_press_held_axis");
  // Slide: 10 s at 20 mm/s (1 mm per 50 steps), 1 mm deep, over surface the press never touched.
  std::vector<ni::ToolPose> slide;
  const double step_m = 0.020 / 1000.0;
  double x = 0.045, y = 0.060, dir = 1.0;
  for (int line = 0; line < 5; ++line) {
    for (double s = 0.0; s < 0.036 - 1e-12; s += step_m) {
      ni::ToolPose pose;
      if (!pose_at(x, y, 0.001, pose)) {
        std::cerr << "brain-contact: the slide leaves the surface at " << x << ", " << y << "\n";
        return 1;
      }
      slide.push_back(pose);
      y += dir * step_m;
    }
    for (double s = 0.0; s < 0.004 - 1e-12; s += step_m) {
      ni::ToolPose pose;
      if (!pose_at(x, y, 0.001, pose)) {
        std::cerr << "brain-contact: the slide leaves the surface at " << x << ", " << y << "\n";
        return 1;
      }
      slide.push_back(pose);
      x += step_m;  // towards the midline (still 25 mm off it at the end)
    }
    dir = -dir;
  }
  sim.reset();
  RunTimes ts, tw;
  {
    auto fresh = ni::Simulation::build(model, contact);
    ts = run_poses(*fresh, slide, true, "brain_slide_step_solves");
  }
  {
    ni::SimulationOptions options = contact;
    options.column_worker = true;
    auto fresh = ni::Simulation::build(model, options);
    run_poses(*fresh, {slide.front()});  // the worker starts where the tool joins
    if (!fresh->wait_columns_ready(600.0)) {
      std::cerr << "brain-contact: the column worker did not finish the first pose's reach\n";
      return 1;
    }
    tw = run_poses(*fresh, slide, true);
  }
  std::cout << "case,steps,p50_us,p99_us,max_us,cpu_p50_us,cpu_p99_us,cpu_max_us,rows_per_step,"
               "lcps_per_step,zero_force_steps,columns_computed,columns_not_ready\n";
  auto print = [](const char* name, const RunTimes& t) {
    char line[320];
    std::snprintf(line, sizeof line, "%s,%zu,%.1f,%.1f,%.1f,%.1f,%.1f,%.1f,%.2f,%.2f,%d,%d,%ld\n", name,
                  t.us.size(), percentile(t.us, 0.5), percentile(t.us, 0.99),
                  *std::max_element(t.us.begin(), t.us.end()), percentile(t.cpu_us, 0.5),
                  percentile(t.cpu_us, 0.99), *std::max_element(t.cpu_us.begin(), t.cpu_us.end()),
                  t.rows, t.lcps, t.zero_force, t.columns, t.not_ready);
    std::cout << line;
  };
  print("brain_press", tp);
  print("brain_press_held_axis", th);
  print("brain_slide_step_solves", ts);
  print("brain_slide_worker", tw);
  // Where a slide step had no force: its index and tip (unit mm), to stderr.
  for (std::size_t k : ts.zero_force_at)
    std::fprintf(stderr, "brain_slide: no force at step %zu, tip %.4f %.4f %.4f mm\n", k,
                 1e3 * slide[k].tip_m.x(), 1e3 * slide[k].tip_m.y(), 1e3 * slide[k].tip_m.z());
  for (std::size_t k : tw.zero_force_at)
    std::fprintf(stderr, "brain_slide_worker: no force at step %zu, tip %.4f %.4f %.4f mm\n", k,
                 1e3 * slide[k].tip_m.x(), 1e3 * slide[k].tip_m.y(), 1e3 * slide[k].tip_m.z());
  return 0;
}

// --four-probes: cube_cylinder.scene as it is (its 3 mm probe), four probes pressing 1.5-2.5 mm
// into the cube's +x face at latency_bench's four station points (axis +z, the stations' identity
// orientation: the shaft lies in the face), one probe's pose new
// per step (a server stepping on each station's pose; each probe at 0.5 Hz, 1 kHz per station),
// twice side by side: `lcp_warm` (SimulationOptions::lcp_warm_start, the default) and `lcp_cold`
// (false), stepped alternately after 2000 warm-up steps each. Per step: thread CPU time p50 /
// p99 / mean (us), wall p50, rows, LCP pivots and LCPs that took the warm start; and the steps
// whose answers (force, K, nodes of every probe) differ between the two (0: bit for bit).
int four_probes(int steps) {
  const std::string path = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/cube_cylinder.scene";
  const neurosim::scene::Model model = neurosim::scene::load_model(path);
  ni::SimulationOptions warm_options, cold_options;
  cold_options.lcp_warm_start = false;
  auto warm = ni::Simulation::build(model, warm_options);
  auto cold = ni::Simulation::build(model, cold_options);
  const double r = model.tools.at(0).tip_radius_m;
  std::vector<ni::ToolPose> poses(4);
  auto place = [&](long step) {
    const int k = static_cast<int>(step % 4);
    const double a = 2.0 * M_PI * k / 4.0, t = 1e-3 * static_cast<double>(step / 4);
    ni::ToolPose& p = poses[static_cast<std::size_t>(k)];
    p.tip_m = Eigen::Vector3d(0.1 + r - 0.002 - 0.0005 * std::sin(2.0 * M_PI * 0.5 * t),
                              0.05 + 0.025 * std::cos(a), 0.05 + 0.025 * std::sin(a));
    p.axis = Eigen::Vector3d::UnitZ();  // latency_bench's stations: identity orientation
    p.station = k;
  };
  for (long s = 0; s < 4; ++s) place(s);
  std::vector<ni::ToolContact> cw, cc;
  ni::StepStats sw, sc;
  struct Side {
    std::vector<double> cpu_us, us;
    double rows{0.0}, pivots{0.0}, lcps{0.0}, taken{0.0};
  } w, c;
  auto one = [](ni::Simulation& sim, const std::vector<ni::ToolPose>& p,
                std::vector<ni::ToolContact>& out, ni::StepStats& st, Side* side) {
    const auto ts = Clock::now();
    const double c0 = thread_cpu_us();
    sim.step(p, out, st);
    const double c1 = thread_cpu_us();
    if (side == nullptr) return;
    side->us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
    side->cpu_us.push_back(c1 - c0);
    side->rows += st.contact_rows;
    side->pivots += st.lcp_pivots;
    side->lcps += st.geometry_iterations;
    side->taken += st.lcp_warm_taken;
  };
  int differ = 0, unconverged = 0;
  for (long s = 0; s < 2000 + steps; ++s) {
    place(s);
    const bool timed = s >= 2000;
    // Alternate which goes first (caches, preemption).
    if (s % 2 == 0) {
      one(*warm, poses, cw, sw, timed ? &w : nullptr);
      one(*cold, poses, cc, sc, timed ? &c : nullptr);
    } else {
      one(*cold, poses, cc, sc, timed ? &c : nullptr);
      one(*warm, poses, cw, sw, timed ? &w : nullptr);
    }
    if (!sw.converged || !sc.converged) ++unconverged;
    bool same = cw.size() == cc.size();
    for (std::size_t t = 0; same && t < cw.size(); ++t)
      same = cw[t].force_n == cc[t].force_n && cw[t].stiffness_n_per_m == cc[t].stiffness_n_per_m &&
             cw[t].nodes == cc[t].nodes && cw[t].in_contact == cc[t].in_contact;
    if (!same) ++differ;
    if (timed) dump_step("four_probes", static_cast<std::size_t>(s - 2000), cw, sw);
  }
  std::cout << "case,steps,cpu_p50_us,cpu_p99_us,cpu_mean_us,p50_us,rows_per_step,"
               "pivots_per_step,lcps_per_step,warm_taken_per_step,steps_differing,unconverged\n";
  auto print = [&](const char* name, const Side& x) {
    const double n = static_cast<double>(std::max<std::size_t>(1, x.cpu_us.size()));
    double sum = 0.0;
    for (double v : x.cpu_us) sum += v;
    char line[320];
    std::snprintf(line, sizeof line, "%s,%zu,%.1f,%.1f,%.1f,%.1f,%.2f,%.2f,%.2f,%.2f,%d,%d\n", name,
                  x.cpu_us.size(), percentile(x.cpu_us, 0.5), percentile(x.cpu_us, 0.99), sum / n,
                  percentile(x.us, 0.5), x.rows / n, x.pivots / n, x.lcps / n, x.taken / n, differ,
                  unconverged);
    std::cout << line;
  };
  print("lcp_warm", w);
  print("lcp_cold", c);
  return differ == 0 && unconverged == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  bool csv = false, quick = false;
  int steps = 2000;
  int sliding_steps = -1;  // default: as --steps
  std::string only;        // one scenario by name
  bool sliding_ref = true;
  std::string residual_csv;
  bool no_sliding_ref = false;
  bool brain = false, smooth_contact = false;
  double contact_spread = -1.0;
  std::string dump;
  neurosim::cli::Parser cli("interaction_bench",
                            "Per-step contact solve: exact vs iterative coupling, sliding.");
  cli.add_flag("--csv", csv, "print CSV");
  cli.add_option("--steps", steps, "steps per scenario")->capture_default_str();
  cli.add_option("--sliding-steps", sliding_steps, "steps of the sliding rows (default: --steps)");
  cli.add_flag("--quick", quick, "small cases only");
  cli.add_option("--residual-csv", residual_csv, "write the iterative residuals as CSV");
  cli.add_option("--only", only, "one scenario by name");
  cli.add_flag("--no-sliding-ref", no_sliding_ref, "no sliding reference solve");
  cli.add_flag("--brain-contact", brain, "brain_artery press and 10 s slide (contact rows)");
  bool four = false;
  cli.add_flag("--four-probes", four,
               "cube_cylinder, four probes in the +x face: LCP warm start against cold start");
  cli.add_flag("--smooth-contact", smooth_contact,
               "with --brain-contact: SimulationOptions contact_spread 1 (or --contact-spread), "
               "contact_smooth_normals, contact_near_field");
  bool barycentric_contact = false;
  cli.add_flag("--barycentric-contact", barycentric_contact,
               "contact_spread 0, no smooth normals, no near field (every scenario)");
  cli.add_option(
      "--contact-spread", contact_spread,
      "with --brain-contact: SimulationOptions::contact_spread (default: the library's)");
  cli.add_option("--dump", dump,
                 "write every step's answer of the deterministic paths (%a: force, K, rows, LCP "
                 "iterations, nodes) to this file, to compare two builds bit for bit");
  std::string step_csv_path;
  cli.add_option("--step-csv", step_csv_path,
                 "write one line per timed step (case, step, wall_us, cpu_us, rows, lcps, pivots, "
                 "warm_taken, columns_computed, columns_not_ready, candidate_tests) to this "
                 "file: which steps make the tail");
  if (auto rc = cli.parse(argc, argv)) return *rc;
  if (!step_csv_path.empty()) {
    step_csv = std::fopen(step_csv_path.c_str(), "w");
    if (step_csv == nullptr) {
      std::cerr << "interaction_bench: cannot write " << step_csv_path << "\n";
      return 2;
    }
    std::fprintf(step_csv,
                 "case,step,wall_us,cpu_us,rows,lcps,pivots,warm_taken,columns_computed,"
                 "columns_not_ready,candidate_tests\n");
  }
  if (!dump.empty()) {
    dump_file = std::fopen(dump.c_str(), "w");
    if (dump_file == nullptr) {
      std::cerr << "interaction_bench: cannot write " << dump << "\n";
      return 2;
    }
  }
  struct CloseDump {
    ~CloseDump() {
      if (dump_file) std::fclose(dump_file);
      if (step_csv) std::fclose(step_csv);
    }
  } close_dump;
  if (four) return four_probes(steps);
  if (brain) {
    ni::SimulationOptions contact;
    if (smooth_contact) {
      contact.contact_spread = 1.0;
      contact.contact_smooth_normals = true;
      contact.contact_near_field = true;
    }
    if (barycentric_contact) {
      contact.contact_spread = 0.0;
      contact.contact_smooth_normals = false;
      contact.contact_near_field = false;
    }
    if (contact_spread >= 0.0) contact.contact_spread = contact_spread;
    return brain_contact(steps, contact);
  }
  sliding_ref = !no_sliding_ref;
  if (sliding_steps < 0) sliding_steps = steps;
  std::vector<Scenario> scenarios;
  const std::string cube_path = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/cube_cylinder.scene";
  scenarios.push_back({"cube_cylinder", neurosim::scene::load_model(cube_path),
                       Eigen::Vector3d(0.05, 0.05, 0.1), 0.0, 0.004});
  // The paper's probe (3 mm tip) touches a handful of nodes; a 25 mm tip 8 mm deep reaches ~20.
  scenarios.back().model.tools.at(0).tip_radius_m = 0.025;
  scenarios.back().radius_m = 0.025;
  scenarios.back().depth_m = 0.008;
  if (!quick) {
    scenarios.push_back({"brain_like",
                         neurosim::scene::compile(
                             neurosim::scene::parse_scene(brain_like_scene(), "brain_like.scene"),
                             "brain_like.scene"),
                         Eigen::Vector3d(0.07, 0.055, 0.09), 0.025, 0.008});
  }
  std::ofstream residual_out;
  if (!residual_csv.empty()) {
    residual_out.open(residual_csv);
    residual_out << "scenario,iteration,relative_residual\n";
  }
  if (!csv)
    std::cout << "# interaction_bench: per-step times in us; set-up details on stderr\n";
  std::cout << "scenario,host_tets,embedded_tets,boundary_nodes,contact_nodes,method,p50_us,p99_us,"
               "tie_residual\n";
  for (auto& sc : scenarios) {
    if (!only.empty() && sc.name != only) continue;
    ni::SimulationOptions options;
    options.max_contact_nodes_per_tool = 20;
    options.cache_full_field_columns = true;
    if (barycentric_contact) {
      options.contact_spread = 0.0;
      options.contact_smooth_normals = false;
      options.contact_near_field = false;
    }
    // Cold start (cache empty) and second start (boundary operator read from the disk cache).
    const auto cache_dir = std::filesystem::temp_directory_path() /
                           ("neurosim_interaction_bench_" + std::to_string(::getpid()));
    std::filesystem::remove_all(cache_dir);
    options.compliance_cache_dir = cache_dir.string();
    double coupling_setup_s[2] = {0.0, 0.0};
    std::unique_ptr<ni::Simulation> sim;
    for (int start = 0; start < 2; ++start) {
      const auto t0 = Clock::now();
      auto built = ni::Simulation::build(sc.model, options);
      const double build_s = neurosim::common::seconds_since(t0);
      const auto& st = built->setup_stats();
      // Coupling set-up: everything after the meshes exist (mesh generation is the mesher's cost).
      coupling_setup_s[start] = build_s - st.load_meshes_s;
      std::cerr << sc.name << (start ? " (second start)" : " (cold)") << ": set-up " << build_s
                << " s (meshes " << st.load_meshes_s << ", factor " << st.factor_s << ", fusion "
                << st.fusion_s << ", condense " << st.condense_s << ", boundary columns "
                << st.boundary_s << ", operator " << st.operator_s << ", cache hits "
                << st.cache_hits << "); boundary nodes " << st.boundary_nodes << ", tied nodes "
                << st.tied_nodes << ", carved tets " << st.carved_tets << "\n";
      if (start == 0) sim = std::move(built);
    }
    std::filesystem::remove_all(cache_dir);
    // Tool path: a small circle on the top face with a breathing indentation.
    auto pose = [&](int k) {
      ni::ToolPose p;
      const double a = 2.0 * M_PI * k / 200.0, b = 2.0 * M_PI * k / 50.0;
      const double depth = sc.depth_m * (1.0 + 0.4 * std::sin(b));
      p.tip_m = sc.centre +
                Eigen::Vector3d(0.004 * std::cos(a), 0.004 * std::sin(a), sc.radius_m - depth);
      p.axis = Eigen::Vector3d::UnitZ();
      return p;
    };
    std::vector<ni::ToolContact> contacts;
    ni::StepStats stats;
    const auto tw = Clock::now();
    for (int k = 0; k < 200; ++k) {  // warm-up: columns cached
      sim->step({pose(k)}, contacts, stats);
      dump_step((sc.name + "_warm").c_str(), k, contacts, stats);
    }
    std::cerr << sc.name << ": warm-up (first touches, columns computed) "
              << neurosim::common::seconds_since(tw) << " s\n";
    std::vector<double> times;
    std::vector<ni::ToolPose> one(1);
    int max_nodes = 0, failures = 0;
    std::vector<int> epivots;
    double erows = 0.0;
    for (int k = 0; k < steps; ++k) {
      one[0] = pose(k);
      const auto ts = Clock::now();
      sim->step(one, contacts, stats);
      times.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
      dump_step(sc.name.c_str(), k, contacts, stats);
      max_nodes = std::max(max_nodes, static_cast<int>(contacts[0].nodes.size()));
      epivots.push_back(contacts[0].iterations);
      erows += stats.contact_rows;
      if (!stats.converged) ++failures;
    }
    std::sort(epivots.begin(), epivots.end());
    if (!epivots.empty())
      std::cerr << sc.name << ": contact rows per step " << erows / static_cast<double>(steps)
                << ", LCP pivots per step median " << epivots[epivots.size() / 2] << " max "
                << epivots.back() << "\n";
    const double depth_now = sc.depth_m;
    const double tie = sim->tie_residual_m() / depth_now;
    const int host_tets = static_cast<int>(sim->mesh(0).num_tets());
    const int emb_tets = static_cast<int>(sim->mesh(1).num_tets());
    const ni::CoupledBody* body = sim->body_of(0);
    const int boundary = static_cast<int>(body->boundary_nodes().size());
    char line[512];
    std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.1f,%.1f,%.3g\n", sc.name.c_str(),
                  host_tets, emb_tets, boundary, max_nodes, "exact", percentile(times, 0.5),
                  percentile(times, 0.99), tie);
    std::cout << line;
    if (failures) std::cerr << sc.name << ": " << failures << " steps did not converge\n";

    // Full-field displacement of the host: one sparse solve with the contact and coupling forces,
    // or the sum of the cached full coupled columns of the contact nodes.
    std::vector<double> full, cached;
    Eigen::VectorXd u, uc;
    std::vector<int> fslots;
    std::vector<Eigen::Vector3d> fforces;
    sim->last_contact_forces(0, fslots, fforces);
    for (int k = 0; k < 30; ++k) {
      auto ts = Clock::now();
      body->host_displacement(fslots, fforces, u);
      full.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
      ts = Clock::now();
      sim->displacements(0, uc);
      cached.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
    }
    const double diff = (u - uc).cwiseAbs().maxCoeff() / std::max(1e-300, u.cwiseAbs().maxCoeff());
    std::cerr << sc.name << ": full field, cached columns vs sparse solve: max relative difference "
              << diff << "\n";
    std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.1f,%.1f,%.3g\n", sc.name.c_str(),
                  host_tets, emb_tets, boundary, max_nodes, "exact_full_field_solve",
                  percentile(full, 0.5), percentile(full, 0.99), tie);
    std::cout << line;
    std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.1f,%.1f,%.3g\n", sc.name.c_str(),
                  host_tets, emb_tets, boundary, max_nodes, "exact_full_field_cached",
                  percentile(cached, 0.5), percentile(cached, 0.99), tie);
    std::cout << line;

    std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.0f,%.0f,%.3g\n", sc.name.c_str(),
                  host_tets, emb_tets, boundary, max_nodes, "setup_coupling_cold",
                  1e6 * coupling_setup_s[0], 1e6 * coupling_setup_s[0], tie);
    std::cout << line;
    std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.0f,%.0f,%.3g\n", sc.name.c_str(),
                  host_tets, emb_tets, boundary, max_nodes, "setup_coupling_cached",
                  1e6 * coupling_setup_s[1], 1e6 * coupling_setup_s[1], tie);
    std::cout << line;

    // Iterative baseline on the same contact forces: time to reach the exact answer to 1e-12.
    ni::IterativeOptions iopt;
    iopt.tolerance = 1e-12;
    ni::IterativeTie iterative(*body, iopt);
    std::vector<double> itimes;
    std::vector<int> iters;
    double worst = 0.0;
    std::vector<int> slots;
    std::vector<Eigen::Vector3d> forces;
    Eigen::VectorXd ub;
    for (int k = 0; k < 40; ++k) {
      sim->step({pose(5 * k)}, contacts, stats);
      sim->last_contact_forces(0, slots, forces);
      const Eigen::VectorXd exact = iterative.exact(slots, forces);
      const auto ts = Clock::now();
      const ni::IterativeResult r = iterative.solve(slots, forces, exact, ub);
      itimes.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
      iters.push_back(r.iterations);
      worst = std::max(worst, r.residual.empty() ? 0.0 : r.residual.back());
      if (k == 0 && residual_out) {
        for (std::size_t i = 0; i < r.residual.size(); ++i)
          residual_out << sc.name << "," << i + 1 << "," << r.residual[i] << "\n";
      }
    }
    std::sort(iters.begin(), iters.end());
    std::cerr << sc.name << ": iterative baseline: relaxation " << iterative.relaxation()
              << ", iterations median " << iters[iters.size() / 2] << " max " << iters.back()
              << "\n";
    std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.1f,%.1f,%.3g\n", sc.name.c_str(),
                  host_tets, emb_tets, boundary, max_nodes, "iterative", percentile(itimes, 0.5),
                  percentile(itimes, 0.99), worst);
    std::cout << line;
    std::cout.flush();

    // SLIDING: the same scene and tool path with the coupling kind SLIDING (meshes touching at
    // rest): every surface node of the embedded mesh is a unilateral row of the step's LCP.
    // tie_residual column: largest interpenetration max(0, -g) over all pairs / mean depth,
    // from full-field solves at 20 poses of the timed path.
    for (int variant = 0; variant < (sliding_ref ? 2 : 1) && sliding_steps > 0; ++variant) {
      const std::string tag = variant == 0 ? "sliding" : "sliding_ref";
      auto model = sc.model;
      model.couplings.at(0).kind = neurosim::scene::CouplingKind::kSliding;
      ni::SimulationOptions sopt;
      sopt.max_contact_nodes_per_tool = 20;
      sopt.sliding_inactive_set = variant == 0;
      if (barycentric_contact) {
        sopt.contact_spread = 0.0;
        sopt.contact_smooth_normals = false;
        sopt.contact_near_field = false;
      }
      const auto t0 = Clock::now();
      auto ssim = ni::Simulation::build(model, sopt);
      const double build_s = std::chrono::duration<double>(Clock::now() - t0).count();
      const auto& st = ssim->setup_stats();
      std::cerr << sc.name << " (" << tag << "): set-up " << build_s << " s (meshes "
                << st.load_meshes_s << ", sliding block " << st.sliding_s << "); sliding rows "
                << st.sliding_rows << "\n";
      const auto tws = Clock::now();
      for (int k = 0; k < 200; ++k) ssim->step({pose(k)}, contacts, stats);
      std::cerr << sc.name << " (" << tag << "): warm-up "
                << std::chrono::duration<double>(Clock::now() - tws).count() << " s\n";
      std::vector<double> stimes;
      int smax_nodes = 0, sfailures = 0, max_active = 0;
      std::vector<int> pivots;
      double penetration = 0.0;
      const int every = std::max(1, sliding_steps / 20);
      for (int k = 0; k < sliding_steps; ++k) {
        one[0] = pose(k);
        const auto ts = Clock::now();
        ssim->step(one, contacts, stats);
        stimes.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
        dump_step((sc.name + "_" + tag).c_str(), k, contacts, stats);
        smax_nodes = std::max(smax_nodes, static_cast<int>(contacts[0].nodes.size()));
        max_active = std::max(max_active, stats.sliding_active);
        pivots.push_back(contacts[0].iterations);
        if (!stats.converged) ++sfailures;
        if (k % every == 0) penetration = std::max(penetration, ssim->sliding_penetration_m());
      }
      std::sort(pivots.begin(), pivots.end());
      std::cerr << sc.name << " (" << tag << "): most active pairs " << max_active << " of "
                << st.sliding_rows << ", LCP pivots per step median " << pivots[pivots.size() / 2]
                << " max " << pivots.back() << ", steps not converged " << sfailures << "\n";
      std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.1f,%.1f,%.3g\n", sc.name.c_str(),
                    host_tets, emb_tets, st.sliding_rows, smax_nodes, tag.c_str(),
                    percentile(stimes, 0.5), percentile(stimes, 0.99), penetration / depth_now);
      std::cout << line;
      std::snprintf(line, sizeof line, "%s,%d,%d,%d,%d,%s,%.0f,%.0f,%.3g\n", sc.name.c_str(),
                    host_tets, emb_tets, st.sliding_rows, smax_nodes, ("setup_" + tag).c_str(),
                    1e6 * (build_s - st.load_meshes_s), 1e6 * (build_s - st.load_meshes_s),
                    penetration / depth_now);
      std::cout << line;
      std::cout.flush();
    }
  }
  return 0;
}
