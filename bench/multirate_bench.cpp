// multirate_bench: what each elasticity tier costs in the real-time loop, and what the multirate
// scheme costs in accuracy.
//   multirate_bench [--csv] [--only SCENE] [--tier T]... [--seconds S] [--update-steps N]...
// Per bundled scene and tier: Simulation set-up time and resident memory it added; then a press
// paced at 1 kHz (absolute deadlines): the tool goes in along the surface normal to the press
// depth over the first half of the run and is held for the second half, while the NONLINEAR
// equilibrium is updated on their worker thread as fast as they go (the server's
// mode; the step itself never waits). Reported: contact step p50/p99 (us), the worker's update
// rate (Hz), and the force error of the multirate answer against the converged tier answer at
// the same pose (the same Simulation with synchronous updates, held until the force is still),
// at mid-ramp, end of ramp and end of hold.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/stats.hpp"
#include "server/fem/served_tiers.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include <chrono>
#include <cstdlib>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace ni = neurosim::interaction;
using neurosim::common::Clock;
using neurosim::common::percentile;
using neurosim::common::seconds_since;

namespace {

struct Press {
  std::string name, path;
  Eigen::Vector3d origin;  // a surface point, unit m
  Eigen::Vector3d up;      // outward normal there (unit)
  double depth_m;
  double tip_radius_m;  // 0: the scene's
};

double resident_mb() {
  std::ifstream f("/proc/self/statm");
  long pages = 0, resident = 0;
  f >> pages >> resident;
  return resident * 4096.0 / (1024.0 * 1024.0);
}

ni::ToolPose pose_at(const Press& p, double r, double depth) {
  ni::ToolPose t;
  t.tip_m = p.origin + (r - depth) * p.up;
  t.axis = p.up;
  return t;
}

// Converged tier force at a pose: synchronous updates until the force is still (1e-10), at most
// 80 steps; `change` is the last step's relative change (reported when not still).
Eigen::Vector3d converged(ni::Simulation& sync, const ni::ToolPose& pose, int& steps,
                          double& change) {
  std::vector<ni::ToolContact> c;
  ni::StepStats st;
  Eigen::Vector3d prev = Eigen::Vector3d::Constant(1e300);
  for (steps = 1; steps <= 80; ++steps) {
    sync.step({pose}, c, st);
    change = (c[0].force_n - prev).norm() / c[0].force_n.norm();
    if (std::getenv("MULTIRATE_TRACE"))
      std::fprintf(stderr, "  reference step %d: force %.9g %.9g %.9g, rows %d, converged %d\n", steps,
                   c[0].force_n.x(), c[0].force_n.y(), c[0].force_n.z(), st.contact_rows,
                   st.converged ? 1 : 0);
    if (change <= 1e-10) break;
    prev = c[0].force_n;
  }
  return c[0].force_n;
}

}  // namespace

int main(int argc, char** argv) {
  bool csv = false;
  std::string only;
  std::vector<std::string> tiers{"linear", "nonlinear"};
  double seconds = 4.0;
  std::vector<int> update_steps{0};
  neurosim::cli::Parser cli("multirate_bench",
                            "Real-time contact step and multirate error of each elasticity tier.");
  cli.add_flag("--csv", csv, "CSV only");
  cli.add_option("--only", only, "one scene by name (cube_cylinder, brain_artery)");
  cli.add_option("--tier", tiers, "tiers to run")->capture_default_str();
  cli.add_option("--seconds", seconds, "paced run length (ramp half, hold half), s")
      ->check(neurosim::cli::range(0.2, 600.0))
      ->capture_default_str();
  cli.add_option("--update-steps", update_steps,
                 "Newton steps per equilibrium update (SimulationOptions::tier_update_steps; "
                 "0: each update converges); several values run side by side")
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  const std::string dir = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/";
  // cube: the top face's centre, the 25 mm probe of interaction_bench (about 20 nodes), 8 mm;
  // brain: the demo's press point on the right lateral surface with the scene's probe, 6 mm.
  const std::vector<Press> presses{
      {"cube_cylinder", dir + "cube_cylinder.scene", {0.05, 0.05, 0.1}, {0, 0, 1}, 0.008, 0.025},
      {"brain_artery", dir + "brain_artery.scene", {0.1605, 0.1125, 0.0787},
       Eigen::Vector3d(0.963, 0.176, 0.202).normalized(), 0.006, 0.0}};
  if (!csv) std::printf("# multirate_bench: %.1f s paced at 1 kHz per case; set-up on stderr\n", seconds);
  std::printf("scene,tier,update_steps,setup_s,memory_mb,step_p50_us,step_p99_us,step_max_us,update_hz,"
              "force_end_n,err_mid_ramp,err_end_ramp,err_end_hold,reference_steps\n");
  for (const Press& press : presses) {
    if (!only.empty() && press.name != only) continue;
    for (const std::string& tier_text : tiers) {
     for (const int steps_per_update : update_steps) {
      const auto tier = neurosim::fem::parse_tier(tier_text);
      if (!tier || !neurosim::fem::tier_served(*tier)) {
        std::fprintf(stderr, "multirate_bench: --tier %s: expected linear or nonlinear%s\n",
                     tier_text.c_str(), tier ? (std::string(" (") + neurosim::fem::kCorotationalWithdrawn + ")").c_str() : "");
        return 2;
      }
      neurosim::scene::Model model = neurosim::scene::load_model(press.path);
      model.effects.tier = *tier;
      if (press.tip_radius_m > 0.0) model.tools.at(0).tip_radius_m = press.tip_radius_m;
      const double r = model.tools.at(0).tip_radius_m;
      if (*tier == neurosim::fem::Tier::kLinear && steps_per_update != update_steps.front())
        continue;  // nothing to update
      ni::SimulationOptions options;
      options.tier_update_steps = steps_per_update;
      const double mb0 = resident_mb();
      const auto t0 = Clock::now();
      auto sim = ni::Simulation::build(model, options);
      const double setup_s = seconds_since(t0);
      const double memory_mb = resident_mb() - mb0;
      ni::SimulationOptions sync_options;  // converged updates: the reference
      sync_options.tier_worker_thread = false;
      auto sync = ni::Simulation::build(model, sync_options);

      const int steps = static_cast<int>(seconds * 1000.0);
      auto depth_at = [&](int k) {
        return press.depth_m * std::min(1.0, 2.0 * k / static_cast<double>(steps));
      };
      // Warm-up (the contact columns of the nodes the press touches are computed on first touch):
      // the ramp once, unpaced, then back out.
      std::vector<ni::ToolContact> contacts;
      ni::StepStats stats;
      for (int k = 0; k <= steps / 2; k += 10) sim->step({pose_at(press, r, depth_at(k))}, contacts, stats);
      for (int k = 0; k < 300; ++k) {
        sim->step({pose_at(press, r, -0.002)}, contacts, stats);
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      const std::vector<int> samples{steps / 4, steps / 2, steps - 1};
      std::vector<Eigen::Vector3d> sampled(samples.size());
      std::vector<double> times;
      times.reserve(steps);
      auto deadline = Clock::now();
      for (int k = 0; k < steps; ++k) {
        deadline += std::chrono::microseconds(1000);
        std::this_thread::sleep_until(deadline);
        const auto ts = Clock::now();
        sim->step({pose_at(press, r, depth_at(k))}, contacts, stats);
        times.push_back(std::chrono::duration<double, std::micro>(Clock::now() - ts).count());
        for (std::size_t i = 0; i < samples.size(); ++i)
          if (samples[i] == k) sampled[i] = contacts[0].force_n;
      }
      const double rate = sim->tier_update_rate_hz();
      double err[3];
      int ref_steps = 0;
      for (std::size_t i = 0; i < samples.size(); ++i) {
        int n = 0;
        double change = 0.0;
        const Eigen::Vector3d f =
            converged(*sync, pose_at(press, r, depth_at(samples[i])), n, change);
        ref_steps += n;
        if (change > 1e-10) {
          std::fprintf(stderr, "%s %s: reference at sample %zu not still after %d steps (%.3g)\n",
                       press.name.c_str(), tier_text.c_str(), i, n, change);
        }
        err[i] = (sampled[i] - f).norm() / f.norm();
      }
      std::printf("%s,%s,%d,%.3f,%.1f,%.1f,%.1f,%.1f,%.2f,%.6g,%.3g,%.3g,%.3g,%d\n",
                  press.name.c_str(), neurosim::fem::tier_name(*tier), steps_per_update, setup_s, memory_mb, percentile(times, 0.5),
                  percentile(times, 0.99), percentile(times, 1.0), rate,
                  contacts[0].force_n.norm(), err[0], err[1], err[2], ref_steps);
      std::fflush(stdout);
     }
    }
  }
  return 0;
}
