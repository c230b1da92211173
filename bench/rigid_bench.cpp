// rigid_bench: what the skull costs per server step. For tool paths on scenes/brain_skull.scene
// (1 kHz, 0.5 m/s, back and forth), the ToolProxy (BVH query of the tip sphere and shaft capsule,
// constraint planes, projection) and the contact step (Simulation) are timed separately on the
// same poses: query p50/p99/max and step p50/p99/max in us, planes per step.
//   rigid_bench [--csv] [--steps N] [--reach M] [--scene FILE]
#include "common/cli.hpp"
#include "common/stats.hpp"
#include "server/interaction/rigid_obstacle.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/surface_probe.hpp"
#include "server/interaction/tool_proxy.hpp"
#include "server/scene/compile.hpp"

#include <chrono>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

namespace ni = neurosim::interaction;
namespace cli = neurosim::cli;
using Clock = std::chrono::steady_clock;

namespace {

double us_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  bool csv = false;
  int steps = 20000;
  ni::ToolProxyOptions proxy_options;
  std::string scene_path = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/brain_skull.scene";
  cli::Parser cli("rigid_bench", "Step cost of the rigid obstacles (tool proxy) next to the contact step.");
  cli.add_flag("--csv", csv, "CSV output");
  cli.add_option("--steps", steps, "steps per path")->check(cli::positive_number());
  cli.add_option("--reach", proxy_options.reach_m, "ToolProxyOptions::reach_m, m")
      ->check(cli::positive_number());
  cli.add_option("--scene", scene_path, "scene with a rigid mesh and an opening");
  if (auto rc = cli.parse(argc, argv)) return *rc;
  try {
    const neurosim::scene::Model model = neurosim::scene::load_model(scene_path);
    if (model.rigid.empty() || model.rigid.front().openings.empty())
      throw std::runtime_error(scene_path + ": no rigid mesh with an opening");
    const auto t_build = Clock::now();
    const auto obstacle = ni::RigidObstacle::build(model.rigid);
    const double build_ms = 1e-3 * us_since(t_build);
    // The server's step holds the tool by a proxy inside the Simulation; here the proxy and the
    // contact step are timed apart: the same proxy outside, a Simulation of the scene without its
    // rigid mesh (the same step otherwise).
    neurosim::scene::Model tissue_only = model;
    tissue_only.rigid.clear();
    auto sim = ni::Simulation::build(tissue_only);
    const auto& tool = model.tools.front();
    const ni::ToolShape shape{tool.tip_radius_m, tool.shaft_radius_m, tool.shaft_length_m};

    // Paths: the top of the skull (where the vertical line through the bounding box centre
    // enters the bone) and the opening's axis.
    const ni::Vec3 down(0, 0, -1);
    const ni::Vec3 top = ni::top_of_obstacle(*obstacle);
    const auto& hole = model.rigid.front().openings.front();
    struct Path {
      const char* name;
      ni::Vec3 from, to, axis;
    };
    const std::vector<Path> paths{
        {"outside (20-8 mm above the skull)", top - 0.020 * down, top - 0.008 * down, -down},
        {"touching (5 mm above to 10 mm into the skull)", top - 0.007 * down, top + 0.010 * down, -down},
        {"opening (through the craniotomy to the cerebellum)", hole.center_m + 0.04 * hole.axis,
         hole.center_m - 0.024 * hole.axis, hole.axis},
    };
    if (csv)
      std::printf("path,steps,planes_mean,query_p50_us,query_p99_us,query_max_us,step_p50_us,step_p99_us,"
                  "step_max_us,contact_steps\n");
    else
      std::printf("rigid obstacle: %d triangles, built in %.1f ms; reach %.1f mm; %d steps per path, 0.5 mm per step\n"
                  "%-52s %7s %9s %9s %9s | %9s %9s %9s %8s\n",
                  obstacle->num_triangles(), build_ms, 1e3 * proxy_options.reach_m, steps, "path", "planes", "query p50", "p99", "max",
                  "step p50", "p99", "max", "contact");
    for (const Path& p : paths) {
      ni::ToolProxy proxy(*obstacle, proxy_options);
      ni::ObstaclePlanes planes;
      std::vector<ni::ToolPose> poses(1);
      std::vector<ni::ToolContact> contacts;
      ni::StepStats stats;
      const double len = (p.to - p.from).norm();
      const int n_path = std::max(2, static_cast<int>(len / 0.0005) + 1);
      auto pose_at = [&](int k) {  // back and forth along the path
        const int period = 2 * (n_path - 1);
        int i = k % period;
        if (i >= n_path) i = period - i;
        ni::ToolPose t;
        t.tip_m = p.from + (p.to - p.from) * (static_cast<double>(i) / (n_path - 1));
        t.axis = p.axis;
        return t;
      };
      // Warm-up: one cycle (contact columns of the touched nodes cached).
      for (int k = 0; k < 2 * n_path; ++k) {
        poses[0] = pose_at(k);
        proxy.constrain(shape, poses[0], planes);
        sim->step(poses, contacts, stats);
      }
      std::vector<double> q_us, s_us;
      q_us.reserve(static_cast<std::size_t>(steps));
      s_us.reserve(static_cast<std::size_t>(steps));
      double planes_sum = 0.0;
      int contact_steps = 0;
      for (int k = 0; k < steps; ++k) {
        poses[0] = pose_at(k);
        const auto t0 = Clock::now();
        proxy.constrain(shape, poses[0], planes);
        const auto t1 = Clock::now();
        sim->step(poses, contacts, stats);
        s_us.push_back(us_since(t1));
        q_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
        planes_sum += planes.count;
        contact_steps += contacts[0].in_contact;
      }
      const auto q = neurosim::common::percentiles(q_us), s = neurosim::common::percentiles(s_us);
      if (csv)
        std::printf("\"%s\",%d,%.2f,%.2f,%.2f,%.2f,%.2f,%.2f,%.2f,%d\n", p.name, steps, planes_sum / steps, q.p50,
                    q.p99, q.max, s.p50, s.p99, s.max, contact_steps);
      else
        std::printf("%-52s %7.2f %9.2f %9.2f %9.2f | %9.2f %9.2f %9.2f %8d\n", p.name, planes_sum / steps, q.p50,
                    q.p99, q.max, s.p50, s.p99, s.max, contact_steps);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rigid_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
