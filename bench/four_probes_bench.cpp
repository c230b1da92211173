// four_probes_bench: the physics of latency_bench's server step in one process, so the contact
// step of two builds (e.g. an older commit's libraries) can be compared without DDS.
//
//   four_probes_bench [--new-per-step K] [--pace-us P] [--steps N] [--warmup N] [--barycentric] [--at-vertices] [--csv]
//
// cube_cylinder.scene as it is (its 3 mm probe), four probes pressing 1.5-2.5 mm into the cube's
// +x face at latency_bench's four station points (axis +z: the stations' identity orientation),
// each probe at 0.5 Hz and 1 kHz like a latency_bench station. Every step passes all four poses,
// as the server does; K of them (1..4, default 4) are new per step (the server at ~1.8 k steps/s
// on 4 x 1 kHz stations sees about 2). --pace-us P: P us asleep before each step (the server's step
// thread waits for the next pose; 0: steps back to back, caches warm). Per step: the step thread's
// CPU time (p50 / p99 / mean, us), rows, and the summed |F| of the last step (the physics' answer,
// to tell two builds' rows apart). --barycentric: the contact options off (SimulationOptions'
// contact_spread 0, contact_smooth_normals and contact_near_field false): one row per feature the
// tip touches, barycentric on its triangle, about as many rows as an older build's node rows, so
// the step's cost per row can be compared between builds whose default rows differ in number. A
// build without these options (node rows only) runs its only rows and says so ("rows node").
// --at-vertices: each probe centred on the +x face's surface vertex nearest its station point
// (instead of the station point itself): with --barycentric the rows a pressed vertex makes (its
// triangles merged into one row) against an older build's node rows, the same pose for both.
//
// Written against the interaction API that the server's step has used since before the service's
// split (Simulation::build, step, ToolPose, StepStats::contact_rows, scene::load_model), so the
// same file also compiles against an older tree's libraries (bench/RESULTS.md gives the command).
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace ni = neurosim::interaction;

namespace {

double thread_cpu_us() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e6 * static_cast<double>(t.tv_sec) + 1e-3 * static_cast<double>(t.tv_nsec);
}

// The pose's station (the slot of a server's station) where the API has one.
template <class P>
auto set_station(P& p, int k, int) -> decltype(p.station = k, void()) {
  p.station = k;
}
template <class P>
void set_station(P&, int, long) {}

// The contact options off where the build has them (true), else false (node rows only).
template <class O>
auto set_barycentric(O& o, int) -> decltype(o.contact_spread = 0.0, o.contact_smooth_normals = false,
                                            o.contact_near_field = false, bool()) {
  o.contact_spread = 0.0;
  o.contact_smooth_normals = false;
  o.contact_near_field = false;
  return true;
}
template <class O>
bool set_barycentric(O&, long) {
  return false;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

int usage(const char* why) {
  std::fprintf(stderr,
               "four_probes_bench: %s\nusage: four_probes_bench [--new-per-step 1..4] [--pace-us P] "
               "[--steps N] [--warmup N] [--barycentric] [--at-vertices] [--csv]\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  int per_step = 4, steps = 6000, warmup = 2000;
  long pace_us = 0;
  bool csv = false, barycentric = false, at_vertices = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--new-per-step" && has_value) per_step = std::atoi(argv[++i]);
    else if (a == "--pace-us" && has_value) pace_us = std::atol(argv[++i]);
    else if (a == "--steps" && has_value) steps = std::atoi(argv[++i]);
    else if (a == "--warmup" && has_value) warmup = std::atoi(argv[++i]);
    else if (a == "--csv") csv = true;
    else if (a == "--barycentric") barycentric = true;
    else if (a == "--at-vertices") at_vertices = true;
    else return usage(("unknown or incomplete option '" + a + "'").c_str());
  }
  if (per_step < 1 || per_step > 4) return usage("--new-per-step must be 1..4");
  if (steps < 1 || warmup < 0 || pace_us < 0 || pace_us > 1000000) return usage("bad --steps, --warmup or --pace-us");

  const std::string path = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/cube_cylinder.scene";
  const auto model = neurosim::scene::load_model(path);
  ni::SimulationOptions options{};
  // The rows' kind: the build's default, its barycentric rows, or (a build without the contact
  // options, asked for --barycentric) its node rows, the only ones it has.
  const char* rows_kind = "default";
  if (barycentric) rows_kind = set_barycentric(options, 0) ? "barycentric" : "node";
  auto sim = ni::Simulation::build(model, options);
  const double r = model.tools.at(0).tip_radius_m;
  // The probes' points on the +x face (y, z), unit m: latency_bench's station points, or the face's
  // surface vertices nearest them (--at-vertices).
  std::vector<ni::Vec3> at(4);
  for (int k = 0; k < 4; ++k) {
    const double a = 2.0 * M_PI * k / 4.0;
    at[static_cast<std::size_t>(k)] = ni::Vec3(0.1, 0.05 + 0.025 * std::cos(a), 0.05 + 0.025 * std::sin(a));
  }
  if (at_vertices) {
    const auto& host = model.meshes.at(0).mesh;
    for (auto& p : at) {
      double best = 1e9;
      ni::Vec3 nearest = p;
      for (const auto& t : host.surface())
        for (int v : t) {
          const ni::Vec3 x = host.vertices()[static_cast<std::size_t>(v)];
          const double d = (x - p).norm();
          if (std::abs(x.x() - 0.1) < 1e-6 && d < best) {
            best = d;
            nearest = x;
          }
        }
      if (best > 0.01) {
        std::fprintf(stderr, "four_probes_bench: no surface vertex of %s on the face x = 0.1 m within 10 mm of "
                     "(%.4f, %.4f) m\n", model.meshes.at(0).id.c_str(), p.y(), p.z());
        return 1;
      }
      p = nearest;
    }
  }
  std::vector<ni::ToolPose> poses(4);
  // Pose number q: probe q % 4 at its (q / 4)-th millisecond (latency_bench's station motion).
  auto place = [&](long q) {
    const int k = static_cast<int>(q % 4);
    const double t = 1e-3 * static_cast<double>(q / 4);
    ni::ToolPose& p = poses[static_cast<std::size_t>(k)];
    const ni::Vec3& on = at[static_cast<std::size_t>(k)];
    p.tip_m = ni::Vec3(0.1 + r - 0.002 - 0.0005 * std::sin(2.0 * M_PI * 0.5 * t), on.y(), on.z());
    p.axis = ni::Vec3::UnitZ();
    p.tool = 0;
    set_station(p, k, 0);
  };
  long q = 0;
  for (; q < 4; ++q) place(q);
  std::vector<ni::ToolContact> contacts;
  ni::StepStats stats;
  std::vector<double> cpu;
  cpu.reserve(static_cast<std::size_t>(steps));
  double rows = 0.0;
  for (int s = 0; s < warmup + steps; ++s) {
    if (pace_us > 0) {
      const timespec ts{pace_us / 1000000, (pace_us % 1000000) * 1000};
      nanosleep(&ts, nullptr);
    }
    for (int j = 0; j < per_step; ++j) place(q++);
    const double c0 = thread_cpu_us();
    sim->step(poses, contacts, stats);
    const double c1 = thread_cpu_us();
    if (s < warmup) continue;
    cpu.push_back(c1 - c0);
    rows += stats.contact_rows;
  }
  double mean = 0.0;
  for (double v : cpu) mean += v;
  mean /= static_cast<double>(cpu.size());
  double force = 0.0;
  for (const auto& c : contacts) force += c.force_n.norm();
  const double p50 = percentile(cpu, 0.5), p99 = percentile(cpu, 0.99);
  if (csv) {
    std::printf("new_per_step,pace_us,steps,cpu_p50_us,cpu_p99_us,cpu_mean_us,rows_per_step,last_force_sum_n,rows\n");
    std::printf("%d,%ld,%d,%.1f,%.1f,%.1f,%.2f,%.6f,%s\n", per_step, pace_us, steps, p50, p99, mean,
                rows / static_cast<double>(steps), force, rows_kind);
  } else {
    std::printf("%d of 4 poses new per step, %ld us asleep before each, %d steps: step CPU p50 %.1f us, p99 %.1f, "
                "mean %.1f; %.2f rows per step (%s rows); last step's summed |F| %.6f N\n",
                per_step, pace_us, steps, p50, p99, mean, rows / static_cast<double>(steps), rows_kind,
                force);
  }
  return 0;
}
