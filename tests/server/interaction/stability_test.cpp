// Stability suite (ctest -L stability): hard cases driven through the Simulation for thousands
// of steps on every elasticity tier (synchronous tier updates: deterministic). Every step: the
// forces and contact stiffnesses are finite and below a stated bound, a step that did not
// converge says so and returns the last good answer, a failed tier update throws a message
// naming it and keeps the last good equilibrium. Every few steps: the displacement fields are
// finite and the strain energy is below a stated bound. Each case prints (and records as test
// properties) its measured worst values; bench/RESULTS.md ("Stability suite") holds the table.
//
// Scenes are a block of brain tissue (a structured mesh written to a Medit file and read back
// through scene::compile, so the file path, file_unit_m and the size check run as in a real
// scene), optionally with a stiffer artery tied inside it.
#include "server/interaction/simulation.hpp"

#include "server/fem/elastic_forces.hpp"
#include "server/fem/fem_test_meshes.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/mesh/io.hpp"
#include "server/mesh/quality.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

namespace neurosim::interaction {
namespace {

// 2 s of tool motion at the server's 1 kHz per case and tier.
constexpr int kSteps = 2000;

// ---------------------------------------------------------------------------------------------
// Scenes

// A block of brain [0, L]^3 (E = 3 kPa as brain_artery.scene's brain; by default nu 0.45 on
// linear-tet, the scene's material before it moved to nu 0.49 on smoothed-tet: the Stability
// cases also run at 0.49 and 0.499 on smoothed-tet, StabilityPoisson both elements) fixed at z = 0,
// structured (cells^3 hexahedra, 6 tetrahedra each), and optionally an artery tied inside it
// (artery_mesh: a rod along y 16 mm below the pressed face x = L). The tool (a 10 mm tip by
// default) pressed at (y, z) = (30, 30) mm lands on the midpoint of a cell's diagonal edge, 8.5
// mm from the cell's corners (contact against the surface triangles: an edge row first).
struct Block {
  double edge_m{0.06};
  int cells{5};  // 12 mm elements
  double e_pa{3000.0};
  double nu{0.45};
  std::string element;  // material.element; empty: the scene default (linear-tet)
  double tip_radius_m{0.010};
  double artery_ratio{0.0};  // E_artery / E_brain; 0: no artery (artery_mesh)
  // Changes to the host mesh before it is written (slivers).
  std::function<void(std::vector<mesh::Vec3>&, const std::vector<mesh::Tet>&)> edit;
  // The file is written in units of this (1e-3: millimetres) ...
  double file_unit_m{1.0};
  // ... and the scene says so (false: the mm mistake).
  bool declare_unit{true};

  double node_m(int i) const { return i * edge_m / cells; }  // grid coordinate i, unit m
};

mesh::TetMesh block_mesh(const Block& b) {
  fem::testing::BoxSpec spec;
  spec.nx = spec.ny = spec.nz = b.cells;
  spec.hi = Eigen::Vector3d::Constant(b.edge_m);
  mesh::TetMesh m = fem::testing::box_mesh(spec);
  if (!b.edit) return m;
  std::vector<mesh::Vec3> x = m.vertices();
  b.edit(x, m.tets());
  return mesh::TetMesh::build(std::move(x), m.tets(), {});
}

// The artery: a rod of square section (10 x 10 mm, 42 mm along y, 2 x 2 x 7 cells) 16 mm below
// the pressed face, off the host's grid planes (no coincident faces for the inclusion decision).
mesh::TetMesh artery_mesh(const Block& b) {
  fem::testing::BoxSpec spec{2, 7, 2};
  const double l = b.edge_m;
  spec.lo = Eigen::Vector3d(0.567 * l, 0.15 * l, 0.417 * l);
  spec.hi = spec.lo + Eigen::Vector3d(0.167 * l, 0.7 * l, 0.167 * l);
  return fem::testing::box_mesh(spec);
}

struct BuiltScene {
  scene::Model model;
  std::string source;  // the scene file it names (removed after compiling)
};

BuiltScene build_scene(const Block& b, const std::string& tag) {
  const auto dir = neurosim::testing::temp_dir("stability_" + tag);
  BuiltScene out;
  const auto file = dir / "brain.mesh";
  mesh::write_medit(file.string(), mesh::to_mesh_data(block_mesh(b)), b.file_unit_m);
  std::ostringstream s;
  s.precision(17);
  s << "name: \"stability_" << tag << "\"\n"
    << "meshes { id: \"brain\" file: \"" << file.string() << "\"\n";
  if (b.declare_unit && b.file_unit_m != 1.0) s << "  file_unit_m: " << b.file_unit_m << "\n";
  s << "  material { name: \"brain\" youngs_modulus_pa: " << b.e_pa << " poisson_ratio: " << b.nu;
  if (!b.element.empty()) s << " element: \"" << b.element << "\"";
  s << " }\n"
    << "  fixed { half_space { point_m { z: 1e-9 } normal { z: 1 } } }\n"
    << "  priority: 0 }\n";
  if (b.artery_ratio > 0.0) {
    const auto artery = dir / "artery.mesh";
    mesh::write_medit(artery.string(), mesh::to_mesh_data(artery_mesh(b)), b.file_unit_m);
    s << "meshes { id: \"artery\" file: \"" << artery.string() << "\"\n";
    if (b.declare_unit && b.file_unit_m != 1.0) s << "  file_unit_m: " << b.file_unit_m << "\n";
    s << "  material { name: \"artery\" youngs_modulus_pa: " << b.artery_ratio * b.e_pa
      << " poisson_ratio: 0.45 } priority: 1 }\n"
      << "couplings { host: \"brain\" embedded: \"artery\" kind: TIE method: EXACT }\n";
  }
  s << "tools { id: \"probe\" tip_radius_m: " << b.tip_radius_m
    << " shaft_radius_m: 0.0015 shaft_length_m: 0.15 max_speed_m_per_s: 2 }\n"
    << "effects { tier: LINEAR coupling: " << (b.artery_ratio > 0.0 ? "true" : "false")
    << " tool_contact: true deformation_output: true }\n";
  out.source = (dir / "stability.scene").string();
  out.model = scene::compile(scene::parse_scene(s.str(), out.source), out.source);
  std::filesystem::remove_all(dir);  // the model holds everything it read
  return out;
}

// ---------------------------------------------------------------------------------------------
// Tool paths

using Path = std::function<std::vector<ToolPose>(int step)>;

// Tip on the face x = L at (y, z), pushed depth_m along -x (negative: clear of the surface).
ToolPose press(const Block& b, double depth_m, double y_m, double z_m) {
  ToolPose p;
  p.tip_m = Vec3(b.edge_m + b.tip_radius_m - depth_m, y_m, z_m);
  p.axis = Vec3::UnitX();
  return p;
}

// Two presses to depth_m (raised cosine, 1 s each) while stroking +-10 mm along y.
Path press_cycles(const Block& b, double depth_m, double y_m, double z_m) {
  return [=](int k) {
    const double t = k / 1000.0;  // s
    const double d = depth_m * 0.5 * (1.0 - std::cos(2.0 * M_PI * t));
    return std::vector<ToolPose>{press(b, d, y_m + 0.01 * std::sin(M_PI * t), z_m)};
  };
}

// ---------------------------------------------------------------------------------------------
// Bounds

// The largest force and strain energy a scene can produce, whatever the tool does.
//  - A contact row is at most d_max deep: a tool part deeper than max_penetration below a
//    node's patch does not push it (SimulationOptions::max_penetration_m, default 0.45 x the
//    host's smallest extent), and the tip adds its radius.
//  - The stiffest way tissue resists a rigid push is a laterally confined column (uniaxial
//    strain, P-wave modulus M = E (1 - nu) / ((1 + nu) (1 - 2 nu))) of the host's largest face
//    A over its smallest extent L: k = M A / L. A locked element is at most that stiff (locking
//    is the volumetric constraint of confinement); a rigid tied inclusion shortens the column,
//    covered by a factor 2 (the artery spans less than half of it).
//  - So |F| <= 2 M A d_max / L per tool, and the strain energy, at most the work of that force
//    over the deepest push, U <= tools x |F|max x d_max.
//  - The contact stiffness K = dF/dx is at most that column's, k: ||K||_F <= sqrt(3) k.
struct Bounds {
  double depth_m{0.0};
  double stiffness_n_per_m{0.0};
  double force_n{0.0};
  double energy_j{0.0};
};

Bounds bounds_of(const scene::Model& model, const SimulationOptions& o, int tools) {
  const auto& host = model.meshes[0];
  Vec3 lo, hi;
  host.mesh.bounds(lo, hi);
  Vec3 ext = hi - lo;
  std::sort(ext.data(), ext.data() + 3);
  const double e = host.material.youngs_modulus_pa, nu = host.material.poisson_ratio;
  const double m = e * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu));
  double tip = 0.0;
  for (const auto& t : model.tools) tip = std::max(tip, t.tip_radius_m);
  Bounds b;
  b.depth_m = (o.max_penetration_m > 0.0 ? o.max_penetration_m : 0.45 * ext[0]) + tip;
  b.stiffness_n_per_m = std::sqrt(3.0) * 2.0 * m * (ext[1] * ext[2]) / ext[0];
  b.force_n = 2.0 * m * (ext[1] * ext[2]) * b.depth_m / ext[0];
  b.energy_j = tools * b.force_n * b.depth_m;
  return b;
}

// ---------------------------------------------------------------------------------------------
// The driver

// What a run measured (worst over its steps).
struct Worst {
  int steps{0};
  double force_n{0.0};             // max |F| over tools and steps, unit N
  double stiffness_n_per_m{0.0};   // max ||K||_F, unit N/m
  double energy_j{0.0};            // max strain energy of all meshes, unit J
  double tie_residual_m{0.0};      // max tie mismatch, unit m
  double max_displacement_m{0.0};  // max |u| over all meshes
  double clapeyron_rel{0.0};       // LINEAR: max |U - f.u/2| / U
  double max_strain{0.0};          // max principal Green strain of an element
  int inverted{0};                 // max elements with det F <= 0 in one field (counted here)
  int inverted_reported{0};        // max StepStats::inverted_elements
  int barrier_reported{0};         // max StepStats::barrier_elements
  int lcp_iterations{0};
  int max_rows{0};
  int unconverged{0};    // steps whose LCP did not converge (flagged, last good answer)
  int tier_failures{0};  // tier updates that threw (synchronous worker)
  std::string last_error;
  double mean_step_us{0.0};
  std::vector<ToolContact> last;  // the last step's contacts
  Vec3 final_force_n{Vec3::Zero()};
  double final_displacement_m{0.0};  // max |u| of the last step's fields
};

struct Scenario {
  std::string name;
  const scene::Model* model{nullptr};
  scene::Tier tier{scene::Tier::kLinear};
  Path path;
  int steps{kSteps};
  int tools{1};
  int field_every{10};  // LINEAR fields are sparse solves: every few steps
  // Strain energy and inverted elements (element loops; corotational: an eigensolve per element)
  // every this many steps; 0: 10 in LINEAR, 50 in the tiers.
  int energy_every{0};
  SimulationOptions options{};
  // Called after every step with its contacts (optional).
  std::function<void(int step, const std::vector<ToolContact>&)> observe;
};

// The first tool's force over the steps [from, to]: its largest fall below the largest force felt
// so far, relative to it (0: the force never falls while the tool goes deeper).
struct ForceFall {
  int from{0};
  int to{kSteps};
  double peak_n{0.0};
  double worst{0.0};
  int worst_step{-1};
  void observe(int k, const std::vector<ToolContact>& c) {
    if (k < from || k > to) return;
    const double f = c[0].force_n.norm();
    peak_n = std::max(peak_n, f);
    if (peak_n > 0.0 && (peak_n - f) / peak_n > worst) {
      worst = (peak_n - f) / peak_n;
      worst_step = k;
    }
  }
};

// Steps `run.path` and checks every step; the worst values into `w`, and one line printed.
// Fatal failures return early (callers check HasFatalFailure()).
void drive(const Scenario& run, Worst& w, std::unique_ptr<Simulation>* keep = nullptr) {
  scene::Model model = *run.model;
  model.effects.tier = run.tier;
  SimulationOptions o = run.options;
  o.tier_worker_thread = false;
  const Bounds bound = bounds_of(model, o, run.tools);
  auto sim = Simulation::build(model, o);
  EXPECT_EQ(sim->tier(), run.tier);
  const bool tiered = run.tier != scene::Tier::kLinear;
  const int energy_every = run.energy_every > 0 ? run.energy_every : (tiered ? 50 : 10);
  const int nm = sim->num_meshes();
  // The strain energy of each active mesh in the tier that runs (the carved host as simulated).
  std::vector<std::unique_ptr<fem::ElasticForces>> elastic(nm);
  for (int m = 0; m < nm; ++m) {
    if (sim->mesh_active(m))
      elastic[m] = std::make_unique<fem::ElasticForces>(
          sim->mesh(m), fem::MaterialMap::uniform(model.meshes[m].material), run.tier);
  }
  w = Worst{};
  std::vector<ToolContact> contacts, good;
  std::vector<Eigen::VectorXd> u(nm), u_before(nm);
  StepStats st;
  double total_us = 0.0;
  for (int k = 0; k < run.steps; ++k) {
    const std::vector<ToolPose> poses = run.path(k);
    bool failed = false;
    try {
      sim->step(poses, contacts, st);
    } catch (const std::runtime_error& e) {
      // Only a tier's equilibrium update may fail; it names itself and keeps the last good
      // equilibrium (checked below).
      failed = true;
      ++w.tier_failures;
      w.last_error = e.what();
      EXPECT_TRUE(tiered) << run.name << " step " << k << ": " << e.what();
      EXPECT_NE(w.last_error.find("TierEquilibrium"), std::string::npos) << e.what();
    }
    total_us += st.solve_us;
    ++w.steps;
    EXPECT_EQ(contacts.size(), poses.size());
    if (!st.converged) {
      // Said so, and the last good answer returned.
      ++w.unconverged;
      for (std::size_t t = 0; t < contacts.size(); ++t) {
        EXPECT_FALSE(contacts[t].converged) << run.name << " step " << k;
        if (t < good.size()) {
          EXPECT_EQ(contacts[t].force_n, good[t].force_n) << run.name;
        }
      }
    } else {
      good = contacts;
    }
    if (run.observe) run.observe(k, contacts);
    w.max_rows = std::max(w.max_rows, st.contact_rows);
    w.inverted_reported = std::max(w.inverted_reported, st.inverted_elements);
    w.barrier_reported = std::max(w.barrier_reported, st.barrier_elements);
    if (!tiered) {
      EXPECT_EQ(st.inverted_elements, 0);
    }
    for (const ToolContact& c : contacts) {
      ASSERT_TRUE(c.force_n.allFinite()) << run.name << " step " << k;
      ASSERT_TRUE(c.stiffness_n_per_m.allFinite()) << run.name << " step " << k;
      ASSERT_TRUE(c.normal.allFinite()) << run.name << " step " << k;
      EXPECT_EQ(c.converged, st.converged) << run.name << " step " << k;
      // Pushes only: the force on the tool points out of the tissue, along its normal.
      if (c.in_contact) {
        EXPECT_GE(c.force_n.dot(c.normal), 0.0) << run.name << " step " << k;
      }
      w.force_n = std::max(w.force_n, c.force_n.norm());
      w.stiffness_n_per_m = std::max(w.stiffness_n_per_m, c.stiffness_n_per_m.norm());
      w.lcp_iterations = std::max(w.lcp_iterations, c.iterations);
    }
    ASSERT_LE(w.force_n, bound.force_n) << run.name << " step " << k;
    ASSERT_LE(w.stiffness_n_per_m, bound.stiffness_n_per_m) << run.name << " step " << k;
    // Fields: every step in the tiers (a copy of the equilibrium: a failed update must leave it
    // as it was), every field_every steps in LINEAR (sparse solves), and the last step.
    const bool last = k + 1 == run.steps;
    if (!(tiered || failed || last || k % run.field_every == 0)) continue;
    if (failed) u_before = u;
    double u_max = 0.0;
    for (int m = 0; m < nm; ++m) {
      sim->displacements(m, u[m]);
      ASSERT_TRUE(u[m].allFinite()) << run.name << " step " << k << " mesh " << m;
      if (failed && u_before[m].size() == u[m].size()) {
        EXPECT_EQ(u[m], u_before[m]) << run.name << ": a failed update changed the field";
      }
      if (u[m].size()) u_max = std::max(u_max, u[m].cwiseAbs().maxCoeff());
    }
    w.max_displacement_m = std::max(w.max_displacement_m, u_max);
    if (last) w.final_displacement_m = u_max;
    // Energy (and inverted elements) every energy_every steps: an element loop per mesh.
    if (!(last || failed || k % energy_every == 0)) continue;
    double energy = 0.0;
    int inverted = 0;
    for (int m = 0; m < nm; ++m) {
      if (!elastic[m]) continue;
      fem::ElasticForcesReport report;
      energy += elastic[m]->energy(u[m], &report);
      inverted += report.inverted_elements;
      w.max_strain = std::max(w.max_strain, report.max_strain);
    }
    ASSERT_TRUE(std::isfinite(energy)) << run.name << " step " << k;
    EXPECT_GE(energy, -1e-12 * bound.energy_j) << run.name << " step " << k;  // round-off
    w.energy_j = std::max(w.energy_j, energy);
    w.inverted = std::max(w.inverted, inverted);
    ASSERT_LE(energy, bound.energy_j) << run.name << " step " << k;
    // The tiers report the inverted elements of the field they return (the same det F <= 0).
    if (tiered) {
      EXPECT_EQ(st.inverted_elements, inverted) << run.name << " step " << k;
    }
    if (!tiered && energy > 0.0) {
      // Clapeyron: the linear strain energy is half the work of the contact forces on the
      // displacements they caused (ties do no work: an exact tie is a constraint).
      std::vector<int> slots;
      std::vector<Vec3> forces;
      sim->last_contact_forces(0, slots, forces);  // the host carries the contact nodes
      const CoupledBody& body = *sim->body_of(0);
      double work = 0.0;
      for (std::size_t s = 0; s < slots.size(); ++s)
        work += forces[s].dot(u[0].segment<3>(3 * body.contact_nodes()[slots[s]]));
      w.clapeyron_rel = std::max(w.clapeyron_rel, std::abs(energy - 0.5 * work) / energy);
    }
    if (k % (10 * energy_every) == 0 || last) {
      w.tie_residual_m = std::max(w.tie_residual_m, sim->tie_residual_m());
    }
  }
  w.last = contacts;
  for (const ToolContact& c : contacts) w.final_force_n += c.force_n;
  w.mean_step_us = total_us / std::max(1, w.steps);
  std::printf(
      "stability | %-28s | %-12s | steps %5d | max|F| %.4g N (bound %.3g) | max|K| %.4g N/m | "
      "max U %.4g J (bound %.3g) | max|u| %.4g m | tie residual %.3g m | max strain %.3g | "
      "inverted %d (reported %d) | Clapeyron %.2g | LCP iterations %d, rows %d | unconverged %d | "
      "tier failures %d | step %.0f us\n",
      run.name.c_str(), scene::tier_name(run.tier), w.steps, w.force_n, bound.force_n,
      w.stiffness_n_per_m, w.energy_j, bound.energy_j, w.max_displacement_m, w.tie_residual_m,
      w.max_strain, w.inverted, w.inverted_reported, w.clapeyron_rel, w.lcp_iterations, w.max_rows,
      w.unconverged, w.tier_failures, w.mean_step_us);
  if (!w.last_error.empty()) {
    std::printf("stability | %s: last tier failure: %s\n", run.name.c_str(), w.last_error.c_str());
  }
  ::testing::Test::RecordProperty("max_force_n", std::to_string(w.force_n));
  ::testing::Test::RecordProperty("max_stiffness_n_per_m", std::to_string(w.stiffness_n_per_m));
  ::testing::Test::RecordProperty("max_strain_energy_j", std::to_string(w.energy_j));
  ::testing::Test::RecordProperty("max_tie_residual_m", std::to_string(w.tie_residual_m));
  ::testing::Test::RecordProperty("max_lcp_iterations", w.lcp_iterations);
  ::testing::Test::RecordProperty("unconverged_steps", w.unconverged);
  ::testing::Test::RecordProperty("tier_failures", w.tier_failures);
  ::testing::Test::RecordProperty("max_inverted_elements", w.inverted);
  ::testing::Test::RecordProperty("max_clapeyron_rel", std::to_string(w.clapeyron_rel));
  ::testing::Test::RecordProperty("max_green_strain", std::to_string(w.max_strain));
  if (keep) *keep = std::move(sim);
}

// ---------------------------------------------------------------------------------------------
// The cases, each on every tier

// The served tiers (COROTATIONAL is withdrawn: fem/served_tiers.hpp).
const std::vector<scene::Tier> kTiers{scene::Tier::kLinear, scene::Tier::kNonlinear};

std::string tier_name_of(const ::testing::TestParamInfo<scene::Tier>& info) {
  return scene::tier_name(info.param);
}

// The Stability cases run on every served tier with the old element at nu = 0.45 (linear-tet,
// the test names without suffix) and with the bundled brain's element, smoothed-tet, at nu = 0.49
// (the scenes' brain) and 0.499.
struct StabilityCase {
  scene::Tier tier;
  double nu;
  const char* element;
};

std::vector<StabilityCase> stability_cases() {
  std::vector<StabilityCase> out;
  for (const auto& [nu, element] : std::vector<std::pair<double, const char*>>{
           {0.45, "linear-tet"}, {0.49, "smoothed-tet"}, {0.499, "smoothed-tet"}})
    for (scene::Tier tier : kTiers) out.push_back({tier, nu, element});
  return out;
}

class Stability : public ::testing::TestWithParam<StabilityCase> {
 protected:
  scene::Tier tier() const { return GetParam().tier; }
  // The block of this case's material.
  Block block() const {
    Block b;
    b.nu = GetParam().nu;
    b.element = GetParam().element;
    return b;
  }
};

std::string stability_case_name(const ::testing::TestParamInfo<StabilityCase>& info) {
  const std::string element = info.param.element;
  if (element == "linear-tet") return scene::tier_name(info.param.tier);
  return std::string(scene::tier_name(info.param.tier)) + "_nu" +
         std::to_string(static_cast<int>(std::lround(info.param.nu * 1000))) + "_SmoothedTet";
}

// Nearly incompressible brain: nu = 0.45 (the scene's), 0.49 and 0.499 (linear tetrahedra lock;
// tests/server/fem/locking_test.cpp measures how much against CalculiX's quadratic tetrahedra),
// with linear-tet and with the locking-free smoothed-tet.
using PoissonCase = std::tuple<scene::Tier, double, const char*>;
class StabilityPoisson : public ::testing::TestWithParam<PoissonCase> {};

TEST_P(StabilityPoisson, PressCycles) {
  const auto [tier, nu, element] = GetParam();
  Block b;
  b.nu = nu;
  b.element = element;
  const BuiltScene scene = build_scene(b, "poisson");
  Scenario run;
  char name[64];
  std::snprintf(name, sizeof name, "poisson nu = %.3f %s", nu, element);
  run.name = name;
  run.model = &scene.model;
  run.tier = tier;
  run.path = press_cycles(b, 0.010, 0.03, 0.03);
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_GT(w.force_n, 0.0);
  if (tier == scene::Tier::kLinear) {
    EXPECT_LE(w.clapeyron_rel, 1e-6);
  }
}

INSTANTIATE_TEST_SUITE_P(stability, StabilityPoisson,
                         ::testing::Combine(::testing::ValuesIn(kTiers),
                                            ::testing::Values(0.45, 0.49, 0.499),
                                            ::testing::Values("linear-tet", "smoothed-tet")),
                         [](const ::testing::TestParamInfo<PoissonCase>& i) {
                           const double nu = std::get<1>(i.param);
                           const std::string element = std::get<2>(i.param);
                           return std::string(scene::tier_name(std::get<0>(i.param))) + "_nu" +
                                  std::to_string(static_cast<int>(std::lround(nu * 1000))) +
                                  (element == "linear-tet" ? "" : "_SmoothedTet");
                         });

// The press cycles at a vertex (24, 24) mm, the midpoint of an axis edge (30, 24) and a
// triangle's centroid (32, 28) of the pressed face's 12 mm cells (the cases above press the
// cell's centre, the midpoint of its diagonal edge): contact against the surface triangles holds
// wherever the tip lands.
TEST_P(Stability, PressCyclesAtVertexEdgeFace) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "vertex_edge_face");
  const std::vector<std::pair<const char*, std::pair<double, double>>> at{
      {"press at a vertex", {0.024, 0.024}},
      {"press at an edge midpoint", {0.030, 0.024}},
      {"press at a face centroid", {0.032, 0.028}}};
  for (const auto& [name, yz] : at) {
    Scenario run;
    run.name = name;
    run.model = &scene.model;
    run.tier = tier();
    run.path = press_cycles(b, 0.010, yz.first, yz.second);
    Worst w;
    drive(run, w);
    if (HasFatalFailure()) return;
    EXPECT_EQ(w.unconverged, 0) << name;
    EXPECT_EQ(w.tier_failures, 0) << name << ": " << w.last_error;
    EXPECT_GT(w.force_n, 0.0) << name;
    if (tier() == scene::Tier::kLinear) {
      EXPECT_LE(w.clapeyron_rel, 1e-6) << name;
    }
  }
}

// The same sphere pressed 10 mm at a vertex, an edge midpoint and a face centroid of the 12 mm
// cells (the cases above) presses about as hard in NONLINEAR as in LINEAR wherever it lands: at
// each point the largest |F| of the press cycles differs from LINEAR's by at most 7.2 %, the
// largest gap of CalculiX's NLGEOM against its own linear answer at a 10 mm press on the cube
// (docs/accuracy.md, "The measurements behind the choice"), and the three points are within a
// factor 2 of each other. The tiers' node and edge rows once pressed a vertex twice as hard as
// an edge or a face in NONLINEAR alone (1.025 / 0.508 / 0.508 N against LINEAR's
// 0.503 / 0.488 / 0.460: the 60-degree rows' flat punch; bench/RESULTS.md, "The tiers' rows
// from the deformed point while the elements hold").
TEST(StabilityVertexEdgeFace, NonlinearPressesAsLinearAtVertexEdgeFace) {
  const std::vector<std::pair<double, double>> at{{0.024, 0.024}, {0.030, 0.024}, {0.032, 0.028}};
  const char* names[] = {"vertex", "edge midpoint", "face centroid"};
  for (const auto& [nu, element] : std::vector<std::pair<double, const char*>>{
           {0.45, "linear-tet"}, {0.49, "smoothed-tet"}}) {
    Block b;
    b.nu = nu;
    b.element = element;
    const BuiltScene scene = build_scene(b, std::string("tier_band_") + element);
    double force[2][3] = {};
    for (int t = 0; t < 2; ++t) {
      for (std::size_t p = 0; p < at.size(); ++p) {
        Scenario run;
        run.name = std::string("tier band, ") + names[p] + ", " + element;
        run.model = &scene.model;
        run.tier = t == 0 ? scene::Tier::kLinear : scene::Tier::kNonlinear;
        run.path = press_cycles(b, 0.010, at[p].first, at[p].second);
        Worst w;
        drive(run, w);
        if (HasFatalFailure()) return;
        force[t][p] = w.force_n;
      }
    }
    for (std::size_t p = 0; p < at.size(); ++p) {
      ASSERT_GT(force[0][p], 0.0) << element << " " << names[p];
      EXPECT_LE(std::abs(force[1][p] / force[0][p] - 1.0), 0.072)
          << element << " at a " << names[p] << ": NONLINEAR " << force[1][p] << " N, LINEAR "
          << force[0][p] << " N";
    }
    const double most = std::max({force[1][0], force[1][1], force[1][2]});
    const double least = std::min({force[1][0], force[1][1], force[1][2]});
    EXPECT_LE(most, 2.0 * least) << element;
  }
}

// A stiff artery tied inside soft brain: E_artery / E_brain = 1e2, 1e4, 1e6; the tool presses the
// brain over the artery. The tie stays exact (coupling by Schur complement, Newton with the tie
// eliminated), and in LINEAR the strain energy of both meshes is half the contact forces' work
// (Clapeyron): the fields of brain and artery are consistent however stiff the artery.
using RatioCase = std::tuple<scene::Tier, double>;
class StabilityStiffnessRatio : public ::testing::TestWithParam<RatioCase> {};

TEST_P(StabilityStiffnessRatio, PressOverTheArtery) {
  const auto [tier, ratio] = GetParam();
  Block b;
  b.artery_ratio = ratio;
  const BuiltScene scene = build_scene(b, "ratio");
  Scenario run;
  char name[64];
  std::snprintf(name, sizeof name, "artery/brain E ratio %.0e", ratio);
  run.name = name;
  run.model = &scene.model;
  run.tier = tier;
  run.path = press_cycles(b, 0.010, 0.03, 0.03);
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_GT(w.force_n, 0.0);
  EXPECT_LE(w.tie_residual_m, 1e-9 * w.max_displacement_m);
  if (tier == scene::Tier::kLinear) {
    EXPECT_LE(w.clapeyron_rel, 1e-6);
  }
}

INSTANTIATE_TEST_SUITE_P(
    stability, StabilityStiffnessRatio,
    ::testing::Combine(::testing::ValuesIn(kTiers), ::testing::Values(1e2, 1e4, 1e6)),
    [](const ::testing::TestParamInfo<RatioCase>& i) {
      return std::string(scene::tier_name(std::get<0>(i.param))) + "_1e" +
             std::to_string(static_cast<int>(std::lround(std::log10(std::get<1>(i.param)))));
    });

// Slivers: vertices one layer below the pressed face moved towards it until a tetrahedron's
// smallest dihedral angle is 0.5 degree (every tetrahedron around them keeps a positive volume);
// the tool strokes over them.
constexpr double kSliverDeg = 0.5;

void make_slivers(const Block& b, std::vector<mesh::Vec3>& x, const std::vector<mesh::Tet>& tets) {
  const double h = b.edge_m / b.cells;
  const fem::testing::BoxSpec grid{b.cells, b.cells, b.cells};
  for (int j : {1, 3}) {
    for (int k : {1, 3}) {
      const int v = fem::testing::box_node(grid, b.cells - 1, j, k);
      // v's tetrahedron whose other three vertices lie on the face x = L: v moves towards that
      // triangle's centroid, flattening every tetrahedron of v with a face on x = L.
      mesh::Vec3 target = mesh::Vec3::Zero();
      std::vector<int> around;
      for (std::size_t t = 0; t < tets.size(); ++t) {
        if (std::find(tets[t].begin(), tets[t].end(), v) == tets[t].end()) continue;
        around.push_back(static_cast<int>(t));
        int on_face = 0;
        mesh::Vec3 c = mesh::Vec3::Zero();
        for (int a : tets[t]) {
          if (a == v) continue;
          if (std::abs(x[a].x() - b.edge_m) < 1e-12) ++on_face;
          c += x[a] / 3.0;
        }
        if (on_face == 3) target = c;
      }
      ASSERT_GT(target.norm(), 0.0);
      const mesh::Vec3 start = x[v];
      auto smallest_angle = [&](double alpha, bool& positive) {
        x[v] = start + alpha * (target - start);
        double deg = 180.0;
        positive = true;
        for (int t : around) {
          const auto& q = tets[t];
          const auto tq = mesh::tet_quality(x[q[0]], x[q[1]], x[q[2]], x[q[3]]);
          positive = positive && tq.volume_m3 > 1e-9 * h * h * h;
          deg = std::min(deg, tq.min_dihedral_deg);
        }
        return deg;
      };
      double lo = 0.0, hi = 1.0;  // bisection on the move towards the target
      for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (lo + hi);
        bool positive = false;
        const double deg = smallest_angle(mid, positive);
        (deg > kSliverDeg && positive ? lo : hi) = mid;
      }
      bool positive = false;
      smallest_angle(lo, positive);
      ASSERT_TRUE(positive);
    }
  }
}

TEST_P(Stability, Slivers) {
  Block b = block();
  b.edit = [&b](std::vector<mesh::Vec3>& x, const std::vector<mesh::Tet>& t) {
    make_slivers(b, x, t);
  };
  const BuiltScene scene = build_scene(b, "sliver");
  if (HasFatalFailure()) return;
  const mesh::QualityReport q = mesh::quality(scene.model.meshes[0].mesh);
  std::printf("stability | sliver mesh: %s\n", q.summary().c_str());
  ASSERT_LT(q.min_dihedral_deg, 1.0);
  ASSERT_EQ(q.inverted, 0);
  Scenario run;
  char name[64];
  std::snprintf(name, sizeof name, "slivers (min dihedral %.2f deg)", q.min_dihedral_deg);
  run.name = name;
  run.model = &scene.model;
  run.tier = tier();
  // Over two of the slivers (grid z = 3, y = 1 and 3) and between them.
  run.path = press_cycles(b, 0.010, b.node_m(2), b.node_m(3));
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_GT(w.force_n, 0.0);
  if (tier() == scene::Tier::kLinear) {
    EXPECT_LE(w.clapeyron_rel, 1e-6);
  }
}

// Large compression: the real probe's 2 mm tip pushes one surface node 25 mm (40 % of the block)
// deep and holds it. The elements around the node invert in the corotational equilibrium (a
// linear law in each element's rotated frame, finite for an inverted element) and would in the
// linear field; the neo-Hookean energy of the nonlinear tier resists inversion. Every tier stays
// finite, the tiers report the inverted elements of their field (StepStats), and from 5 mm deep
// on the force does not fall below 98 % of the largest felt so far while the tool goes deeper.
TEST_P(Stability, InvertedElementsUnderLargeCompression) {
  Block b = block();
  b.tip_radius_m = 0.002;
  const BuiltScene scene = build_scene(b, "inverted");
  Scenario run;
  run.name = "inverted elements";
  run.model = &scene.model;
  run.tier = tier();
  run.path = [b](int k) {
    const double d = 0.025 * std::min(1.0, k / 1500.0);
    return std::vector<ToolPose>{press(b, d, b.node_m(2), b.node_m(2))};
  };
  // The force along the ramp from 5 mm deep on: it never falls while the tool goes deeper.
  ForceFall fall{300, 1500};
  run.observe = [&fall](int k, const std::vector<ToolContact>& c) { fall.observe(k, c); };
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_GT(w.force_n, 0.0);
  EXPECT_EQ(w.unconverged, 0);
  std::printf("stability | inverted elements %s: %d in the field, %d reported, tier failures %d, "
              "%d held by the element barrier; force %.4f N at the end, largest fall on the ramp "
              "%.4f (step %d)\n",
              scene::tier_name(tier()), w.inverted, w.inverted_reported, w.tier_failures,
              w.barrier_reported, w.final_force_n.norm(), fall.worst, fall.worst_step);
  RecordProperty("inverted_reported", w.inverted_reported);
  EXPECT_LT(fall.worst, 0.02) << "step " << fall.worst_step;
  // The corotational equilibrium does invert elements (counted on its field), and says so; the
  // counts equal at every checked step (drive).
  if (tier() == scene::Tier::kCorotational) {
    EXPECT_GT(w.inverted, 0);
    EXPECT_GT(w.inverted_reported, 0);
  }
}

// The tool driven straight through the block along x (tip and then the 150 mm shaft, 5 mm
// outside the face x = L to clear of the face x = 0, in 1.8 s), then held outside 0.2 s: every
// force bounded on the way, none at the end, and the tissue back at rest. The whole path is
// felt: a force at every step with the tip or the shaft in the block (1650 steps). Measured
// exception: in NONLINEAR the tip, released 27 mm below the face (max_penetration_m), feels 0 N
// for one step (315): that step finds its rows on the last equilibrium, deformed around the tip,
// where the shaft touches nothing; its forces are then 0, the tissue is at rest at the next
// update (TierWorker, TierEquilibrium::update) and the shaft's rows carry 0.05-0.11 N from step
// 316 on, with either element and nu. (Before, the worker relaxed the forces towards 0 over
// several step-limited updates: 2-5 steps without force, more at higher nu and on smoothed-tet.)
// LINEAR has none.
TEST_P(Stability, ToolThroughTheTissueAndOut) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "through");
  Scenario run;
  run.name = "through the tissue and out";
  run.model = &scene.model;
  run.tier = tier();
  const double shaft = scene.model.tools[0].shaft_length_m;
  run.path = [b, shaft](int k) {
    const double travel = b.edge_m + 2.0 * b.tip_radius_m + shaft + 0.010;
    const double d = -0.005 + travel * std::min(1.0, k / 1800.0);
    return std::vector<ToolPose>{press(b, d, 0.03, 0.03)};
  };
  // Steps whose tool (tip sphere or shaft) reaches into the block [0, L] along x, and those of
  // them with no force.
  int inside = 0, unfelt = 0, first_unfelt = -1, last_unfelt = -1;
  run.observe = [&](int k, const std::vector<ToolContact>& c) {
    const double tip_x = run.path(k)[0].tip_m.x();
    if (tip_x - b.tip_radius_m >= b.edge_m || tip_x + shaft <= 0.0) return;
    ++inside;
    if (c[0].force_n.norm() == 0.0) {
      ++unfelt;
      if (first_unfelt < 0) first_unfelt = k;
      last_unfelt = k;
    }
  };
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  std::printf("through: %d steps with the tool in the block, %d without force (steps %d .. %d)\n",
              inside, unfelt, first_unfelt, last_unfelt);
  EXPECT_GT(inside, 1500);
  EXPECT_LE(unfelt, tier() == scene::Tier::kLinear ? 0 : 1)
      << "steps " << first_unfelt << " .. " << last_unfelt;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_GT(w.force_n, 0.0);
  EXPECT_FALSE(w.last[0].in_contact);
  EXPECT_EQ(w.final_force_n.norm(), 0.0);
  EXPECT_LE(w.final_displacement_m, 1e-9 * w.max_displacement_m);
}

// Jumps of 10 cm in one step: from 10 cm off the surface to 8 mm deep, out sideways by 10 cm,
// back, 10 cm deeper (the tip beyond the far face, the shaft through the block), back, and away;
// each pose held 250 steps.
TEST_P(Stability, ToolJumps10cm) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "jump");
  Scenario run;
  run.name = "tool jumps 10 cm";
  run.model = &scene.model;
  run.tier = tier();
  run.path = [b](int k) {
    const double c = 0.03;
    switch (k / 250) {
      case 0:
        return std::vector<ToolPose>{press(b, -0.092, c, c)};
      case 1:
        return std::vector<ToolPose>{press(b, 0.008, c, c)};
      case 2:
        return std::vector<ToolPose>{press(b, 0.008, c + 0.1, c)};
      case 3:
        return std::vector<ToolPose>{press(b, 0.008, c, c)};
      case 4:
        return std::vector<ToolPose>{press(b, 0.108, c, c)};
      case 5:
        return std::vector<ToolPose>{press(b, 0.008, c, c)};
      default:
        return std::vector<ToolPose>{press(b, -0.092, c, c)};
    }
  };
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_GT(w.force_n, 0.0);
  EXPECT_FALSE(w.last[0].in_contact);
  EXPECT_EQ(w.final_force_n.norm(), 0.0);
  EXPECT_LE(w.final_displacement_m, 1e-9 * w.max_displacement_m);
}

// Two tools on one node, pressed 8 mm (0.5 s) and then pulled apart along +-y (30 mm each in
// 1.5 s): each feels a bounded force; on the shared node the deeper tool carries the row.
TEST_P(Stability, TwoToolsPullOneNodeApart) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "two_apart");
  Scenario run;
  run.name = "two tools pulled apart";
  run.model = &scene.model;
  run.tier = tier();
  run.tools = 2;
  const double c = b.node_m(2);
  run.path = [b, c](int k) {
    const double d = 0.008 * std::min(1.0, k / 500.0);
    const double s = 0.03 * std::max(0.0, (k - 500) / 1500.0);
    return std::vector<ToolPose>{press(b, d, c + s, c), press(b, d, c - s, c)};
  };
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_TRUE(w.last[0].in_contact && w.last[1].in_contact);
}

// Two tools at the same node from opposite sides: one from outside (handle along +x), one from
// inside the tissue (handle along -x, through the block), their depths alternating every step
// (6 and 7 mm), so the shared row changes owner at every step.
TEST_P(Stability, TwoToolsPressOneNodeFromOppositeSides) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "two_opposite");
  Scenario run;
  run.name = "two tools, opposite sides";
  run.model = &scene.model;
  run.tier = tier();
  run.tools = 2;
  const double c = b.node_m(2);
  run.path = [b, c](int k) {
    const double ramp = std::min(1.0, k / 300.0);
    const double da = ramp * (k % 2 ? 0.006 : 0.007), db = ramp * (k % 2 ? 0.007 : 0.006);
    ToolPose outside = press(b, da, c, c), inside = press(b, db, c, c);
    inside.axis = -Vec3::UnitX();
    return std::vector<ToolPose>{outside, inside};
  };
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  // The last step (odd): the inside tool is the deeper one and carries the node.
  EXPECT_GT(w.last[1].force_n.norm(), 0.0);
  EXPECT_GT(w.last[1].force_n.norm(), w.last[0].force_n.norm());
}

// Motions of 1e-9 m per step: pressed 6 mm (0.3 s), held (0.5 s), then 1200 steps of 1 nm deeper
// each, and 200 more measured one by one: the force follows the motion, dF = K dx per step (K:
// the step's contact stiffness), without noise of the motion's size.
TEST_P(Stability, NanometreMotions) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "nanometre");
  Scenario run;
  run.name = "1e-9 m per step";
  run.model = &scene.model;
  run.tier = tier();
  auto depth = [](int k) { return 0.006 * std::min(1.0, k / 300.0) + 1e-9 * std::max(0, k - 800); };
  run.path = [b, depth](int k) { return std::vector<ToolPose>{press(b, depth(k), 0.03, 0.03)}; };
  std::unique_ptr<Simulation> sim;
  Worst w;
  drive(run, w, &sim);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  std::vector<ToolContact> c0, c1;
  StepStats st;
  double worst_rel = 0.0, mean_ratio = 0.0;
  Vec3 f_first = Vec3::Zero(), kdx_sum = Vec3::Zero();
  const int n = 200;
  for (int k = 0; k <= n; ++k) {
    sim->step({press(b, depth(run.steps + k), 0.03, 0.03)}, c1, st);
    if (k == 0) f_first = c1[0].force_n;
    if (k > 0) {
      const Vec3 kdx = c0[0].stiffness_n_per_m * Vec3(-1e-9, 0.0, 0.0);
      const Vec3 df = c1[0].force_n - c0[0].force_n;
      worst_rel = std::max(worst_rel, (df - kdx).norm() / kdx.norm());
      kdx_sum += kdx;
    }
    c0 = c1;
  }
  mean_ratio = (c1[0].force_n - f_first).norm() / kdx_sum.norm();
  std::printf(
      "stability | 1e-9 m per step %s: per step |dF - K dx| / |K dx| <= %.3g; over %d steps "
      "|F_end - F_start| / sum |K dx| = %.4f\n",
      scene::tier_name(tier()), worst_rel, n, mean_ratio);
  RecordProperty("nanometre_df_minus_kdx_rel", std::to_string(worst_rel));
  RecordProperty("nanometre_mean_df_over_kdx", std::to_string(mean_ratio));
  if (tier() == scene::Tier::kLinear) {
    // Linear while the active set holds, but for the turn of the rows' radial normals with the
    // tip, which K leaves out (simulation_test.cpp, StiffnessMatchesFiniteDifference): 3 % seen.
    EXPECT_LE(worst_rel, 0.05);
  } else {
    // The step's K is the warped linear stiffness, the force converges to the tier's: over many
    // steps dF / (K dx) is their ratio, within 25 % at this press (4 % strain; measured: 1 %),
    // and no single step departs from K dx by more than twice it: the rows are found on the tier's
    // latest equilibrium, whose every update moves the surface by ~1e-7 of the press (measured:
    // 1.5 K dx corotational at 1 nm per step), noise of this motion's size but not larger.
    EXPECT_GT(mean_ratio, 0.8);
    EXPECT_LT(mean_ratio, 1.25);
    EXPECT_LE(worst_rel, 2.0);
  }
}

// Motions of 0.2 m per step: every step the tool goes from 6 mm deep to 0.2 m off the surface or
// back; from step 1000 the far pose is 0.2 m to the side instead.
TEST_P(Stability, DecimetreMotions) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "decimetre");
  Scenario run;
  run.name = "0.2 m per step";
  run.model = &scene.model;
  run.tier = tier();
  run.path = [b](int k) {
    ToolPose p = press(b, 0.006, 0.03, 0.03);
    if (k % 2) p.tip_m += k < 1000 ? Vec3(0.2, 0.0, 0.0) : Vec3(0.0, 0.2, 0.0);
    return std::vector<ToolPose>{p};
  };
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_GT(w.force_n, 0.0);
  EXPECT_FALSE(w.last[0].in_contact);  // the last step (odd) is 0.2 m away
}

// A scene whose mesh file is in mm but says nothing (read as m: a 60 m block): compile() warns,
// naming the scene file, the mesh, its size in m and the fix; with file_unit_m: 0.001 no
// warning. The mistaken scene still runs stably on every tier (the physics has no unit of its
// own; only the tool, in m, is 1000 times too small for it).
TEST_P(Stability, SceneInMillimetresIsWarnedAbout) {
  Block b = block();
  b.file_unit_m = 1e-3;
  b.declare_unit = false;
  const BuiltScene wrong = build_scene(b, "mm");
  ASSERT_EQ(wrong.model.warnings.size(), 1u);
  const std::string& msg = wrong.model.warnings[0];
  std::printf("stability | size check: %s\n", msg.c_str());
  EXPECT_NE(msg.find(wrong.source), std::string::npos) << msg;
  EXPECT_NE(msg.find("\"brain\""), std::string::npos) << msg;
  EXPECT_NE(msg.find("diagonal 103.9 m"), std::string::npos) << msg;  // 60 m x sqrt(3)
  EXPECT_NE(msg.find("set file_unit_m: 0.001"), std::string::npos) << msg;
  b.declare_unit = true;
  const BuiltScene right = build_scene(b, "mm_declared");
  EXPECT_TRUE(right.model.warnings.empty());
  EXPECT_NEAR(right.model.meshes[0].mesh.vertices().back().x(), b.edge_m, 1e-12);

  Block big = b;  // the mistaken scene's geometry, for the tool path
  big.edge_m = 1000.0 * b.edge_m;
  Scenario run;
  run.name = "scene in mm read as m";
  run.model = &wrong.model;
  run.tier = tier();
  run.path = press_cycles(big, 0.010, big.node_m(2), big.node_m(2));  // at a node
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_EQ(w.unconverged, 0);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
  EXPECT_GT(w.force_n, 0.0);
}

// A contact solver that does not converge says so: the two tools pulled apart with the LCP
// limited to one pivot per step (SimulationOptions::lcp_max_iterations = 1). Steps whose active
// set changes by more than one row do not converge: StepStats and every ToolContact say
// converged = false and the last good answer comes back (checked in drive at every step).
TEST_P(Stability, UnconvergedContactSaysSoAndKeepsTheLastGoodAnswer) {
  Block b = block();
  const BuiltScene scene = build_scene(b, "lcp_limit");
  Scenario run;
  run.name = "LCP limited to 1 pivot";
  run.model = &scene.model;
  run.tier = tier();
  run.tools = 2;
  run.options.lcp_max_iterations = 1;
  const double c = b.node_m(2);
  run.path = [b, c](int k) {
    const double d = 0.008 * std::min(1.0, k / 500.0);
    const double s = 0.03 * std::max(0.0, (k - 500) / 1500.0);
    return std::vector<ToolPose>{press(b, d, c + s, c), press(b, d, c - s, c)};
  };
  Worst w;
  drive(run, w);
  if (HasFatalFailure()) return;
  EXPECT_GT(w.unconverged, 0);
  EXPECT_LT(w.unconverged, w.steps);
  EXPECT_EQ(w.tier_failures, 0) << w.last_error;
}

INSTANTIATE_TEST_SUITE_P(stability, Stability, ::testing::ValuesIn(stability_cases()),
                         stability_case_name);

// A tier update that fails throws a message naming it (the body, the tier, the mesh file,
// Newton's last residual) and keeps the last good equilibrium: a Newton tolerance no update can
// meet (1e-20 relative, below round-off) and no step limit. The tool presses 6 mm: the update
// fails, the field stays the rest state it was, the contact answer stays finite; withdrawn, the
// simulation steps on (nothing left to update).
class StabilityTierFailure : public ::testing::TestWithParam<scene::Tier> {};

TEST_P(StabilityTierFailure, FailedUpdateThrowsAndKeepsTheLastGoodEquilibrium) {
  Block b;
  scene::Model model = build_scene(b, "tier_failure").model;
  model.effects.tier = GetParam();
  SimulationOptions o;
  o.tier_worker_thread = false;
  o.tier_newton_tolerance = 1e-20;
  o.tier_update_steps = 0;
  auto sim = Simulation::build(model, o);
  std::vector<ToolContact> c;
  StepStats st;
  sim->step({press(b, -0.002, 0.03, 0.03)}, c, st);  // clear of the surface: nothing to update
  const std::string msg =
      neurosim::testing::message_of([&] { sim->step({press(b, 0.006, 0.03, 0.03)}, c, st); });
  std::printf("stability | tier failure %s: %s\n", scene::tier_name(GetParam()), msg.c_str());
  RecordProperty("tier_failure_message", msg);
  EXPECT_NE(msg.find("TierEquilibrium: body of host mesh 0 in tier"), std::string::npos) << msg;
  EXPECT_NE(msg.find(scene::tier_name(GetParam())), std::string::npos) << msg;
  EXPECT_NE(msg.find("brain.mesh"), std::string::npos) << msg;
  EXPECT_NE(msg.find("no convergence"), std::string::npos) << msg;
  ASSERT_TRUE(c[0].in_contact);
  EXPECT_TRUE(c[0].force_n.allFinite() && c[0].stiffness_n_per_m.allFinite());
  EXPECT_GT(c[0].force_n.norm(), 0.0);
  Eigen::VectorXd u;
  sim->displacements(0, u);
  EXPECT_EQ(u.cwiseAbs().maxCoeff(), 0.0);  // the last good equilibrium: at rest
  EXPECT_NO_THROW(sim->step({press(b, -0.002, 0.03, 0.03)}, c, st));
  EXPECT_FALSE(c[0].in_contact);
  sim->displacements(0, u);
  EXPECT_EQ(u.cwiseAbs().maxCoeff(), 0.0);
}

INSTANTIATE_TEST_SUITE_P(stability, StabilityTierFailure,
                         ::testing::Values(scene::Tier::kNonlinear),
                         tier_name_of);

// smoothed-tet's deep press on cells the tip's size: a 3 mm tip pushed 20 mm into the block of
// 6 mm cells at nu = 0.49 in 1.5 s and held 0.5 s. The smoothing cells alone let the tetrahedra
// under a pushed tip collapse (the 7 mm brain's 20 mm press: 2-6 inverted, the force falling
// from 0.52 to 0.18 N while the tool went deeper); the element barrier (fem/element_barrier.hpp)
// holds them. In NONLINEAR the force does not fall below 98 % of the largest felt so far while
// the tool goes deeper, nothing is inverted, and the force at the end is within a factor 2 of
// LINEAR's (same mesh and element).
TEST(StabilitySmoothedTet, DeepPressOnCellsTheTipsSize) {
  Block b;
  b.cells = 10;
  b.nu = 0.49;
  b.element = "smoothed-tet";
  b.tip_radius_m = 0.003;
  const BuiltScene scene = build_scene(b, "deep");
  double final_n[2] = {0.0, 0.0};
  for (scene::Tier tier : {scene::Tier::kLinear, scene::Tier::kNonlinear}) {
    Scenario run;
    run.name = "deep press, 6 mm cells";
    run.model = &scene.model;
    run.tier = tier;
    run.path = [b](int k) {
      return std::vector<ToolPose>{press(b, 0.020 * std::min(1.0, k / 1500.0), b.node_m(5) + 0.0011,
                                         b.node_m(5) + 0.0007)};
    };
    ForceFall fall{300};
    run.observe = [&fall](int k, const std::vector<ToolContact>& c) { fall.observe(k, c); };
    Worst w;
    drive(run, w);
    if (HasFatalFailure()) return;
    const bool nonlinear = tier == scene::Tier::kNonlinear;
    final_n[nonlinear ? 1 : 0] = w.final_force_n.norm();
    std::printf("deep press %s: force %.4f N at the end, largest fall %.4f (step %d), %d inverted "
                "(%d reported), %d held by the element barrier, max strain %.2f\n",
                scene::tier_name(tier), w.final_force_n.norm(), fall.worst, fall.worst_step,
                w.inverted, w.inverted_reported, w.barrier_reported, w.max_strain);
    EXPECT_EQ(w.unconverged, 0);
    EXPECT_EQ(w.tier_failures, 0) << w.last_error;
    EXPECT_LT(fall.worst, 0.02) << scene::tier_name(tier) << " step " << fall.worst_step;
    EXPECT_EQ(w.inverted_reported, 0);
  }
  EXPECT_GT(final_n[1], 0.5 * final_n[0]);
  EXPECT_LT(final_n[1], 2.0 * final_n[0]);
}

// The linear tier at 30 % strain: a 15 mm tip pressed 18 mm (30 % of the block) in 1 s and held
// 1 s, on every tier; the linear and corotational answers against the nonlinear one.
TEST(StabilityStrain, LinearTierAt30PercentStrain) {
  Block b;
  b.tip_radius_m = 0.015;
  const BuiltScene scene = build_scene(b, "strain30");
  const double depth = 0.3 * b.edge_m;
  std::vector<Worst> w(kTiers.size());
  std::vector<Eigen::VectorXd> u(kTiers.size());
  for (std::size_t t = 0; t < kTiers.size(); ++t) {
    Scenario run;
    run.name = "30 % strain";
    run.model = &scene.model;
    run.tier = kTiers[t];
    run.path = [b, depth](int k) {
      return std::vector<ToolPose>{press(b, depth * std::min(1.0, k / 1000.0), 0.03, 0.03)};
    };
    std::unique_ptr<Simulation> sim;
    drive(run, w[t], &sim);
    if (HasFatalFailure()) return;
    EXPECT_EQ(w[t].unconverged, 0);
    EXPECT_EQ(w[t].tier_failures, 0) << w[t].last_error;
    sim->displacements(0, u[t]);
  }
  // The last tier is NONLINEAR, the reference of the others.
  const std::size_t nl = kTiers.size() - 1;
  ASSERT_EQ(kTiers[nl], scene::Tier::kNonlinear);
  const Vec3 f_nl = w[nl].final_force_n;
  const double scale = u[nl].cwiseAbs().maxCoeff();
  for (std::size_t t = 0; t < nl; ++t) {
    const double force_err = (w[t].final_force_n - f_nl).norm() / f_nl.norm();
    const double field_err = (u[t] - u[nl]).cwiseAbs().maxCoeff() / scale;
    std::printf(
        "stability | 30 %% strain: %s against NONLINEAR: force %.4g N vs %.4g N "
        "(error %.1f %%), displacement error %.1f %% of max |u| %.4g m; max Green strain "
        "%.3f\n",
        scene::tier_name(kTiers[t]), w[t].final_force_n.norm(), f_nl.norm(), 100.0 * force_err,
        100.0 * field_err, scale, w[nl].max_strain);
    RecordProperty(std::string(scene::tier_name(kTiers[t])) + "_force_error_vs_nonlinear",
                   std::to_string(force_err));
    RecordProperty(std::string(scene::tier_name(kTiers[t])) + "_field_error_vs_nonlinear",
                   std::to_string(field_err));
    // At 30 % strain the tiers differ visibly but not wildly (the linear tier is finite, not
    // unstable): more than 0.5 %, less than 100 %.
    EXPECT_GT(std::max(force_err, field_err), 0.005) << scene::tier_name(kTiers[t]);
    EXPECT_LT(force_err, 1.0) << scene::tier_name(kTiers[t]);
    EXPECT_LT(field_err, 1.0) << scene::tier_name(kTiers[t]);
  }
  EXPECT_GE(w[nl].max_strain, 0.3);
}

}  // namespace
}  // namespace neurosim::interaction
