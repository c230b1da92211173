// neurosim-replay: offline replay of recorded tool trajectories (idl/recording.proto) through the
// server's simulation, deterministically (no threads, no clock): one step per distinct sample
// time, all stations together. Writes the contact forces per step and station (forces.csv) and
// the displacement fields as a ParaView time series (series.pvd + one .vtu per frame and mesh).
#include "common/cli.hpp"
#include "idl/wire/recording_io.hpp"
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
using neurosim::interaction::ToolPose;
using neurosim::interaction::Vec3;

namespace {

const char* kDescription =
    "Offline replay of recorded tool trajectories (one recording file per station) through the\n"
    "server's simulation, deterministically: the elasticity tier's equilibrium is updated inside\n"
    "each step (no worker thread, no clock), so two runs give byte-identical output.\n"
    "The samples of all recordings are merged by time; at each distinct sample time the\n"
    "simulation steps once with every station's newest sample so far. A station whose recording\n"
    "has not started yet is left out of the step (as the live server leaves out a station that\n"
    "has sent no pose); a station whose recording has ended keeps its last pose.";
const char* kFooter =
    "Writes DIR/forces.csv (time_s,station,tip_x_m,tip_y_m,tip_z_m,force_x_n,force_y_n,\n"
    "force_z_n,in_contact; one row per step and station taking part, numbers as %.17g) and\n"
    "DIR/series.pvd with DIR/<mesh>_<frame>.vtu (point data displacement_m) for every active\n"
    "mesh at steps 0, N, 2N, ... and the last step (--every N).";

struct Options {
  std::string scene_path, out_dir, tier;  // tier: empty = the scene's
  std::vector<std::string> recordings;
  int every{10};
};

struct Station {
  std::string file;
  std::string id;
  int tool{0};
  std::vector<neurosim::recording::Sample> samples;
  std::size_t next{0};  // first sample not yet taken
  bool started{false};
};

// The pose the live server builds from a ToolState (server/service/server.cpp): the quaternion
// normalized, the shaft axis the tool frame's +z rotated into the scene frame.
ToolPose pose_of(const neurosim::recording::Sample& s, int tool) {
  ToolPose tp;
  tp.tip_m = Vec3(s.position_m().x(), s.position_m().y(), s.position_m().z());
  const auto& o = s.orientation();
  const double qn = std::sqrt(o.w() * o.w() + o.x() * o.x() + o.y() * o.y() + o.z() * o.z());
  const double w = o.w() / qn, x = o.x() / qn, y = o.y() / qn, z = o.z() / qn;
  tp.axis = Vec3(2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y));
  tp.tool = tool;
  return tp;
}

std::string g17(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

int run(const Options& opt) {
  neurosim::scene::Model model = neurosim::scene::load_model(opt.scene_path);
  if (!opt.tier.empty()) model.effects.tier = *neurosim::fem::parse_tier(opt.tier);
  if (model.tools.empty()) throw std::runtime_error(opt.scene_path + ": the scene has no tools");
  if (!model.effects.tool_contact) {
    std::cerr << "neurosim-replay: note: " << opt.scene_path
              << ": effects.tool_contact is off: no station will touch anything\n";
  }

  // Recordings: one station each.
  std::vector<Station> stations;
  for (const auto& file : opt.recordings) {
    if (!fs::exists(file)) throw std::runtime_error(file + ": no such recording file");
    neurosim::wire::Recording rec = neurosim::wire::read_recording(file);
    Station st;
    st.file = file;
    st.id = rec.header.station_id().empty() ? fs::path(file).stem().string()
                                            : rec.header.station_id();
    const std::string& tool_id = rec.header.tool_id();
    int tool = -1;
    for (std::size_t t = 0; t < model.tools.size(); ++t) {
      if (model.tools[t].id == tool_id) tool = static_cast<int>(t);
    }
    if (tool < 0) {
      std::string known;
      for (const auto& t : model.tools) known += (known.empty() ? "" : ", ") + t.id;
      throw std::runtime_error(file + ": tool '" + tool_id + "' is not a tool of scene " +
                               opt.scene_path + " (" + known + ")");
    }
    st.tool = tool;
    if (st.id.find_first_of(",\"\r\n") != std::string::npos) {
      throw std::runtime_error(file + ": station id '" + st.id +
                               "' has a comma, quote or line break (not written to forces.csv)");
    }
    for (const auto& other : stations) {
      if (other.id == st.id) {
        throw std::runtime_error(file + ": station '" + st.id + "' is also recorded in " +
                                 other.file);
      }
    }
    st.samples = std::move(rec.samples);
    if (st.samples.empty()) {
      std::cerr << "neurosim-replay: note: " << file << ": no samples (station '" << st.id
                << "' never takes part)\n";
    }
    stations.push_back(std::move(st));
  }

  // Every distinct sample time, in order.
  std::vector<double> times;
  for (const auto& st : stations)
    for (const auto& s : st.samples) times.push_back(s.time_s());
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  if (times.empty()) throw std::runtime_error("the recordings hold no samples");

  neurosim::interaction::SimulationOptions sim_options;
  sim_options.tier_worker_thread = false;
  std::unique_ptr<neurosim::interaction::Simulation> sim =
      neurosim::interaction::Simulation::build(model, sim_options);
  std::cout << "scene " << model.name << " (" << opt.scene_path << "), tier "
            << neurosim::fem::tier_name(model.effects.tier)
            << (opt.tier.empty() ? " (scene)" : " (--tier)") << "; " << stations.size()
            << " station(s), " << times.size() << " steps\n";

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

  std::vector<ToolPose> poses;
  std::vector<int> station_of_pose;
  std::vector<neurosim::interaction::ToolContact> contacts;
  neurosim::interaction::StepStats stats;
  Eigen::VectorXd u;
  int contact_rows = 0, unconverged = 0;
  double max_force = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double t = times[k];
    poses.clear();
    station_of_pose.clear();
    for (std::size_t i = 0; i < stations.size(); ++i) {
      Station& st = stations[i];
      while (st.next < st.samples.size() && st.samples[st.next].time_s() <= t) ++st.next;
      if (st.next == 0) continue;  // not started yet: not in this step
      poses.push_back(pose_of(st.samples[st.next - 1], st.tool));
      station_of_pose.push_back(static_cast<int>(i));
    }
    sim->step(poses, contacts, stats);
    if (!stats.converged) ++unconverged;
    for (std::size_t p = 0; p < poses.size(); ++p) {
      const auto& c = contacts[p];
      const Vec3 f = c.in_contact ? c.force_n : Vec3::Zero();
      if (!f.allFinite()) {
        throw std::runtime_error(stations[static_cast<std::size_t>(station_of_pose[p])].file +
                                 ": non-finite force at time " + g17(t) + " s");
      }
      if (c.in_contact) ++contact_rows;
      max_force = std::max(max_force, f.norm());
      const Vec3& x = poses[p].tip_m;
      csv << g17(t) << ',' << stations[static_cast<std::size_t>(station_of_pose[p])].id << ','
          << g17(x.x()) << ',' << g17(x.y()) << ',' << g17(x.z()) << ',' << g17(f.x()) << ','
          << g17(f.y()) << ',' << g17(f.z()) << ',' << (c.in_contact ? 1 : 0) << '\n';
    }
    if (k % static_cast<std::size_t>(opt.every) == 0 || k + 1 == times.size()) {
      for (int m : active_meshes) {
        sim->displacements(m, u);
        std::vector<double> values(u.data(), u.data() + u.size());
        char name[64];
        std::snprintf(name, sizeof name, "_%06d.vtu", frame_index);
        const std::string file = sim->mesh_id(m) + name;
        neurosim::mesh::write_vtu((out / file).string(), sim->mesh(m),
                                  {neurosim::mesh::VtuField{"displacement_m", 3, values}});
        frames.push_back({t, m, file});
      }
      ++frame_index;
    }
  }
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
  std::cout << times.size() << " steps, " << contact_rows << " contact rows, largest |force| "
            << max_force << " N" << (unconverged ? ", " + std::to_string(unconverged) +
                                                       " steps whose contact LCP did not converge"
                                                 : std::string())
            << "; " << frame_index << " frames x " << active_meshes.size() << " mesh(es)\n"
            << "results in " << fs::absolute(out).string() << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  neurosim::cli::Parser cli("neurosim-replay", kDescription);
  cli->add_option("--scene", opt.scene_path, "scene file")->required();
  cli->add_option("--recording", opt.recordings, "recording file (one per station; repeat)")
      ->required()
      ->take_all();
  cli->add_option("--tier", opt.tier, "linear | corotational | nonlinear (default: the scene's)");
  cli->add_option("--out", opt.out_dir, "output folder DIR")->required();
  cli->add_option("--every", opt.every, "write a displacement frame every N steps (default 10)")
      ->check(CLI::Range(1, 1000000000));
  cli.check([&] {
    if (!opt.tier.empty() && !neurosim::fem::parse_tier(opt.tier)) {
      throw neurosim::cli::UsageError("--tier " + opt.tier +
                                      ": unknown tier, expected linear, corotational or nonlinear");
    }
  });
  cli->footer(kFooter);
  if (auto rc = cli.parse(argc, argv)) return *rc;
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::cerr << "neurosim-replay: error: " << e.what() << "\n";
    return 1;
  }
}
