// viscoelastic_bench: what the viscoelastic history costs in the contact step.
//   viscoelastic_bench [--csv] [--seconds S] [--rounds N]
//   viscoelastic_bench --hold-csv FILE [--hold S] [--rest-rows]
// The bundled viscoelastic brain (scenes/brain_viscoelastic.scene) without its kernel (the elastic
// reference: brain_artery.scene's brain has since moved to another material) and with it
// (scenes/brain_viscoelastic.scene, Miller's relaxation), the same press at the demo's press
// point: 6 mm in over the first fifth of the run, held, 3 mm sideways and back, out; stepped
// back to back at the sample times of a 1 kHz station (not paced: the step's own cost). The two
// scenes alternate round by round so machine load falls on both alike; step p50/p99/max over all
// rounds, and the force at the end of the hold.
// --hold-csv: instead, the relaxation of a held press (the demo's press point, 4 mm in over
// 1.5 s as script:hold, held S s, default 10): per 10 ms the tool's force on the elastic and on
// the viscoelastic brain, and the hereditary integral int g(t - s) dF_el(s) of the elastic
// forces along the same path (what the stated model predicts, g the brain's kernel), to FILE;
// a summary (start of the hold, 1 s, end) on stdout. Deterministic (sample times, no clock).
//   viscoelastic_bench --nonlinear-hold [--hold S] [--sample-ms M]
// The same held press in the NONLINEAR tier (quasi-linear viscoelasticity in the tier's
// equilibrium), brain_viscoelastic.scene with and without its kernel alternating step by step, synchronous updates
// (one equilibrium update per step, at M ms sample times, default 10: a 100 Hz worker): the force
// during the hold and the update's wall time (p50 / p99 / max) with and without the history.
#include "common/cli.hpp"
#include "common/stats.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
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

// The scene without its relaxation terms: the elastic reference of the same material.
neurosim::scene::Model without_kernel(neurosim::scene::Model model) {
  for (auto& m : model.meshes) {
    m.material.viscoelastic = {};
    for (auto& mm : m.materials.materials) mm.viscoelastic = {};
  }
  return model;
}

// The held press of --hold-csv: forces on both scenes and the hereditary integral of the elastic
// ones; returns the exit status.
int hold_relaxation(const std::string& dir, const std::string& file, double hold_s,
                    bool rest_rows) {
  const Eigen::Vector3d origin(0.1605, 0.1125, 0.0787);
  const Eigen::Vector3d up = Eigen::Vector3d(0.963, 0.176, 0.202).normalized();
  const auto visco_model = neurosim::scene::load_model(dir + "brain_viscoelastic.scene");
  const auto elastic_model = without_kernel(visco_model);
  const auto& kernel = visco_model.meshes.at(0).material.viscoelastic;
  ni::SimulationOptions o;
  if (rest_rows) o.contact_geometry_iterations = 1;  // rows on the rest surface, one LCP per step
  auto elastic = ni::Simulation::build(elastic_model, o);
  auto visco = ni::Simulation::build(visco_model, o);
  const double tip = visco_model.tools.at(0).tip_radius_m;
  const double depth = 0.004, press_s = 1.5;
  const int n = static_cast<int>(std::lround((press_s + hold_s) * 1000.0));
  std::vector<Eigen::Vector3d> f_el(n + 1);
  std::vector<double> f_ve(n + 1);
  std::vector<ni::ToolPose> poses(1);
  std::vector<ni::ToolContact> ce, cv;
  ni::StepStats st;
  for (int k = 0; k <= n; ++k) {
    const double t = k * 1e-3;
    // script:hold's descent (smooth in 1.5 s, from the surface point here), then held.
    const double u = std::min(1.0, t / press_s);
    const double d = depth * (0.5 - 0.5 * std::cos(M_PI * u));
    poses[0].tip_m = origin + (tip - d) * up;
    poses[0].axis = up;
    elastic->step_at(t, poses, ce, st);
    visco->step_at(t, poses, cv, st);
    f_el[k] = ce[0].force_n;
    f_ve[k] = cv[0].force_n.norm();
  }
  // |int g(T - s) dF_el(s)|, F_el linear between the samples (exact integral of the kernel).
  auto hereditary = [&](int kt) {
    const double big_t = kt * 1e-3;
    Eigen::Vector3d f = Eigen::Vector3d::Zero();
    for (int k = 1; k <= kt; ++k) {
      const double a = (k - 1) * 1e-3, b = k * 1e-3;
      double w = kernel.relaxed_fraction() * (b - a);
      for (const auto& p : kernel.terms)
        w += p.g * p.tau_s * (std::exp(-(big_t - b) / p.tau_s) - std::exp(-(big_t - a) / p.tau_s));
      f += (f_el[k] - f_el[k - 1]) / 1e-3 * w;
    }
    return f.norm();
  };
  std::ofstream out(file);
  if (!out) {
    std::fprintf(stderr, "viscoelastic_bench: %s: cannot write\n", file.c_str());
    return 1;
  }
  out << "t_s,depth_m,f_elastic_n,f_viscoelastic_n,f_hereditary_n\n";
  double worst = 0.0, f_peak = 0.0;
  for (int k = 0; k <= n; k += 10) {
    const double t = k * 1e-3;
    const double h = hereditary(k);
    const double u = std::min(1.0, t / press_s);
    out << t << ',' << depth * (0.5 - 0.5 * std::cos(M_PI * u)) << ',' << f_el[k].norm() << ','
        << f_ve[k] << ',' << h << '\n';
    f_peak = std::max(f_peak, f_ve[k]);
    worst = std::max(worst, std::abs(f_ve[k] - h));
  }
  const int k0 = static_cast<int>(std::lround(press_s * 1000.0));
  std::printf("# held press on brain_viscoelastic (4 mm in over %.1f s, held %.1f s): |F| in N\n",
              press_s, hold_s);
  std::printf("t_into_hold_s,f_elastic_n,f_viscoelastic_n,f_hereditary_n,f_over_f_hold_start\n");
  for (double s : {0.0, 0.5, 1.0, 2.0, 5.0, hold_s}) {
    if (s > hold_s) continue;
    const int k = k0 + static_cast<int>(std::lround(s * 1000.0));
    std::printf("%.1f,%.4f,%.4f,%.4f,%.3f\n", s, f_el[k].norm(), f_ve[k], hereditary(k),
                f_ve[k] / f_ve[k0]);
  }
  std::printf("# largest |F_visco - int g dF_el| over the run (10 ms samples): %.2e N (%.2e of the peak)\n",
              worst, worst / f_peak);
  return 0;
}

// --nonlinear-hold: the held press in the NONLINEAR tier, elastic and viscoelastic brain.
int nonlinear_hold(const std::string& dir, double hold_s, double sample_ms) {
  const Eigen::Vector3d origin(0.1605, 0.1125, 0.0787);
  const Eigen::Vector3d up = Eigen::Vector3d(0.963, 0.176, 0.202).normalized();
  ni::SimulationOptions o;
  o.tier_worker_thread = false;  // one update inside each step: deterministic, timed
  std::vector<std::unique_ptr<ni::Simulation>> sims;
  std::vector<std::vector<double>> update_us(2), force(2);
  // The elastic reference is the same scene without its kernel (brain_artery.scene's brain has
  // another material since it moved to nu = 0.49 on smoothed-tet).
  for (bool relaxing : {false, true}) {
    auto model = neurosim::scene::load_model(dir + "brain_viscoelastic.scene");
    model.effects.tier = neurosim::scene::Tier::kNonlinear;
    sims.push_back(ni::Simulation::build(relaxing ? model : without_kernel(model), o));
  }
  const double tip = neurosim::scene::load_model(dir + "brain_viscoelastic.scene").tools.at(0).tip_radius_m;
  const double depth = 0.004, press_s = 1.5, dt = 1e-3 * sample_ms;
  const int n = static_cast<int>(std::lround((press_s + hold_s) / dt));
  std::vector<ni::ToolPose> poses(1);
  std::vector<ni::ToolContact> c;
  ni::StepStats st;
  for (int k = 0; k <= n; ++k) {
    const double t = k * dt;
    const double u = std::min(1.0, t / press_s);
    const double d = depth * (0.5 - 0.5 * std::cos(M_PI * u));
    poses[0].tip_m = origin + (tip - d) * up;
    poses[0].axis = up;
    for (int i = 0; i < 2; ++i) {
      sims[i]->step_at(t, poses, c, st);
      if (st.tier_updated) update_us[i].push_back(st.tier_update_us);
      force[i].push_back(c[0].force_n.norm());
    }
  }
  const int k0 = static_cast<int>(std::lround(press_s / dt));
  std::printf("# held press in the NONLINEAR tier (4 mm in over %.1f s, held %.1f s; one update per "
              "%.0f ms sample): |F| in N\n", press_s, hold_s, sample_ms);
  std::printf("t_into_hold_s,f_elastic_n,f_viscoelastic_n,f_over_f_hold_start\n");
  for (double s : {0.0, 0.5, 1.0, 2.0, 5.0, hold_s}) {
    if (s > hold_s) continue;
    const int k = k0 + static_cast<int>(std::lround(s / dt));
    std::printf("%.1f,%.4f,%.4f,%.3f\n", s, force[0][k], force[1][k], force[1][k] / force[1][k0]);
  }
  std::printf("scene,updates,update_p50_us,update_p99_us,update_max_us\n");
  const char* names[] = {"brain_viscoelastic without its kernel (elastic)", "brain_viscoelastic (QLV)"};
  for (int i = 0; i < 2; ++i) {
    const auto p = neurosim::common::percentiles(update_us[i]);
    std::printf("%s,%zu,%.0f,%.0f,%.0f\n", names[i], update_us[i].size(), p.p50, p.p99, p.max);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  bool csv = false;
  double seconds = 5.0;
  int rounds = 3;
  neurosim::cli::Parser cli("viscoelastic_bench",
                            "Contact step cost with and without viscoelastic terms (bundled brain).");
  cli.add_flag("--csv", csv, "CSV only");
  cli.add_option("--seconds", seconds, "recorded time of one round, s")
      ->check(neurosim::cli::range(0.5, 600.0))
      ->capture_default_str();
  cli.add_option("--rounds", rounds, "rounds per scene (alternating)")
      ->check(neurosim::cli::range(1, 100))
      ->capture_default_str();
  std::string hold_csv;
  double hold_s = 10.0;
  cli.add_option("--hold-csv", hold_csv, "write the held press's relaxation to this CSV instead");
  bool rest_rows = false;
  cli.add_flag("--rest-rows", rest_rows,
               "with --hold-csv: rows on the rest surface (one LCP per step, no row search)");
  cli.add_option("--hold", hold_s, "with --hold-csv: seconds held")
      ->check(neurosim::cli::range(0.0, 600.0))
      ->capture_default_str();
  bool nonlinear = false;
  cli.add_flag("--nonlinear-hold", nonlinear,
               "the held press in the NONLINEAR tier (quasi-linear viscoelasticity), elastic and "
               "viscoelastic: forces and update times");
  double sample_ms = 10.0;
  cli.add_option("--sample-ms", sample_ms,
                 "with --nonlinear-hold: ms between samples (one update each)")
      ->check(neurosim::cli::range(1.0, 100.0))
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  const std::string dir = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/";
  if (nonlinear) return nonlinear_hold(dir, hold_s, sample_ms);
  if (!hold_csv.empty()) return hold_relaxation(dir, hold_csv, hold_s, rest_rows);
  const Eigen::Vector3d origin(0.1605, 0.1125, 0.0787);
  const Eigen::Vector3d up = Eigen::Vector3d(0.963, 0.176, 0.202).normalized();
  const Eigen::Vector3d side = up.cross(Eigen::Vector3d::UnitZ()).normalized();
  std::vector<Case> cases;
  for (const char* name : {"brain_viscoelastic without its kernel", "brain_viscoelastic"}) {
    const auto scene = neurosim::scene::load_model(dir + "brain_viscoelastic.scene");
    const auto model = std::string(name) == "brain_viscoelastic" ? scene : without_kernel(scene);
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
