// The real neurosim-server in every elasticity tier on the bundled cube and on a brain (the tests'
// 7 mm brain_artery, kBrain7, in LINEAR and NONLINEAR) (child process,
// private DDS domain on loopback, bounded): `--tier T`, a station presses and holds; SimStatus
// names the tier that runs (and, for COROTATIONAL and NONLINEAR, a non-zero equilibrium update
// rate); every ContactModel is finite; once the held force is still, it equals the in-process
// Simulation of the same tier settled at the same pose (synchronous updates) to 1e-9 relative.
// The cost of the tier's accuracy in SimStatus: max_strain is the in-process field's largest
// principal strain, expected_force_error the value the accuracy table given with
// --accuracy-table gives at that strain (a test table: error = 20 x strain), and since that is
// above the scene's bound (effects.max_expected_force_error) the server warns once. Against
// the converged answer (nested refinements extrapolated): discretization_error_estimate is the committed
// share/accuracy/discretization_error.csv's row for the host (the bundled and the 7 mm brain must
// have one: smoothed-tet, nu 0.49) and total_error_estimate that + expected_force_error; a host on an
// element the table has no row for says -1 (unknown) in both, and the log says so.
#include "server/fem/strain.hpp"
#include "server/scene/compile.hpp"
#include "server/service/discretization_table.hpp"
#include "tests/server/service/service_scenarios.hpp"

#include <cmath>
#include <fstream>
#include <cstdio>

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;
namespace ni = neurosim::interaction;

namespace {

struct Press {
  const char* scene;  // under the source tree, or with brain7 the tests' 7 mm brain of that name
  std::array<double, 3> origin;  // a surface point, unit m
  std::array<double, 3> up;      // outward normal there
  double depth_m;
  bool brain7{false};
};

// cube: the +x face's centre (the paper's push); brain: the demo's point on the right lateral
// surface, along its normal.
const Press kCube{"scenes/cube_cylinder.scene", {0.1, 0.05, 0.05}, {1.0, 0.0, 0.0}, 0.004};
const Press kBrain{"scenes/brain_artery.scene", {0.1605, 0.1125, 0.0787}, {0.963, 0.176, 0.202},
                   0.004};
// The same press on the tests' 7 mm brain_artery (test_support.hpp brain7_scene: 5354 vertices
// instead of 13272, a row of its own in the committed discretization table): NONLINEAR's
// equilibrium updates on the bundled brain kept both cores busy for minutes of a CI run; the
// server's tier against the in-process one does not depend on the cell size. LINEAR too: on the
// bundled brain its server and in-process builds took 42 s of CPU (120 s wall at load 6); the
// bundled brain's own discretization row is checked by discretization_table_test, and the
// server on the bundled brain by the viewer tests.
const Press kBrain7{"brain_artery", {0.1605, 0.1125, 0.0787}, {0.963, 0.176, 0.202}, 0.004, true};

neurosim_Tier wire_tier(const char* tier) {
  const std::string t = tier;
  return t == "linear" ? neurosim_TIER_LINEAR
                       : t == "corotational" ? neurosim_TIER_COROTATIONAL : neurosim_TIER_NONLINEAR;
}

void press_and_hold(const Press& press, const char* tier) {
  const auto scene =
      press.brain7 ? nt::brain7_scene(press.scene) : nt::source_dir() / press.scene;
  neurosim::scene::Model model = neurosim::scene::load_model(scene);
  model.effects.tier = *neurosim::fem::parse_tier(tier);
  const double r = model.tools.at(0).tip_radius_m;
  ni::Vec3 up(press.up[0], press.up[1], press.up[2]);
  up.normalize();
  const ni::Vec3 origin(press.origin[0], press.origin[1], press.origin[2]);
  auto tip = [&](double depth) -> std::array<double, 3> {
    const ni::Vec3 p = origin + (r - depth) * up;
    return {p.x(), p.y(), p.z()};
  };
  const std::array<double, 3> hold = tip(press.depth_m);

  // Accuracy table: for this scene, tier, element and nu, 20 % force error per 1 % of strain (up
  // to 100 %).
  const auto& host_material = model.meshes.at(0).material;
  const auto table = nt::temp_dir(std::string("tier_table_") + tier) / "force_error.csv";
  {
    std::ofstream t(table);
    t << "# test table\nscene,tier,max_strain,force_rel_error,element,poisson_ratio\n"
      << model.name << "," << tier << ",1.0,20,"
      << neurosim::fem::element_name(host_material.element) << "," << host_material.poisson_ratio
      << "\n";
  }
  // The committed discretization table's row for this host (the server reads it by default).
  const auto disc_row =
      neurosim::service::DiscretizationTable::read(nt::source_dir() /
                                                   "share/accuracy/discretization_error.csv")
          .find(host_material.element, host_material.poisson_ratio,
                model.meshes.at(0).mesh.num_vertices(), model.meshes.at(0).mesh.num_tets());
  const bool brain = press.brain7 || std::string(press.scene) == kBrain.scene;
  if (brain) {
    ASSERT_TRUE(disc_row) << "no discretization row for the brain ("
                          << neurosim::fem::element_name(host_material.element) << ", nu "
                          << host_material.poisson_ratio << ")";
  }
  ASSERT_GT(model.effects.max_expected_force_error, 0.0) << "the bundled scenes set a bound";

  st::Setup setup;
  setup.exe = nt::bin_dir() / "neurosim-server";
  setup.scene = scene;
  setup.server_args = {"--tier", tier, "--accuracy-table", table.string()};
  setup.startup_timeout_s = 300;  // brain: meshes, factorization, boundary operator on 2 cores
  // The reference: the same tier in process, synchronous updates (deterministic). Built before
  // the server starts: with the run's cache still empty it factors the host once and the server
  // reads that factor, instead of both factoring the same brain at once on the two cores.
  ni::SimulationOptions sync;
  sync.tier_worker_thread = false;
  sync.compliance_cache_dir = nt::shared_cache_dir().string();  // the server's factor, once a run
  auto ref = ni::Simulation::build(model, sync);
  st::Session ses(setup, std::string("tier_") + tier, 240);
  ASSERT_TRUE(ses.wait_ready());
  const neurosim_Tier want = wire_tier(tier);
  ASSERT_TRUE(ses.status.wait_for([&](const neurosim_SimStatus& s) { return s.tier == want; }, 5))
      << ses.status.last_text;

  st::ModelCollector models(ses.client);
  const double approach_s = 1.0;
  const double hold_s = 150.0;  // at most: the test stops once the force has settled
  st::StationThread station(
      ses.client, "tier-1",
      [&](double t) { return tip(-0.002 + (press.depth_m + 0.002) * std::min(1.0, t / approach_s)); },
      approach_s + hold_s);
  ASSERT_TRUE(station.writer().wait_for_readers(1, DDS_SECS(10)));
  // The in-process tier settled at the held pose (synchronous updates: deterministic).
  std::vector<ni::ToolContact> c;
  ni::StepStats stats;
  ni::Vec3 prev = ni::Vec3::Constant(1e300);
  int steps = 0;
  for (steps = 1; steps <= 200; ++steps) {
    ref->step({st::pose_at(hold)}, c, stats);
    if ((c[0].force_n - prev).norm() <= 1e-12 * c[0].force_n.norm()) break;
    prev = c[0].force_n;
  }
  ASSERT_TRUE(c[0].in_contact);
  const double fn = c[0].force_n.norm();

  // The server's held force reaches the in-process one (to 1e-9 of it) and stays there for a
  // second of models. Not "still for a second" alone: the tier worker's updates come in bursts,
  // and an update that jumps the load path can take seconds (on the brain with a locking-free
  // element, 3 s between force changes were seen), so a still force may be half converged.
  double reached_t = -1.0;
  ni::Vec3 last_f = ni::Vec3::Zero();
  std::size_t seen = 0;
  const auto t0 = st::Clock::now();
  bool settled = false;
  while (!settled && st::seconds_since(t0) < approach_s + hold_s - 5.0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const auto recs = models.records();
    for (; seen < recs.size(); ++seen) {
      const auto& m = recs[seen];
      if (m.station != "tier-1") continue;
      const ni::Vec3 f(m.f0[0], m.f0[1], m.f0[2]);
      ASSERT_TRUE(f.allFinite()) << "ContactModel force not finite, seq " << m.tool_sequence;
      for (double k : m.K) ASSERT_TRUE(std::isfinite(k)) << "stiffness not finite";
      const bool at_ref = m.in_contact && (f - c[0].force_n).norm() <= 1e-9 * fn;
      if (!at_ref) reached_t = -1.0;
      if (at_ref && reached_t < 0.0) reached_t = st::seconds_since(t0);
      last_f = f;
    }
    settled = reached_t >= 0.0 && st::seconds_since(t0) - reached_t > 1.0;
  }
  std::printf("%s %s: held force %.9g N (server) vs %.9g N (in process, %d steps)%s\n",
              press.scene, tier, last_f.norm(), fn, steps,
              settled ? "" : ": never reached and held for a second");
  ASSERT_TRUE(settled) << last_f.transpose() << " vs " << c[0].force_n.transpose() << "\n"
                       << ses.server.log();
  double rate = 0.0;
  ASSERT_TRUE(ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        rate = s.tier_update_rate_hz;
        return s.tier == want;
      },
      5));
  std::printf("%s %s: update rate %.2f Hz\n", press.scene, tier, rate);
  if (want == neurosim_TIER_LINEAR) {
    EXPECT_EQ(rate, 0.0);
  } else {
    EXPECT_GT(rate, 0.0);
    EXPECT_TRUE(std::isfinite(rate));
  }

  // The largest strain of the settled fields, in process, and what SimStatus says.
  double strain = 0.0;
  for (int m = 0; m < ref->num_meshes(); ++m) {
    if (!ref->mesh_active(m)) continue;
    Eigen::VectorXd u;
    ref->displacements(m, u);
    strain = std::max(strain, neurosim::fem::max_principal_strain(ref->mesh(m), u).max_strain);
  }
  ASSERT_GT(strain, 0.0);
  // The strain is measured in the fields solved for viewers: a Deformation reader joins.
  neurosim::wire::Reader<neurosim_Deformation> viewer(ses.client.pp, ses.client.deform_topic);
  double status_strain = -1.0, status_error = -1.0, status_disc = -2.0, status_total = -2.0;
  const bool measured = ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        status_strain = s.max_strain;
        status_error = s.expected_force_error;
        status_disc = s.discretization_error_estimate;
        status_total = s.total_error_estimate;
        return std::abs(s.max_strain - strain) <= 1e-6 * strain;
      },
      // A bound on a wait, not a speed claim (it returns at the first matching status): the
      // viewer's first field on the brain was not out after 8 s once at load ~7.
      60);
  std::printf("%s %s: max strain %.6g (server) vs %.6g (in process), expected force error %.6g, "
              "vs converged answer: discretization %.6g, total %.6g\n",
              press.scene, tier, status_strain, strain, status_error, status_disc, status_total);
  EXPECT_TRUE(measured) << "SimStatus max_strain " << status_strain << ", in process " << strain;
  EXPECT_NEAR(status_error, std::min(20.0, 20.0 * status_strain), 1e-12 * status_error);
  if (disc_row) {
    EXPECT_EQ(status_disc, disc_row->discretization_error);
    EXPECT_GT(status_disc, 0.0);
    EXPECT_LT(status_disc, 1.0) << "a discretization error of 100 % is no estimate";
    EXPECT_DOUBLE_EQ(status_total, status_disc + status_error);
  } else {
    EXPECT_EQ(status_disc, -1.0);
    EXPECT_EQ(status_total, -1.0);
  }
  const std::string log = ses.server.log();
  EXPECT_NE(log.find("exceeds the scene's bound effects.max_expected_force_error"),
            std::string::npos)
      << log;
}

}  // namespace

// A host on an element the committed discretization table has no row for (the cube on anp-tet,
// `--element anp-tet`): SimStatus says unknown (-1) for the discretization part and the total,
// not a number borrowed from another element, and the log says why.
TEST(service_tier, ElementWithoutATableSaysUnknown) {
  const auto scene = nt::source_dir() / kCube.scene;
  neurosim::scene::Model model = neurosim::scene::load_model(scene);
  const auto& host = model.meshes.at(0);
  ASSERT_FALSE(neurosim::service::DiscretizationTable::read(
                   nt::source_dir() / "share/accuracy/discretization_error.csv")
                   .find(neurosim::fem::Element::kAnpTet, host.material.poisson_ratio,
                         host.mesh.num_vertices(), host.mesh.num_tets()))
      << "the test needs an element without a row";
  st::Setup setup;
  setup.exe = nt::bin_dir() / "neurosim-server";
  setup.scene = scene;
  setup.server_args = {"--element", "anp-tet"};
  setup.startup_timeout_s = 300;
  st::Session ses(setup, "tier_unknown", 120);
  ASSERT_TRUE(ses.wait_ready());
  double disc = 0.0, total = 0.0;
  ASSERT_TRUE(ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        disc = s.discretization_error_estimate;
        total = s.total_error_estimate;
        return s.steps > 0;
      },
      10))
      << ses.status.last_text;
  EXPECT_EQ(disc, -1.0);
  EXPECT_EQ(total, -1.0);
  const std::string log = ses.server.log();
  EXPECT_NE(log.find("anp-tet"), std::string::npos) << log;
  EXPECT_NE(log.find("discretization error unknown"), std::string::npos) << log;
}

TEST(service_tier, CubeLinear) { press_and_hold(kCube, "linear"); }
TEST(service_tier, CubeNonlinear) { press_and_hold(kCube, "nonlinear"); }
TEST(service_tier, BrainLinear) { press_and_hold(kBrain7, "linear"); }
TEST(service_tier, BrainNonlinear) { press_and_hold(kBrain7, "nonlinear"); }
