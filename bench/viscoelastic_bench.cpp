// viscoelastic_bench: what the viscoelastic history costs in the contact step.
//   viscoelastic_bench [--csv] [--seconds S] [--rounds N]
// The bundled brain elastic (scenes/brain_artery.scene) and viscoelastic
// (scenes/brain_viscoelastic.scene, Miller's relaxation), the same press at the demo's press
// point: 6 mm in over the first fifth of the run, held, 3 mm sideways and back, out; stepped
// back to back at the sample times of a 1 kHz station (not paced: the step's own cost). The two
// scenes alternate round by round so machine load falls on both alike; step p50/p99/max over all
// rounds, and the force at the end of the hold.
#include "common/cli.hpp"
#include "common/stats.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace ni = neurosim::interaction;

namespace {

struct Case {
  std::string name;
  std::unique_ptr<ni::Simulation> sim;
  double tip_radius_m{0.0};
  std::vector<double> step_us;
  double force_end_hold_n{0.0};
  int max_rows{0};
};

}  // namespace

int main(int argc, char** argv) {
  bool csv = false;
  double seconds = 5.0;
  int rounds = 3;
  neurosim::cli::Parser cli("viscoelastic_bench",
                            "Contact step cost with and without viscoelastic terms (bundled brain).");
  cli->add_flag("--csv", csv, "CSV only");
  cli->add_option("--seconds", seconds, "recorded time of one round, s")
      ->check(CLI::Range(0.5, 600.0))
      ->capture_default_str();
  cli->add_option("--rounds", rounds, "rounds per scene (alternating)")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  const std::string dir = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/";
  const Eigen::Vector3d origin(0.1605, 0.1125, 0.0787);
  const Eigen::Vector3d up = Eigen::Vector3d(0.963, 0.176, 0.202).normalized();
  const Eigen::Vector3d side = up.cross(Eigen::Vector3d::UnitZ()).normalized();
  std::vector<Case> cases;
  for (const char* name : {"brain_artery", "brain_viscoelastic"}) {
    const auto model = neurosim::scene::load_model(dir + name + ".scene");
    ni::SimulationOptions o;
    o.precompute_contact_columns = true;  // the step's cost, not first-touch column solves
    Case c;
    c.name = name;
    c.sim = ni::Simulation::build(model, o);
    c.tip_radius_m = model.tools.at(0).tip_radius_m;
    cases.push_back(std::move(c));
  }
  const int n = static_cast<int>(seconds * 1000.0);
  const double depth = 0.006;
  for (int round = 0; round < rounds; ++round) {
    for (Case& c : cases) {
      std::vector<ni::ToolPose> poses(1);
      std::vector<ni::ToolContact> contacts;
      ni::StepStats st;
      for (int k = 0; k < n; ++k) {
        const double s = static_cast<double>(k) / n;  // fraction of the round
        double d = depth;
        Eigen::Vector3d off = Eigen::Vector3d::Zero();
        if (s < 0.2) d = depth * s / 0.2;
        else if (s >= 0.6 && s < 0.8) off = 0.003 * (s < 0.7 ? (s - 0.6) : (0.8 - s)) / 0.1 * side;
        else if (s >= 0.8) d = depth * (1.0 - (s - 0.8) / 0.1);
        poses[0].tip_m = origin + off + (c.tip_radius_m - d) * up;
        poses[0].axis = up;
        const double t = round * seconds + k * 1e-3;
        c.sim->step_at(t, poses, contacts, st);
        c.step_us.push_back(st.solve_us);
        c.max_rows = std::max(c.max_rows, st.contact_rows);
        if (k == static_cast<int>(0.6 * n) - 1) c.force_end_hold_n = contacts[0].force_n.norm();
      }
    }
  }
  if (!csv)
    std::printf("# viscoelastic_bench: %d rounds of %.1f s at 1 kHz sample times per scene, "
                "alternating; columns precomputed\n", rounds, seconds);
  std::printf("scene,steps,step_p50_us,step_p99_us,step_max_us,max_rows,force_end_hold_n\n");
  for (Case& c : cases) {
    const auto p = neurosim::common::percentiles(c.step_us);
    std::printf("%s,%zu,%.1f,%.1f,%.1f,%d,%.4f\n", c.name.c_str(), c.step_us.size(), p.p50, p.p99,
                p.max, c.max_rows, c.force_end_hold_n);
  }
  return 0;
}
