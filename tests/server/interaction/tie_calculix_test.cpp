// The tied coupling (host A carved around the embedded mesh B, B's surface nodes inside A tied to
// A's new boundary S' by barycentric weights) against CalculiX (bench/RESULTS.md "The tied system
// (host + embedded mesh) against CalculiX"). One deck holds both meshes (C3D4, B's nodes after
// A's), each its material, A's (and B's) fixed nodes, one *EQUATION per tied node and direction
// (u_B,k - sum_a w_a u_A,a = 0) and the same *CLOADs; solved linear (*ELASTIC, *STATIC) and with
// NLGEOM (neo-Hooke, C10 = E/(4(1+nu)), D1 = 6(1-2nu)/E). Ours: LINEAR, the coupled body's tied
// compliance (CoupledBody::coupled_displacement for the forces on A, tied_mesh_displacement for
// those on B; B from TieCondensation); NONLINEAR, the tier's stacked equilibrium
// (fem::EquilibriumSolver on equilibrium_definition, the one TierEquilibrium updates) under the
// same nodal forces. Scenes: cube_cylinder.scene with both materials' element set to linear-tet
// (C3D4's), the cylinder raised 20 mm out of the cube's top (axis z = 0.105 m, as
// simulation_exposure_test; 1 N and 8 N: 2.4 mm, strain 0.17, LINEAR and NLGEOM 6.4 % apart) and
// the bundled enclosed placement (1 N). Measured (2026-11-29, 0.01-8 N): both tiers agree with ccx
// to its print rounding (the .dat's 7 significant digits): per dof 0.50-0.55 of ccx's last printed
// digit, <= 2.0e-7 of max |u_ccx|; our tie residual 1e-17 of max |u|. Asserted: 1 printed digit
// (floored at 1e-12 of max |u|, so a dof near zero is not held to its own round-off), 1e-6 of max
// |u_ccx|, our tie residual 1e-12 of max |u|. A missing ccx fails the test (a required package).
#include "server/fem/calculix.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/tier_equilibrium.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "cube_cylinder_fixtures.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

namespace neurosim::interaction {
namespace {

using mesh::Vec3;

// The raised or enclosed scene without tools, every material on C3D4's element.
scene::Scene cube_cylinder(double z_m) {
  scene::Scene s = testing::cube_cylinder_at(z_m, false);
  for (int m = 0; m < s.meshes_size(); ++m) s.mutable_meshes(m)->mutable_material()->set_element("linear-tet");
  return s;
}

double load_average() {
  std::ifstream in("/proc/loadavg");
  double l = -1.0;
  in >> l;
  return l;
}

// Both meshes in one (A's vertices, then B's; unused vertices of the carved A dropped).
struct Combined {
  mesh::TetMesh mesh;
  fem::MaterialMap materials;
  std::vector<int> id_a, id_b;  // A's / B's vertex -> combined id (-1: unused)
};

Combined combine(const mesh::TetMesh& a, const fem::Material& ma, const mesh::TetMesh& b,
                 const fem::Material& mb) {
  std::vector<Vec3> v = a.vertices();
  v.insert(v.end(), b.vertices().begin(), b.vertices().end());
  std::vector<mesh::Tet> t = a.tets();
  const int na = static_cast<int>(a.num_vertices());
  std::vector<int> mat(a.num_tets(), 0);
  for (auto tet : b.tets()) {
    for (int& x : tet) x += na;
    t.push_back(tet);
    mat.push_back(1);
  }
  mesh::BuildOptions bo;
  bo.drop_unused_vertices = true;
  bo.source = "host + embedded (tie_calculix_test)";
  Combined c{mesh::TetMesh::build(v, t, bo), fem::MaterialMap::per_tet({ma, mb}, mat), {}, {}};
  c.id_a.assign(a.num_vertices(), -1);
  c.id_b.assign(b.num_vertices(), -1);
  const auto& src = c.mesh.source_vertex_ids();
  for (std::size_t k = 0; k < src.size(); ++k) {
    const int s = src[k];
    if (s < na) c.id_a[s] = static_cast<int>(k);
    else c.id_b[s - na] = static_cast<int>(k);
  }
  return c;
}

struct CcxRun {
  fem::CalculixResult result;
  double seconds{0.0};
};

// write_calculix_input's deck with the tie's *EQUATION block inserted before *STEP; ccx run
// single-threaded as run_calculix does.
CcxRun run_tied_ccx(const std::string& tag, const Combined& c, const TieCondensation& tie,
                    const fem::CalculixLoads& loads) {
  const auto dir = neurosim::testing::temp_dir("ccx_tie_" + tag);
  const auto inp = dir / (tag + ".inp");
  fem::write_calculix_input(inp, c.mesh, c.materials, loads);
  std::string deck;
  {
    std::ifstream in(inp);
    std::stringstream ss;
    ss << in.rdbuf();
    deck = ss.str();
  }
  std::ostringstream eq;
  eq << std::setprecision(13);
  eq << "** the tie: u_B(k) - sum_a w_a u_A(a) = 0 per tied node k and direction\n*EQUATION\n";
  int equations = 0;
  for (std::size_t k = 0; k < tie.tied_nodes().size(); ++k) {
    const int nb = c.id_b.at(tie.tied_nodes()[k]);
    std::vector<std::pair<int, double>> terms;
    for (int j = 0; j < 3; ++j)
      if (tie.weights()[k][j] != 0.0) terms.push_back({c.id_a.at(tie.host_nodes()[k][j]), -tie.weights()[k][j]});
    for (int a = 1; a <= 3; ++a) {
      eq << 1 + terms.size() << "\n" << nb + 1 << ", " << a << ", 1.";
      for (const auto& [n, w] : terms) eq << ", " << n + 1 << ", " << a << ", " << w;
      eq << "\n";
      ++equations;
    }
  }
  const auto at = deck.find("*STEP");
  if (at == std::string::npos) throw std::runtime_error("no *STEP in the deck");
  deck.insert(at, eq.str());
  {
    std::ofstream out(inp);
    out << deck;
  }
  const auto dat = dir / (tag + ".dat");
  std::filesystem::remove(dat);
  const std::string cmd = "cd '" + dir.string() + "' && OMP_NUM_THREADS=1 CCX_NPROC_EQUATION_SOLVER=1 timeout -k 5 600 ccx -i " +
                          tag + " > " + tag + ".log 2>&1";
  const auto t0 = std::chrono::steady_clock::now();
  const int status = std::system(cmd.c_str());
  CcxRun r;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::ifstream lin(dir / (tag + ".log"));
  std::stringstream ls;
  ls << lin.rdbuf();
  const std::string log = ls.str();
  if (status != 0 || log.find("*ERROR") != std::string::npos)
    throw std::runtime_error("ccx failed (exit status " + std::to_string(status) +
                             "; CalculiX is a required package: Debian calculix-ccx) in " + dir.string() + ":\n" + log.substr(log.size() > 1500 ? log.size() - 1500 : 0));
  r.result = fem::read_calculix_dat(dat, c.mesh.num_vertices());
  std::printf("  ccx %s: %d equations, %zu nodes, %zu C3D4, %.2f s wall (load %.2f), deck %s\n",
              tag.c_str(), equations, c.mesh.num_vertices(), c.mesh.num_tets(), r.seconds,
              load_average(), inp.string().c_str());
  if (std::abs(r.result.time - 1.0) > 1e-9) throw std::runtime_error("ccx stopped before the step's end");
  return r;
}

// max over the tie of |u_B,k - sum w u_A| (ua, ub: per-mesh vectors).
double tie_residual(const TieCondensation& tie, const Eigen::VectorXd& ua, const Eigen::VectorXd& ub) {
  double r = 0.0;
  for (std::size_t k = 0; k < tie.tied_nodes().size(); ++k) {
    Vec3 d = ub.segment<3>(3 * tie.tied_nodes()[k]);
    for (int j = 0; j < 3; ++j) d -= tie.weights()[k][j] * ua.segment<3>(3 * tie.host_nodes()[k][j]);
    r = std::max(r, d.norm());
  }
  return r;
}

struct Comparison {
  double rel_a{0.0}, rel_b{0.0}, rel{0.0};  // max |u - u_ccx| / max |u_ccx| (A, B, both)
  double max_u_m{0.0};
  double tie_ours_m{0.0}, tie_ccx_m{0.0};
  // max over dofs of |u - u_ccx| in units of the last digit ccx printed (.dat: 7 significant
  // digits, d.dddddd E+xx): <= 0.5 when the difference is ccx's print rounding alone.
  double print_ulps{0.0};
};

double print_ulp(double x) {
  return x == 0.0 ? 1e-300 : std::pow(10.0, std::floor(std::log10(std::abs(x))) - 6.0);
}

Comparison compare(const Combined& c, const TieCondensation& tie, const Eigen::VectorXd& ua,
                   const Eigen::VectorXd& ub, const Eigen::VectorXd& u_ccx) {
  Comparison out;
  out.max_u_m = u_ccx.cwiseAbs().maxCoeff();
  double ea = 0.0, eb = 0.0;
  Eigen::VectorXd ca = Eigen::VectorXd::Zero(ua.size()), cb = Eigen::VectorXd::Zero(ub.size());
  const double floor_m = 1e-12 * out.max_u_m;
  for (std::size_t v = 0; v < c.id_a.size(); ++v) {
    if (c.id_a[v] < 0) continue;
    ca.segment<3>(3 * v) = u_ccx.segment<3>(3 * c.id_a[v]);
    ea = std::max(ea, (ua.segment<3>(3 * v) - ca.segment<3>(3 * v)).cwiseAbs().maxCoeff());
    for (int k = 0; k < 3; ++k)
      out.print_ulps = std::max(out.print_ulps, std::abs(ua[3 * v + k] - ca[3 * v + k]) / std::max(print_ulp(ca[3 * v + k]), floor_m));
  }
  for (std::size_t v = 0; v < c.id_b.size(); ++v) {
    cb.segment<3>(3 * v) = u_ccx.segment<3>(3 * c.id_b[v]);
    eb = std::max(eb, (ub.segment<3>(3 * v) - cb.segment<3>(3 * v)).cwiseAbs().maxCoeff());
    for (int k = 0; k < 3; ++k)
      out.print_ulps = std::max(out.print_ulps, std::abs(ub[3 * v + k] - cb[3 * v + k]) / std::max(print_ulp(cb[3 * v + k]), floor_m));
  }
  out.rel_a = ea / out.max_u_m;
  out.rel_b = eb / out.max_u_m;
  out.rel = std::max(out.rel_a, out.rel_b);
  out.tie_ours_m = tie_residual(tie, ua, ub);
  out.tie_ccx_m = tie_residual(tie, ca, cb);
  return out;
}

void run_case(const std::string& tag, double axis_z_m, double load_scale) {
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const scene::Scene s = cube_cylinder(axis_z_m);
  const scene::Model model = scene::compile(s, path.string());
  const auto sim = Simulation::build(model);
  const int cube = scene::find_mesh(s, "cube");
  const CoupledBody& body = *sim->body_of(cube);
  ASSERT_EQ(body.ties().size(), 1u);
  const TieCondensation& tie = body.ties()[0];
  const mesh::TetMesh& a = body.host();
  const mesh::TetMesh& b = tie.geometry();
  const fem::Material ma = model.meshes[cube].material;
  ASSERT_EQ(ma.element, fem::Element::kLinearTet);
  ASSERT_EQ(tie.material().element, fem::Element::kLinearTet);
  const std::vector<int>& fixed_a = body.host_solver().fixed_nodes();
  const Combined c = combine(a, ma, b, tie.material());

  // Loads: B's exposed top (z > 0.117 m, |y - 50 mm| < 12 mm) when raised; A's top face around
  // (20, 50) mm and its +x face around (y, z) = (50, 50) mm. Total per group ~ load_scale N.
  Eigen::VectorXd fa = Eigen::VectorXd::Zero(3 * a.num_vertices());
  Eigen::VectorXd fb = Eigen::VectorXd::Zero(3 * b.num_vertices());
  std::vector<int> top_b, top_a, side_a;
  for (int v : b.surface_vertices()) {
    const Vec3& x = b.vertices()[v];
    if (x.z() > 0.117 && std::abs(x.y() - 0.05) < 0.012) top_b.push_back(v);
  }
  std::vector<char> fixed(a.num_vertices(), 0);
  for (int v : fixed_a) fixed[v] = 1;
  for (int v : a.surface_vertices()) {
    const Vec3& x = a.vertices()[v];
    if (fixed[v]) continue;
    if (std::abs(x.z() - 0.1) < 1e-9 && std::hypot(x.x() - 0.02, x.y() - 0.05) < 0.012) top_a.push_back(v);
    if (std::abs(x.x() - 0.1) < 1e-9 && std::hypot(x.y() - 0.05, x.z() - 0.05) < 0.012) side_a.push_back(v);
  }
  for (int v : top_b) fb.segment<3>(3 * v) = load_scale / top_b.size() * Vec3(0.25, 0.0, -1.0);
  for (int v : top_a) fa.segment<3>(3 * v) = 0.5 * load_scale / top_a.size() * Vec3(0.0, 0.1, -1.0);
  for (int v : side_a) fa.segment<3>(3 * v) = load_scale / side_a.size() * Vec3(-1.0, 0.0, 0.2);
  std::printf("%s (axis z %.3f m): A %zu nodes (%zu used), %zu tets, %zu fixed; B %zu nodes, %zu "
              "tets, %zu fixed; tie %zu nodes; loaded: B top %zu, A top %zu, A +x %zu nodes; scale "
              "%.3g N\n",
              tag.c_str(), axis_z_m, a.num_vertices(), c.mesh.num_vertices() - b.num_vertices(),
              a.num_tets(), fixed_a.size(), b.num_vertices(), b.num_tets(), tie.fixed_nodes().size(),
              tie.tied_nodes().size(), top_b.size(), top_a.size(), side_a.size(), load_scale);
  ASSERT_FALSE(top_a.empty());
  ASSERT_FALSE(side_a.empty());

  // The deck's loads (combined numbering).
  fem::CalculixLoads loads;
  loads.forces_n = Eigen::VectorXd::Zero(3 * c.mesh.num_vertices());
  for (std::size_t v = 0; v < a.num_vertices(); ++v)
    if (c.id_a[v] >= 0) loads.forces_n.segment<3>(3 * c.id_a[v]) = fa.segment<3>(3 * v);
  for (std::size_t v = 0; v < b.num_vertices(); ++v) loads.forces_n.segment<3>(3 * c.id_b[v]) = fb.segment<3>(3 * v);
  for (int v : fixed_a)
    if (c.id_a.at(v) >= 0) loads.fixed_nodes.push_back(c.id_a[v]);  // carved-out nodes dropped
  for (int v : tie.fixed_nodes()) loads.fixed_nodes.push_back(c.id_b.at(v));

  // LINEAR: ours (tied compliance, superposed) against ccx linear.
  {
    Eigen::VectorXd ua1, ub1, ua2, ub2;
    const auto t0 = std::chrono::steady_clock::now();
    body.coupled_displacement(fa, ua1);
    tie.displacement(ua1, ub1);
    body.tied_mesh_displacement(0, fb, ua2, ub2);
    const double ours_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const Eigen::VectorXd ua = ua1 + ua2, ub = ub1 + ub2;
    const CcxRun r = run_tied_ccx(tag + "_linear", c, tie, loads);
    const Comparison cmp = compare(c, tie, ua, ub, r.result.displacement_m);
    std::printf("  LINEAR: max |u_ccx| %.4f mm; max |u - u_ccx| / max |u_ccx|: A %.2e, B %.2e "
                "(%.2f of ccx's last printed digit); tie residual ours %.2e m, ccx %.2e m; ours %.3f s\n",
                1e3 * cmp.max_u_m, cmp.rel_a, cmp.rel_b, cmp.print_ulps, cmp.tie_ours_m, cmp.tie_ccx_m, ours_s);
    EXPECT_LE(cmp.rel, 1e-6) << tag;
    EXPECT_LE(cmp.print_ulps, 1.0) << tag;
    EXPECT_LE(cmp.tie_ours_m, 1e-12 * cmp.max_u_m) << tag;
  }
  // NONLINEAR: the tier's stacked equilibrium under the same forces against ccx NLGEOM.
  {
    fem::EquilibriumSolver solver(equilibrium_definition(body, ma, fixed_a, fem::Tier::kNonlinear));
    Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
    f.segment(solver.body_offset(0), fa.size()) = fa;
    f.segment(solver.body_offset(1), fb.size()) = fb;
    fem::NewtonOptions no;
    no.tolerance = 1e-12;
    const auto t0 = std::chrono::steady_clock::now();
    const fem::EquilibriumResult res = solver.solve(f, no);
    const double ours_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    int iterations = 0;
    for (const auto& inc : res.increments) iterations += static_cast<int>(inc.residual_n.size()) - 1;
    const Eigen::VectorXd ua = res.displacement_m.segment(solver.body_offset(0), fa.size());
    const Eigen::VectorXd ub = res.displacement_m.segment(solver.body_offset(1), fb.size());
    fem::CalculixLoads nl = loads;
    nl.step.neo_hookean_nlgeom = true;
    nl.step.increments = 10;
    const CcxRun r = run_tied_ccx(tag + "_nlgeom", c, tie, nl);
    const Comparison cmp = compare(c, tie, ua, ub, r.result.displacement_m);
    // The linear answer for scale (how nonlinear the case is).
    Eigen::VectorXd ua1, ub1, ua2, ub2;
    body.coupled_displacement(fa, ua1);
    tie.displacement(ua1, ub1);
    body.tied_mesh_displacement(0, fb, ua2, ub2);
    const Comparison lin = compare(c, tie, ua1 + ua2, ub1 + ub2, r.result.displacement_m);
    std::printf("  NONLINEAR: max |u_ccx| %.4f mm; max |u - u_ccx| / max |u_ccx|: A %.2e, B %.2e "
                "(%.2f of ccx's last printed digit; LINEAR vs NLGEOM: %.2e); tie residual ours %.2e m, ccx %.2e m; %zu increments, "
                "%d Newton iterations, %d inverted, %d clamped, max strain %.3f; ours %.3f s\n",
                1e3 * cmp.max_u_m, cmp.rel_a, cmp.rel_b, cmp.print_ulps, lin.rel, cmp.tie_ours_m, cmp.tie_ccx_m,
                res.increments.size(), iterations, res.elements.inverted_elements,
                res.elements.clamped_elements, res.elements.max_strain, ours_s);
    EXPECT_LE(cmp.rel, 1e-6) << tag;
    EXPECT_LE(cmp.print_ulps, 1.0) << tag;
    EXPECT_LE(cmp.tie_ours_m, 1e-12 * cmp.max_u_m) << tag;
  }
}

TEST(interaction_tie_calculix, RaisedCylinderTiedSystemMatchesCalculix) {
  std::printf("load average at start %.2f\n", load_average());
  for (double scale : {1.0, 8.0}) run_case("raised_" + std::to_string(static_cast<int>(1000 * scale)) + "mN", 0.105, scale);
}

TEST(interaction_tie_calculix, EnclosedCylinderTiedSystemMatchesCalculix) {
  for (double scale : {1.0}) run_case("enclosed_" + std::to_string(static_cast<int>(1000 * scale)) + "mN", 0.05, scale);
}

}  // namespace
}  // namespace neurosim::interaction
