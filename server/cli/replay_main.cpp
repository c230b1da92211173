// neurosim-replay: offline replay of recorded tool trajectories (idl/recording.proto) through the
// server's simulation, deterministically (no threads, no clock): one step per distinct sample
// time, all stations together. Writes the contact forces per step and station (forces.csv) and
// the displacement fields as a ParaView time series (series.pvd + one .vtu per frame and mesh).
#include "common/cli.hpp"
#include "server/cli/replay.hpp"
#include "server/fem/element.hpp"
#include "server/fem/served_tiers.hpp"
#include "server/fem/tier.hpp"
#include "server/interaction/simulation.hpp"
#include "server/mesh/vtu.hpp"
#include "server/scene/compile.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using neurosim::interaction::Vec3;

namespace {

const char* kDescription =
    "Offline replay of recorded tool trajectories (one recording file per station) through the\n"
    "server's simulation, deterministically: the elasticity tier's equilibrium is updated inside\n"
    "each step (no worker thread, no clock), so two runs give byte-identical output.\n"
    "The samples of all recordings are merged by time; at each distinct sample time the\n"
    "simulation steps once with every station's newest sample so far. A station whose recording\n"
    "has not started yet is left out of the step (as the live server leaves out a station that\n"
    "has sent no pose); a station whose recording has ended keeps its last pose.\n"
    "Every sample first passes the live server's filter (its code): a sample the server would\n"
    "reject (non-finite, tip outside the scene's bounding box + 0.5 m, a jump faster than the\n"
    "tool's max_speed_m_per_s, ...) is an error unless --skip-rejected leaves it out.";
const char* kFooter =
    "Writes DIR/forces.csv (time_s,station,tip_x_m,tip_y_m,tip_z_m,force_x_n,force_y_n,\n"
    "force_z_n,in_contact; one row per step and station taking part, numbers as %.17g) and\n"
    "DIR/series.pvd with DIR/<mesh>_<frame>.vtu (point data displacement_m) for every active\n"
    "mesh at steps 0, N, 2N, ... and the last step (--every N).";

struct Options {
  std::string scene_path, out_dir, tier;  // tier: empty = the scene's
  std::string element;                    // empty: the scene's material.element
  std::vector<std::string> recordings;
  int every{10};
  double max_rate_hz{0.0};  // 0: every sample time
  bool skip_rejected{false};  // replay without the samples the live server would reject
  int max_rows{0};            // --contact-max-rows (0: the library's), as neurosim-server's
  int lcp_max_iterations{0};  // --lcp-max-iterations (0: the library's), as neurosim-server's
  std::string cache_dir;      // --cache-dir (empty: none), as neurosim-server's
};

std::string g17(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

int run(const Options& opt) {
  neurosim::scene::Model model = neurosim::scene::load_model(opt.scene_path);
  for (const auto& w : model.warnings) std::cerr << "neurosim-replay: warning: " << w << "\n";
  if (!opt.tier.empty()) model.effects.tier = *neurosim::fem::parse_tier(opt.tier);
  if (!opt.element.empty()) model.set_element(*neurosim::fem::parse_element(opt.element));
  if (model.tools.empty()) throw std::runtime_error(opt.scene_path + ": the scene has no tools");
  if (!model.effects.tool_contact) {
    std::cerr << "neurosim-replay: note: " << opt.scene_path
              << ": effects.tool_contact is off: no station will touch anything\n";
  }

  // Recordings: one station each.
  std::vector<neurosim::replay::Station> stations;
  for (const auto& file : opt.recordings) {
    stations.push_back(neurosim::replay::load_station(file, model));
    if (stations.back().samples.empty()) {
      std::cerr << "neurosim-replay: note: " << file << ": no samples (station '"
                << stations.back().id << "' never takes part)\n";
    }
  }
  const std::size_t num_steps = neurosim::replay::step_times(stations, opt.max_rate_hz).size();
  if (num_steps == 0) throw std::runtime_error("the recordings hold no samples");

  neurosim::interaction::SimulationOptions sim_options;
  sim_options.tier_worker_thread = false;
  // Compliance columns solved inside the step on first touch, never by the live server's column
  // worker: the replay's answer is the poses' alone (docs/ARCHITECTURE.md, "compliance").
  sim_options.column_worker = false;
  if (opt.max_rows > 0) sim_options.max_contact_nodes_per_tool = opt.max_rows;
  if (opt.lcp_max_iterations > 0) sim_options.lcp_max_iterations = opt.lcp_max_iterations;
  sim_options.compliance_cache_dir = opt.cache_dir;  // a read factor solves bit for bit as its own
  std::unique_ptr<neurosim::interaction::Simulation> sim =
      neurosim::interaction::Simulation::build(model, sim_options);
  // The live server's filter on every sample (its code, server/service/tool_filter.hpp): a
  // sample it would reject is an error (the replay would compute what no session could), or,
  // with --skip-rejected, left out as the server leaves it out.
  const neurosim::service::Workspace workspace = neurosim::replay::scene_workspace(*sim);
  std::size_t skipped = 0;
  for (auto& st : stations) {
    const auto rejected =
        neurosim::replay::filter_station(st, model, workspace, opt.skip_rejected);
    if (rejected.empty()) continue;
    std::map<std::string, std::size_t> by_cause;
    for (const auto& r : rejected) ++by_cause[neurosim::service::to_string(r.why)];
    std::string causes;
    for (const auto& [cause, n] : by_cause)
      causes += (causes.empty() ? "" : ", ") + std::to_string(n) + " " + cause;
    const auto& first = rejected.front();
    const std::string what = st.file + ": " + std::to_string(rejected.size()) +
                             " sample(s) the live server would reject (" + causes +
                             "), the first: sample " + std::to_string(first.index) + " at " +
                             g17(first.time_s) + " s (" + neurosim::service::to_string(first.why) +
                             ")";
    if (!opt.skip_rejected)
      throw std::runtime_error(what + "; --skip-rejected replays without them, as the server would");
    std::cerr << "neurosim-replay: note: " << what << ": skipped (--skip-rejected)\n";
    skipped += rejected.size();
  }
  const std::size_t steps_left = neurosim::replay::step_times(stations, opt.max_rate_hz).size();
  if (steps_left == 0) throw std::runtime_error("no sample left after the live server's filter");

  std::cout << "scene " << model.name << " (" << opt.scene_path << "), tier "
            << neurosim::fem::tier_name(model.effects.tier)
            << (opt.tier.empty() ? " (scene)" : " (--tier)") << "; " << stations.size()
            << " station(s), " << steps_left << " steps"
            << (skipped ? ", " + std::to_string(skipped) + " rejected sample(s) skipped"
                        : std::string())
            << "\n";

  const fs::path out(opt.out_dir);
  fs::create_directories(out);
  const fs::path csv_path = out / "forces.csv";
  std::ofstream csv(csv_path, std::ios::binary);
  if (!csv) throw std::runtime_error(csv_path.string() + ": cannot write");
  csv << "time_s,station,tip_x_m,tip_y_m,tip_z_m,force_x_n,force_y_n,force_z_n,in_contact\n";

  std::vector<int> active_meshes;
  for (int m = 0; m < sim->num_meshes(); ++m)
    if (sim->mesh_active(m)) active_meshes.push_back(m);
  struct Frame {
    double time_s;
    int mesh;
    std::string file;
  };
  std::vector<Frame> frames;
  int frame_index = 0;

  Eigen::VectorXd u;
  int contact_rows = 0, unconverged = 0, rows_dropped_steps = 0;
  double max_force = 0.0;
  neurosim::replay::run(*sim, stations, [&](const neurosim::replay::StepView& v) {
    if (!v.stats->converged) ++unconverged;
    if (v.stats->contact_rows_dropped > 0) ++rows_dropped_steps;
    for (std::size_t p = 0; p < v.poses->size(); ++p) {
      const auto& c = (*v.contacts)[p];
      const auto& st = stations[static_cast<std::size_t>((*v.station_of_pose)[p])];
      const Vec3 f = c.in_contact ? c.force_n : Vec3::Zero();
      if (!f.allFinite()) {
        throw std::runtime_error(st.file + ": non-finite force at time " + g17(v.time_s) + " s");
      }
      if (c.in_contact) ++contact_rows;
      max_force = std::max(max_force, f.norm());
      const Vec3& x = (*v.poses)[p].tip_m;
      csv << g17(v.time_s) << ',' << st.id << ',' << g17(x.x()) << ',' << g17(x.y()) << ','
          << g17(x.z()) << ',' << g17(f.x()) << ',' << g17(f.y()) << ',' << g17(f.z()) << ','
          << (c.in_contact ? 1 : 0) << '\n';
    }
    if (v.index % static_cast<std::size_t>(opt.every) == 0 || v.index + 1 == v.count) {
      for (int m : active_meshes) {
        sim->displacements(m, u);
        std::vector<double> values(u.data(), u.data() + u.size());
        char name[64];
        std::snprintf(name, sizeof name, "_%06d.vtu", frame_index);
        const std::string file = sim->mesh_id(m) + name;
        neurosim::mesh::write_vtu((out / file).string(), sim->mesh(m),
                                  {neurosim::mesh::VtuField{"displacement_m", 3, values}});
        frames.push_back({v.time_s, m, file});
      }
      ++frame_index;
    }
  }, opt.max_rate_hz);
  csv.close();
  if (!csv) throw std::runtime_error(csv_path.string() + ": write failed");

  const fs::path pvd_path = out / "series.pvd";
  {
    std::ofstream pvd(pvd_path, std::ios::binary);
    pvd << "<?xml version=\"1.0\"?>\n"
        << "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
        << "  <Collection>\n";
    for (const auto& fr : frames) {
      pvd << "    <DataSet timestep=\"" << g17(fr.time_s) << "\" group=\"\" part=\"" << fr.mesh
          << "\" name=\"" << neurosim::mesh::xml_escape(sim->mesh_id(fr.mesh)) << "\" file=\""
          << neurosim::mesh::xml_escape(fr.file) << "\"/>\n";
    }
    pvd << "  </Collection>\n</VTKFile>\n";
    pvd.close();
    if (!pvd) throw std::runtime_error(pvd_path.string() + ": write failed");
  }
  std::cout << steps_left << " steps, " << contact_rows << " contact rows, largest |force| "
            << max_force << " N" << (unconverged ? ", " + std::to_string(unconverged) +
                                                       " steps whose contact LCP did not converge"
                                                 : std::string())
            << (rows_dropped_steps
                    ? ", " + std::to_string(rows_dropped_steps) +
                          " steps that left touching contact rows out (more than " +
                          std::to_string(sim_options.max_contact_nodes_per_tool) +
                          " per tool: --contact-max-rows)"
                    : std::string())
            << "; " << frame_index << " frames x " << active_meshes.size() << " mesh(es)\n"
            << "results in " << fs::absolute(out).string() << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  neurosim::cli::Parser cli("neurosim-replay", kDescription);
  cli.add_option("--scene", opt.scene_path, "scene file")->required();
  cli.add_option("--recording", opt.recordings, "recording file (one per station; repeat)")
      ->required()
      ->take_all();
  cli.add_option("--tier", opt.tier, "linear | nonlinear (default: the scene's)");
  cli.add_option("--element", opt.element,
                 "smoothed-tet | anp-tet | linear-tet: every mesh's element (default: the scene's "
                 "material.element)");
  cli.add_option("--out", opt.out_dir, "output folder DIR")->required();
  cli.add_option("--every", opt.every, "write a displacement frame every N steps (default 10)")
      ->check(neurosim::cli::range(1, 1000000000));
  cli.add_option("--max-rate", opt.max_rate_hz,
                 "step at most HZ times per second of recording (samples in between are "
                 "skipped; default 0: every sample time)")
      ->check(neurosim::cli::range(0.0, 1e9));
  cli.add_flag("--skip-rejected", opt.skip_rejected,
               "replay without the samples the live server's filter would reject (NaN, tip "
               "outside the scene's workspace, jumps faster than the tool, ...; counted on "
               "stderr); without it such a sample is an error (exit 1)");
  cli.add_option("--contact-max-rows", opt.max_rows,
                 "a tool's deepest contact rows kept, as neurosim-server's (default: the "
                 "library's, 32; a patch of cells much finer than the tip has more)")
      ->check(neurosim::cli::range(1, 100000));
  cli.add_option("--lcp-max-iterations", opt.lcp_max_iterations,
                 "the contact LCP's pivots, as neurosim-server's (default: the library's, 200)")
      ->check(neurosim::cli::range(1, 1000000));
  cli.add_option("--cache-dir", opt.cache_dir,
                 "disk cache of the hosts' factors and boundary operators, keyed by their "
                 "content, as neurosim-server's: a second replay of the same scene reads them "
                 "instead of factoring; the answers are the same bit for bit (default: none)");
  cli.check([&] {
    if (!opt.tier.empty() && !neurosim::fem::parse_tier(opt.tier)) {
      throw neurosim::cli::UsageError("--tier " + opt.tier +
                                      ": unknown tier, expected linear or nonlinear");
    }
    if (!opt.tier.empty() && !neurosim::fem::tier_served(*neurosim::fem::parse_tier(opt.tier))) {
      throw neurosim::cli::UsageError("--tier " + opt.tier + ": " +
                                      neurosim::fem::kCorotationalWithdrawn);
    }
    if (!opt.element.empty() && !neurosim::fem::parse_element(opt.element)) {
      throw neurosim::cli::UsageError("--element " + opt.element + ": unknown element, expected " +
                                      neurosim::fem::element_names());
    }
  });
  cli.footer(kFooter);
  if (auto rc = cli.parse(argc, argv)) return *rc;
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::cerr << "neurosim-replay: error: " << e.what() << "\n";
    return 1;
  }
}
