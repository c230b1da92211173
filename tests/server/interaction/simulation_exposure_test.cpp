// An embedded mesh that sticks out of its host: the set-up ties only the embedded surface nodes
// inside the host and carves the host around them; tool contact with the exposed part is built in
// the LINEAR tier with a TIE coupling (the tip pressing the raised cylinder's top, across the
// rim, against an independent monolithic solve; relaxing tissue against the analytic held-press
// relaxation) and in the NONLINEAR tier (its equilibrium with loads on the cylinder against the
// linear monolithic solve, the meshes' internal forces and their tangents; a press through a 10
// mm cycle; relaxing tissue against the elastic presses QLV reduces to), with method ITERATIVE
// in LINEAR (against EXACT), with a SLIDING coupling in LINEAR (the tip on the top against the
// sliding system assembled and solved in the test, K against central differences of the force),
// refused where not built (naming what is missing); the bundled scenes load.
#include "server/fem/assembly.hpp"
#include "server/interaction/contact_surface.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/tier_equilibrium.hpp"
#include "server/fem/elastic_forces.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/viscoelastic.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "cube_cylinder_fixtures.hpp"
#include "test_support.hpp"

#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <functional>
#include <initializer_list>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace neurosim::interaction {
namespace {

// The cube/cylinder scene with the cylinder's axis at height z_m (cube_cylinder_fixtures.hpp).
scene::Scene cube_cylinder(double z_m, bool tools) { return testing::cube_cylinder_at(z_m, tools); }

// The cube's contactable triangles as the simulation builds them (its contact slots, its fixed
// nodes, the faces the cylinder covers).
ContactSurface contact_surface(const Simulation& sim, int cube) {
  const CoupledBody& body = *sim.body_of(cube);
  std::vector<int> slot_of(body.host().num_vertices(), -1);
  for (std::size_t v = 0; v < slot_of.size(); ++v)
    slot_of[v] = body.contact_slot(static_cast<int>(v));
  return ContactSurface(ContactSurfaceDefinition{&body.host(), &slot_of, &sim.fixed_nodes(cube),
                                                 &body.covered_faces()});
}

bool on_cube_face(const mesh::Vec3& x) {
  for (int a = 0; a < 3; ++a)
    if (std::abs(x[a]) < 1e-9 || std::abs(x[a] - 0.1) < 1e-9) return true;
  return false;
}

std::array<int, 3> sorted(const std::array<int, 3>& t) {
  std::array<int, 3> f = t;
  std::sort(f.begin(), f.end());
  return f;
}

// Adds the Prony terms to the material of each named mesh of the scene.
void add_kernel(scene::Scene& s, std::initializer_list<const char*> meshes,
                const std::vector<fem::PronyTerm>& terms) {
  for (const char* mesh : meshes)
    for (const auto& t : terms) {
      auto* term = s.mutable_meshes(scene::find_mesh(s, mesh))
                       ->mutable_material()
                       ->mutable_viscoelastic()
                       ->add_terms();
      term->set_g(t.g);
      term->set_tau_s(t.tau_s);
    }
}

// Steps the pose at time t until the force changes by less than 1e-12 relative (at most 200
// steps); the settled force (c: the last step's answer; steps: how many were taken).
Vec3 settle(Simulation& sim, double t, const ToolPose& pose, std::vector<ToolContact>& c,
            int* steps = nullptr) {
  StepStats st;
  Vec3 prev = Vec3::Constant(1e300);
  int k = 1;
  for (; k <= 200; ++k) {
    sim.step_at(t, {pose}, c, st);
    EXPECT_TRUE(st.converged) << "t " << t;
    if (!c[0].force_n.allFinite()) break;
    if ((c[0].force_n - prev).norm() <= 1e-12 * c[0].force_n.norm()) break;
    prev = c[0].force_n;
  }
  if (steps != nullptr) *steps = k;
  return c[0].force_n;
}

std::string build_error(const scene::Model& model, const SimulationOptions& options = {}) {
  try {
    (void)build_model(model, options);
  } catch (const std::exception& ex) {
    return ex.what();
  }
  return {};
}

TEST(interaction_simulation_exposure, CylinderOutOfTheCubeIsRefusedWhereNotBuilt) {
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  // The cylinder (r = 15 mm, axis along y) moved up so that it sticks 20 mm out of the cube's
  // top face (z = 0.1 m): its axis at z = 0.105 m, its top at z = 0.12 m. Tool contact with its
  // exposed part is built with a TIE in the LINEAR and NONLINEAR tiers (elastic or relaxing
  // tissue; method ITERATIVE exists in LINEAR only) and with a SLIDING coupling in LINEAR
  // (elastic, the rows on the rest surface); the rest is refused, naming what is not built.
  {
    scene::Scene s = cube_cylinder(0.105, true);
    add_kernel(s, {"cube", "cylinder"}, {{0.3, 1.0}});
    s.mutable_effects()->set_tier(scene::Effects::LINEAR);
    EXPECT_EQ(build_error(testing::compile_kept(s, path)), "");
    s.mutable_effects()->set_tier(scene::Effects::NONLINEAR);
    EXPECT_EQ(build_error(testing::compile_kept(s, path)), "");
  }
  {
    scene::Scene s = cube_cylinder(0.105, true);
    s.mutable_effects()->set_tier(scene::Effects::NONLINEAR);
    for (int variant = 0; variant < 2; ++variant) {
      if (variant == 0) s.mutable_couplings(0)->set_kind(scene::Coupling::SLIDING);
      else s.mutable_couplings(0)->set_method(scene::Coupling::ITERATIVE);
      const std::string what = build_error(testing::compile_kept(s, path));
      ASSERT_FALSE(what.empty()) << "NONLINEAR variant " << variant << " was accepted";
      EXPECT_NE(what.find(variant == 0 ? "SLIDING" : "ITERATIVE"), std::string::npos) << what;
      s = cube_cylinder(0.105, true);
      s.mutable_effects()->set_tier(scene::Effects::NONLINEAR);
    }
  }
  {
    // SLIDING in LINEAR: built (contact slots on the exposed part, B's own columns).
    scene::Scene s = cube_cylinder(0.105, true);
    s.mutable_couplings(0)->set_kind(scene::Coupling::SLIDING);
    const scene::Model model = testing::compile_kept(s, path);
    EXPECT_EQ(build_error(model), "");
    // The rows iterated on the deformed surface are not built with it (the deformed positions
    // would need the sliding forces' displacement of B): refused, naming scene, mesh and option.
    SimulationOptions o;
    o.contact_geometry_iterations = 2;
    std::string what = build_error(model, o);
    ASSERT_FALSE(what.empty()) << "SLIDING, exposed, iterated rows accepted";
    std::printf("refused as expected: %s\n", what.c_str());
    EXPECT_NE(what.find(path.string()), std::string::npos) << what;
    EXPECT_NE(what.find("embedded mesh cylinder"), std::string::npos) << what;
    EXPECT_NE(what.find("outside host cube"), std::string::npos) << what;
    EXPECT_NE(what.find("not implemented with a SLIDING coupling and "
                        "SimulationOptions.contact_geometry_iterations > 1"),
              std::string::npos)
        << what;
    // Relaxing tissue with SLIDING (the sliding forces have no history): refused.
    add_kernel(s, {"cube", "cylinder"}, {{0.3, 1.0}});
    what = build_error(testing::compile_kept(s, path));
    ASSERT_FALSE(what.empty()) << "SLIDING with viscoelastic terms accepted";
    std::printf("refused as expected: %s\n", what.c_str());
    EXPECT_NE(what.find(path.string()), std::string::npos) << what;
    EXPECT_NE(what.find("cube / cylinder"), std::string::npos) << what;
    EXPECT_NE(what.find("viscoelastic terms with a SLIDING coupling are not implemented"),
              std::string::npos)
        << what;
  }
  {
    // ITERATIVE (the paper's baseline) exists in the LINEAR tier only: built there.
    scene::Scene s = cube_cylinder(0.105, true);
    s.mutable_couplings(0)->set_method(scene::Coupling::ITERATIVE);
    EXPECT_EQ(build_error(testing::compile_kept(s, path)), "");
  }
  // LINEAR and NONLINEAR with TIE (the scene's own coupling): build, with contact slots on the
  // exposed part.
  EXPECT_EQ(build_error(testing::compile_kept(cube_cylinder(0.105, true), path)), "");
  {
    scene::Scene s = cube_cylinder(0.105, true);
    s.mutable_effects()->set_tier(scene::Effects::NONLINEAR);
    EXPECT_EQ(build_error(testing::compile_kept(s, path)), "");
  }

  // Without tools nothing touches the exposed part: the same geometry builds, and only the
  // cylinder's surface nodes inside the cube (z <= 0.1 m + the tolerance) are tied.
  scene::Scene s = cube_cylinder(0.105, false);
  const scene::Model model = testing::compile_kept(s, path);
  EXPECT_EQ(build_error(model), "");
  const auto sim = Simulation::build(model);
  const int cube = scene::find_mesh(s, "cube"), cylinder = scene::find_mesh(s, "cylinder");
  const auto& st = sim->setup_stats();
  EXPECT_GT(st.exposed_nodes, 0);
  EXPECT_GT(st.tied_nodes, 0);
  // The cube is carved around the part inside it (S' is open at the cube's top).
  EXPECT_GT(st.carved_tets, 0);
  const double tolerance_m = 0.1 * model.meshes[cube].mesh.mean_edge_length();
  const CoupledBody* body = sim->body_of(cylinder);
  ASSERT_NE(body, nullptr);
  ASSERT_EQ(body->ties().size(), 1u);
  EXPECT_FALSE(body->has_exposed_contact());  // no tool: no slots on the cylinder
  const auto& tie = body->ties()[0];
  EXPECT_EQ(static_cast<int>(tie.tied_nodes().size()), st.tied_nodes);
  int above = 0;
  for (int v : tie.tied_nodes()) above += sim->mesh(cylinder).vertices()[v].z() > 0.1 + tolerance_m;
  EXPECT_EQ(above, 0) << "tied nodes outside the cube";
  int exposed = 0;
  for (int v : sim->mesh(cylinder).surface_vertices())
    exposed += sim->mesh(cylinder).vertices()[v].z() > 0.1 + tolerance_m;
  EXPECT_EQ(st.exposed_nodes, exposed);
}

TEST(interaction_simulation_exposure, BundledScenesLoad) {
  for (const char* name : {"cube_cylinder.scene", "brain_artery.scene", "brain_skull.scene",
                           "brain_viscoelastic.scene"}) {
    const auto path = neurosim::testing::source_dir() / "scenes" / name;
    const scene::Model model = scene::load_model(path);
    SimulationOptions o;
    o.compliance_cache_dir = neurosim::testing::shared_cache_dir().string();  // once a run
    std::unique_ptr<Simulation> sim;
    EXPECT_EQ(neurosim::testing::message_of([&] { sim = Simulation::build(model, o); }), "")
        << name;
    ASSERT_TRUE(sim) << name;
    const auto& st = sim->setup_stats();
    std::printf("%s: carved tets %d, tied nodes %d, exposed nodes %d\n", name, st.carved_tets,
                st.tied_nodes, st.exposed_nodes);
    EXPECT_EQ(st.exposed_nodes, 0) << name;
  }
}

TEST(interaction_simulation_exposure, EnclosedCylinderLeavesOnlyTheCubesOuterFacesContactable) {
  // The bundled placement (axis at z = 0.05 m, inside): the carved cavity's faces are covered,
  // so every contact node lies on the cube's outer faces and every free node there is one.
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const scene::Scene s = cube_cylinder(0.05, true);
  const auto sim = Simulation::build(testing::compile_kept(s, path));
  const int cube = scene::find_mesh(s, "cube");
  const CoupledBody& body = *sim->body_of(cube);
  ASSERT_FALSE(body.covered_faces().empty());
  const auto& host = body.host();
  const auto& fixed = sim->fixed_nodes(cube);
  int outer = 0;
  for (int v : host.surface_vertices()) {
    const bool free = !std::binary_search(fixed.begin(), fixed.end(), v);
    if (on_cube_face(host.vertices()[v])) {
      outer += free;
      if (free) {
        EXPECT_GE(body.contact_slot(v), 0) << "outer node " << v;
      }
    } else {
      EXPECT_EQ(body.contact_slot(v), -1) << "cavity node " << v;
    }
  }
  EXPECT_EQ(static_cast<int>(body.contact_nodes().size()), outer);
  const ContactSurface surface = contact_surface(*sim, cube);
  for (const auto& t : surface.triangles())
    for (int v : t.node) EXPECT_TRUE(on_cube_face(host.vertices()[v])) << "node " << v;
}

TEST(interaction_simulation_exposure, RingAroundAnExitingCylinderStaysContactable) {
  // The cylinder 20 mm out of the cube's top (no tools: tool contact with it is refused). The
  // groove under it (S') is covered; every face of the cube's top around it is contactable,
  // also those with a node on S' (a rule by node would drop the ring around the exit).
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const scene::Scene s = cube_cylinder(0.105, false);
  const auto sim = Simulation::build(testing::compile_kept(s, path));
  const int cube = scene::find_mesh(s, "cube");
  const CoupledBody& body = *sim->body_of(cube);
  const auto& host = body.host();
  const auto& covered = body.covered_faces();
  ASSERT_FALSE(covered.empty());
  const ContactSurface surface = contact_surface(*sim, cube);
  std::vector<std::array<int, 3>> contactable;
  for (const auto& t : surface.triangles()) {
    contactable.push_back(sorted(t.node));
    EXPECT_FALSE(std::binary_search(covered.begin(), covered.end(), contactable.back()));
  }
  std::sort(contactable.begin(), contactable.end());
  // No contactable face lies inside the cylinder (axis (0.05, y, 0.105) m for y in [0.02, 0.08]
  // m, radius 15 mm; 1 mm margin for its coarse polygon): the host is carved where B is, so no
  // host face coincides with B's.
  for (const auto& t : surface.triangles()) {
    mesh::Vec3 c = mesh::Vec3::Zero();
    for (int v : t.node) c += host.vertices()[v] / 3.0;
    const double r = std::hypot(c.x() - 0.05, c.z() - 0.105);
    EXPECT_FALSE(c.y() > 0.021 && c.y() < 0.079 && r < 0.015 - 0.001)
        << "contactable face inside the cylinder, centroid " << c.transpose();
  }
  const auto& boundary = body.boundary_nodes();
  int top = 0, ring = 0;
  for (const auto& tri : host.surface()) {
    bool in_top = true, on_boundary = false;
    for (int v : tri) {
      in_top = in_top && std::abs(host.vertices()[v].z() - 0.1) < 1e-9;
      on_boundary = on_boundary || std::binary_search(boundary.begin(), boundary.end(), v);
    }
    if (!in_top) continue;
    ++top;
    ring += on_boundary;
    EXPECT_TRUE(std::binary_search(contactable.begin(), contactable.end(),
                                   sorted({tri[0], tri[1], tri[2]})))
        << "top face " << tri[0] << " " << tri[1] << " " << tri[2];
  }
  EXPECT_GT(top, 0);
  EXPECT_GT(ring, 0);  // the ring around the exit touches S'
  std::printf("cube top: %d faces contactable, %d of them with a node on S'\n", top, ring);
  // Its nodes' normals point out of the top, not into the groove.
  for (std::size_t k = 0; k < body.contact_nodes().size(); ++k) {
    const mesh::Vec3& x = host.vertices()[body.contact_nodes()[k]];
    if (std::abs(x.z() - 0.1) < 1e-9 && x.x() > 1e-9 && x.x() < 0.1 - 1e-9 && x.y() > 1e-9 &&
        x.y() < 0.1 - 1e-9) {
      EXPECT_GT(body.contact_normals()[k].z(), 1.0 - 1e-12) << "node " << body.contact_nodes()[k];
    }
  }
}

// The sparse LU of a KKT matrix solved here, kept for the process with its matrix: a test that
// solves the same system again (another load, another depth or LCP path giving the same rows and
// active set) factors it once. Found only by the same matrix bit for bit (size, pattern, values);
// SparseLU is deterministic, so a kept factor solves as a fresh one would. The last two kept.
using KktLu = Eigen::SparseLU<Eigen::SparseMatrix<double>>;
const KktLu& kkt_lu(Eigen::SparseMatrix<double> kkt, const char* what) {
  struct Kept {
    Eigen::SparseMatrix<double> matrix;
    std::unique_ptr<KktLu> lu;
  };
  static std::deque<Kept> kept;
  kkt.makeCompressed();
  const auto same = [&](const Eigen::SparseMatrix<double>& m) {
    const auto bytes = [](const auto* p, Eigen::Index n) { return sizeof(*p) * static_cast<std::size_t>(n); };
    return m.rows() == kkt.rows() && m.cols() == kkt.cols() && m.nonZeros() == kkt.nonZeros() &&
           std::memcmp(m.outerIndexPtr(), kkt.outerIndexPtr(), bytes(m.outerIndexPtr(), m.cols() + 1)) == 0 &&
           std::memcmp(m.innerIndexPtr(), kkt.innerIndexPtr(), bytes(m.innerIndexPtr(), m.nonZeros())) == 0 &&
           std::memcmp(m.valuePtr(), kkt.valuePtr(), bytes(m.valuePtr(), m.nonZeros())) == 0;
  };
  for (const Kept& k : kept)
    if (same(k.matrix)) return *k.lu;
  auto lu = std::make_unique<KktLu>();
  lu->compute(kkt);
  if (lu->info() != Eigen::Success) throw std::runtime_error(std::string(what) + ": LU failed");
  kept.push_back({std::move(kkt), std::move(lu)});
  if (kept.size() > 2) kept.pop_front();
  return *kept.back().lu;
}

// The monolithic tied system of the cube (A) and the cylinder (B) under assembly: unknowns A's
// 3 N_A dofs, B's 3 N_B, then one Lagrange multiplier per constraint row (scaled to the
// stiffness): the fixed nodes of both meshes and the tie (u_B,k - sum w_a u_A,a = 0), plus any
// rows a test prescribes. One sparse LU, written here: independent of the coupled body's path.
struct TiedKkt {
  TiedKkt(const CoupledBody& body, const fem::SparseMatrix& ka, const fem::SparseMatrix& kb)
      : na3(static_cast<int>(ka.rows())), n(na3 + static_cast<int>(kb.rows())), row(n),
        scale(1e-3 * ka.diagonal().maxCoeff()) {
    for (int k = 0; k < ka.outerSize(); ++k)
      for (fem::SparseMatrix::InnerIterator it(ka, k); it; ++it)
        t.emplace_back(static_cast<int>(it.row()), static_cast<int>(it.col()), it.value());
    for (int k = 0; k < kb.outerSize(); ++k)
      for (fem::SparseMatrix::InnerIterator it(kb, k); it; ++it)
        t.emplace_back(na3 + static_cast<int>(it.row()), na3 + static_cast<int>(it.col()), it.value());
    const auto& tie = body.ties().at(0);
    for (int v : body.host_solver().fixed_nodes())
      for (int a = 0; a < 3; ++a) constrain({{3 * v + a, 1.0}}, 0.0);
    for (int v : tie.fixed_nodes())
      for (int a = 0; a < 3; ++a) constrain({{na3 + 3 * v + a, 1.0}}, 0.0);
    for (std::size_t k = 0; k < tie.tied_nodes().size(); ++k)
      for (int a = 0; a < 3; ++a) {
        std::vector<std::pair<int, double>> terms{{na3 + 3 * tie.tied_nodes()[k] + a, 1.0}};
        for (int j = 0; j < 3; ++j) terms.push_back({3 * tie.host_nodes()[k][j] + a, -tie.weights()[k][j]});
        constrain(terms, 0.0);
      }
  }
  // A constraint row sum w u_dof = rhs; returns its row (its multiplier's index).
  int constrain(const std::vector<std::pair<int, double>>& terms, double rhs) {
    for (const auto& [dof, w] : terms) {
      t.emplace_back(row, dof, scale * w);
      t.emplace_back(dof, row, scale * w);
    }
    g.push_back(scale * rhs);
    return row++;
  }
  // All unknowns (dofs, then multipliers) under the nodal loads f (stacked, n entries).
  Eigen::VectorXd solve(const Eigen::VectorXd& f) const {
    Eigen::SparseMatrix<double> kkt(row, row);
    kkt.setFromTriplets(t.begin(), t.end());
    Eigen::VectorXd rhs(row);
    rhs.head(n) = f;
    for (std::size_t k = 0; k < g.size(); ++k) rhs[n + static_cast<int>(k)] = g[k];
    return kkt_lu(std::move(kkt), "TiedKkt").solve(rhs);
  }
  const int na3, n;
  int row;
  const double scale;
  std::vector<Eigen::Triplet<double>> t;
  std::vector<double> g;  // constraint right-hand sides (scaled)
};

// The raised cylinder (axis at z = 0.105 m: its top 20 mm above the cube's top) with the scene's
// tool, LINEAR tier, TIE: the simulation and the highest surface node of the cylinder's top near
// y = 50 mm (the tip is placed over it).
struct RaisedPress {
  scene::Scene scene;
  scene::Model model;
  std::unique_ptr<Simulation> sim;
  int cube{-1}, cylinder{-1};
  int top_node{-1};
  mesh::Vec3 top_m{mesh::Vec3::Zero()};
  double tip_radius_m{0.0};
  // The tip depth_m past the cylinder's top (unit m), pressed down z with its shaft up.
  ToolPose pose_at(double depth_m) const {
    ToolPose pose;
    pose.tip_m = top_m + Vec3(0.0, 0.0, tip_radius_m - depth_m);
    pose.axis = Vec3::UnitZ();
    return pose;
  }
};

// tier: effects.tier (the scene's own: LINEAR); options: the simulation's; edit: applied to the
// scene before it is compiled (none: the scene as it is).
std::unique_ptr<RaisedPress> raised_press(
    scene::Effects::Tier tier = scene::Effects::LINEAR, const SimulationOptions& options = {},
    const std::function<void(scene::Scene&)>& edit = nullptr) {
  auto p = std::make_unique<RaisedPress>();
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  p->scene = cube_cylinder(0.105, true);
  p->scene.mutable_effects()->set_tier(tier);
  if (edit) edit(p->scene);
  p->model = testing::compile_kept(p->scene, path);
  p->sim = Simulation::build(p->model, options);
  p->cube = scene::find_mesh(p->scene, "cube");
  p->cylinder = scene::find_mesh(p->scene, "cylinder");
  p->tip_radius_m = p->model.tools.at(0).tip_radius_m;
  const auto& cyl = p->sim->mesh(p->cylinder);
  for (int v : cyl.surface_vertices()) {
    const mesh::Vec3& x = cyl.vertices()[v];
    if (std::abs(x.y() - 0.05) > 0.008) continue;
    if (p->top_node < 0 || x.z() > p->top_m.z()) {
      p->top_node = v;
      p->top_m = x;
    }
  }
  return p;
}

// Force of the last step on each mesh of the body: sum of the slot forces on the host's nodes
// and on the tied mesh's nodes (CoupledBody::contact_point), unit N.
void forces_by_mesh(const Simulation& sim, int host, mesh::Vec3& on_host, mesh::Vec3& on_tied) {
  std::vector<int> slots;
  std::vector<Vec3> forces;
  sim.last_contact_forces(host, slots, forces);
  on_host.setZero();
  on_tied.setZero();
  const CoupledBody& body = *sim.body_of(host);
  for (std::size_t k = 0; k < slots.size(); ++k)
    (body.contact_point(slots[k]).tie < 0 ? on_host : on_tied) += forces[k];
}

// (a) The tip pressing the exposed top of the raised cylinder: no force above it, a force from
// the first touch (20 um) on, growing with the depth; the answer names the cylinder and its node
// under the tip; the cylinder's field (for the viewers) closes the gap there.
TEST(interaction_simulation_exposure, TipPressingTheRaisedCylindersTopFeelsIt) {
  // Without the tip's near field (the indentation below the cells, which takes most of the depth
  // on the cylinder's coarse cells: TipNearFieldOnTheExposedTopIsTheCylinders), so the field
  // shows the whole depth.
  SimulationOptions o;
  o.contact_near_field = false;
  const auto p = raised_press(scene::Effects::LINEAR, o);
  ASSERT_GE(p->top_node, 0);
  ASSERT_GT(p->top_m.z(), 0.119);  // the cylinder's top, 20 mm above the cube's
  const CoupledBody& body = *p->sim->body_of(p->cylinder);
  ASSERT_TRUE(body.has_exposed_contact());
  std::printf("contact slots: %d on the cube, %zu on the cylinder\n", body.num_host_contact(),
              body.contact_nodes().size() - static_cast<std::size_t>(body.num_host_contact()));
  std::vector<ToolContact> c;
  StepStats st;
  double last = 0.0;
  for (double d : {-0.0002, 0.00002, 0.00025, 0.0005, 0.001}) {
    const ToolPose pose = p->pose_at(d);
    p->sim->step({pose}, c, st);
    ASSERT_TRUE(st.converged) << "depth " << d;
    Vec3 on_host, on_tied;
    forces_by_mesh(*p->sim, p->cube, on_host, on_tied);
    std::printf("d %+.3f mm: F (%.5f, %.5f, %.5f) N, rows %d, on the cylinder's nodes %.5f N, "
                "on the cube's %.5f N\n",
                d * 1e3, c[0].force_n.x(), c[0].force_n.y(), c[0].force_n.z(), st.contact_rows,
                -on_tied.z(), -on_host.z());
    if (d < 0.0) {
      EXPECT_FALSE(c[0].in_contact);
      EXPECT_EQ(c[0].force_n.norm(), 0.0);
      continue;
    }
    ASSERT_TRUE(c[0].in_contact) << "depth " << d;
    EXPECT_GT(c[0].force_n.z(), last) << "depth " << d;
    EXPECT_LT(std::abs(c[0].force_n.x()) + std::abs(c[0].force_n.y()), 0.05 * c[0].force_n.z());
    last = c[0].force_n.z();
    EXPECT_EQ(c[0].mesh, p->cylinder);
    EXPECT_NE(std::find(c[0].nodes.begin(), c[0].nodes.end(), p->top_node), c[0].nodes.end());
    // The force on the tissue is on the cylinder's nodes (the cube under it carries none).
    EXPECT_NEAR(-on_tied.z(), c[0].force_n.z(), 1e-9 * c[0].force_n.z());
    if (d == 0.001) {
      Eigen::VectorXd u;
      p->sim->displacements(p->cylinder, u);
      const double uz = u[3 * p->top_node + 2];
      std::printf("d 1 mm: the top node moved %.4f mm; tie residual %.2e m\n", uz * 1e3,
                  p->sim->tie_residual_m());
      EXPECT_LT(uz, -0.5 * d);
      EXPECT_GT(uz, -1.5 * d);
      EXPECT_LT(p->sim->tie_residual_m(), 1e-12);
    }
  }
}

// The tip's near field (SimulationOptions::contact_near_field: the indentation the cells cannot
// show under the tip, in series with its rows) on the exposed top is the cylinder's: its
// compliance, d / F with it less d / F without it, does not follow the cube's E (the cube 1 and
// 4 MPa, the cylinder 0.1 MPa throughout). Taken from the host's material it fell fourfold.
TEST(interaction_simulation_exposure, TipNearFieldOnTheExposedTopIsTheCylinders) {
  const double d = 0.00025;  // m
  double near_field[2] = {0.0, 0.0}, f_mesh[2] = {0.0, 0.0}, tip_radius_m = 0.0;
  fem::Material cylinder;
  for (int k = 0; k < 2; ++k) {
    const double e_cube = k == 0 ? 1.0e6 : 4.0e6;
    auto edit = [&](scene::Scene& s) {
      s.mutable_meshes(scene::find_mesh(s, "cube"))->mutable_material()->set_youngs_modulus_pa(e_cube);
    };
    double f[2] = {0.0, 0.0};
    for (int on = 0; on < 2; ++on) {
      SimulationOptions o;
      o.contact_near_field = on == 1;
      const auto p = raised_press(scene::Effects::LINEAR, o, edit);
      ASSERT_GE(p->top_node, 0);
      std::vector<ToolContact> c;
      StepStats st;
      const ToolPose pose = p->pose_at(d);
      p->sim->step({pose}, c, st);
      ASSERT_TRUE(st.converged);
      ASSERT_TRUE(c[0].in_contact);
      EXPECT_EQ(c[0].mesh, p->cylinder);
      f[on] = c[0].force_n.z();
      ASSERT_GT(f[on], 0.0);
      cylinder = p->model.meshes[static_cast<std::size_t>(p->cylinder)].material;
      tip_radius_m = p->tip_radius_m;
    }
    near_field[k] = d / f[1] - d / f[0];
    f_mesh[k] = f[0];
    std::printf("cube E %.0f MPa: F %.6f N without the near field, %.6f N with it: near-field "
                "compliance %.4e m/N\n",
                e_cube * 1e-6, f[0], f[1], near_field[k]);
    EXPECT_GT(near_field[k], 0.0);
  }
  // Against Hertz (outside the mesh): a rigid sphere of radius R on the cylinder's top (radius
  // 15 mm, its axis along y), principal radii R' = R R_c / (R + R_c) across the axis and R along
  // it, F = 4/3 E* sqrt(R_e) d^3/2 with R_e = sqrt(R' R) (ellipticity R'/R = 0.83: its factor
  // within 0.1 % of 1), E* = E / (1 - nu^2) of the cylinder. The mesh alone (no near field) is
  // over ten times stiffer here (its cells are several tip radii wide).
  {
    const double r = tip_radius_m, rc = 0.015;
    const double r_e = std::sqrt(r * rc / (r + rc) * r);
    const double e_star = cylinder.youngs_modulus_pa /
                          (1.0 - cylinder.poisson_ratio * cylinder.poisson_ratio);
    const double hertz = 4.0 / 3.0 * e_star * std::sqrt(r_e) * std::pow(d, 1.5);
    std::printf("Hertz %.6f N (R %.1f mm, R_e %.2f mm, E* %.0f Pa); with the near field %.6f N\n",
                hertz, r * 1e3, r_e * 1e3, e_star, d / (near_field[0] + d / f_mesh[0]));
    EXPECT_NEAR(d / (near_field[0] + d / f_mesh[0]), hertz, 0.2 * hertz);
  }
  const double ratio = near_field[1] / near_field[0];
  std::printf("near-field compliance, cube 4 MPa over 1 MPa: %.4f\n", ratio);
  EXPECT_GT(ratio, 0.8);
  EXPECT_LT(ratio, 1.25);
}

// Coupling method ITERATIVE (the paper's baseline: G applied by the boundary iteration inside the
// same coupled solves; LINEAR tier) with the exposed cylinder: the tip pressing its top gives the
// EXACT method's answer to 1e-9 of the force (the iteration stops at 1e-12 relative updates,
// SimulationOptions::iterative_tolerance; the simulation test's bound for a host press), the
// same nodes and the same cylinder field; the exposed slots' columns ran the iteration (counted,
// all converged).
TEST(interaction_simulation_exposure, IterativePressOnTheRaisedCylinderEqualsExact) {
  const auto exact = raised_press();
  const auto iter = raised_press(scene::Effects::LINEAR, {}, [](scene::Scene& s) {
    s.mutable_couplings(0)->set_method(scene::Coupling::ITERATIVE);
  });
  ASSERT_TRUE(iter->sim->body_of(iter->cylinder)->has_exposed_contact());
  ASSERT_EQ(iter->top_node, exact->top_node);
  std::vector<ToolContact> ce, ci;
  StepStats st;
  double worst = 0.0, worst_field = 0.0;
  for (double d : {0.00025, 0.0005, 0.001}) {
    const ToolPose pose = exact->pose_at(d);
    exact->sim->step({pose}, ce, st);
    ASSERT_TRUE(st.converged);
    iter->sim->step({pose}, ci, st);
    ASSERT_TRUE(st.converged);
    ASSERT_TRUE(ci[0].in_contact) << "depth " << d;
    EXPECT_EQ(ci[0].mesh, iter->cylinder);
    EXPECT_EQ(ci[0].nodes, ce[0].nodes) << "depth " << d;
    const double f = ce[0].force_n.norm();
    const double df = (ci[0].force_n - ce[0].force_n).norm() / f;
    Eigen::VectorXd ue, ui;
    exact->sim->displacements(exact->cylinder, ue);
    iter->sim->displacements(iter->cylinder, ui);
    const double du = (ue - ui).cwiseAbs().maxCoeff() / ue.cwiseAbs().maxCoeff();
    std::printf("d %.2f mm: EXACT F %.9f N, ITERATIVE %.9f N: %.2e apart; cylinder field %.2e\n",
                1e3 * d, ce[0].force_n.z(), ci[0].force_n.z(), df, du);
    worst = std::max(worst, df);
    worst_field = std::max(worst_field, du);
  }
  EXPECT_LE(worst, 1e-9);
  EXPECT_LE(worst_field, 1e-9);
  const auto report = iter->sim->iterative_report(iter->cylinder);
  std::printf("ITERATIVE: %d right-hand sides iterated, at most %d iterations, %d unconverged\n",
              report.solves, report.max_iterations, report.unconverged);
  EXPECT_GT(report.solves, 0);
  EXPECT_GT(report.max_iterations, 1);
  EXPECT_EQ(report.unconverged, 0);
  EXPECT_EQ(exact->sim->iterative_report(exact->cylinder).solves, 0);
}

// (a') The same press on relaxing tissue (LINEAR; cube and cylinder with one Prony kernel g, the
// tied body's): held 0.5 mm deep on the exposed top for 5 tau_max, the reaction is the elastic
// one times g(t) (linear viscoelasticity with one kernel, displacement held: the analytic
// answer), the force on the cylinder's nodes. Rows on the rest surface (one geometry pass), as
// the block's analytic comparisons (viscoelastic_history_test.cpp), so the rows do not depend
// on the history.
TEST(interaction_simulation_exposure, HeldPressOnTheRaisedCylindersTopRelaxesAsTheKernel) {
  const std::vector<fem::PronyTerm> terms{{0.3, 0.05}, {0.2, 0.5}};
  SimulationOptions o;
  o.contact_geometry_iterations = 1;
  const auto elastic = raised_press(scene::Effects::LINEAR, o);
  const auto visco = raised_press(scene::Effects::LINEAR, o, [&](scene::Scene& s) {
    add_kernel(s, {"cube", "cylinder"}, terms);
  });
  ASSERT_TRUE(visco->sim->body_of(visco->cylinder)->has_exposed_contact());
  ASSERT_EQ(visco->top_node, elastic->top_node);
  constexpr double kDepth = 0.0005, kDt = 1e-3;
  const ToolPose pose = elastic->pose_at(kDepth);
  std::vector<ToolContact> c;
  StepStats st;
  elastic->sim->step_at(0.0, {pose}, c, st);
  ASSERT_TRUE(st.converged);
  const double f_el = c[0].force_n.z();
  ASSERT_GT(f_el, 1e-3);
  ASSERT_EQ(c[0].mesh, elastic->cylinder);
  fem::Viscoelastic g;
  g.terms = terms;
  double worst = 0.0, last = 0.0;
  for (int k = 0; k <= 2500; ++k) {
    const double t = k * kDt;
    visco->sim->step_at(t, {pose}, c, st);
    ASSERT_TRUE(st.converged) << "t " << t;
    ASSERT_TRUE(std::isfinite(c[0].force_n.z())) << "t " << t;
    EXPECT_EQ(c[0].mesh, visco->cylinder) << "t " << t;
    worst = std::max(worst, std::abs(c[0].force_n.z() - f_el * g.relaxation(t)) / f_el);
    last = c[0].force_n.z();
  }
  // The body's slot forces of a relaxing body are the creep-equivalent ones (the elastic forces
  // giving its displacement): with the displacement held they stay the elastic press's, all on
  // the cylinder's nodes.
  Vec3 on_host, on_tied;
  forces_by_mesh(*visco->sim, visco->cube, on_host, on_tied);
  std::printf("held 0.5 mm on the exposed top: F_el %.6g N, F(2.5 s) %.6g N (g %.4f), worst "
              "|F - F_el g(t)| / F_el %.3g; creep-equivalent force on the cylinder's nodes %.6g "
              "N, on the cube's %.3g N\n",
              f_el, last, g.relaxation(2.5), worst, -on_tied.z(), on_host.norm());
  EXPECT_LT(worst, 1e-3);
  EXPECT_NEAR(-on_tied.z(), f_el, 1e-6 * f_el);
  EXPECT_LT(on_host.norm(), 1e-9 * f_el);
}

// The shaft lying across the cylinder's top (the tip off to the side, above the cube, touching
// nothing): the exposed part's triangles are the shaft's candidates too.
TEST(interaction_simulation_exposure, ShaftAcrossTheRaisedCylindersTopFeelsIt) {
  const auto p = raised_press();
  const double shaft_r = p->model.tools.at(0).shaft_radius_m;
  std::vector<ToolContact> c;
  StepStats st;
  double last = 0.0;
  for (double d : {-0.0002, 0.0002, 0.0005}) {
    ToolPose pose;
    pose.tip_m = Vec3(0.02, p->top_m.y(), p->top_m.z() + shaft_r - d);
    pose.axis = Vec3::UnitX();  // the shaft over the cylinder's top (x = 35..65 mm)
    p->sim->step({pose}, c, st);
    ASSERT_TRUE(st.converged);
    std::printf("shaft d %+.2f mm: F (%.5f, %.5f, %.5f) N, rows %d\n", d * 1e3, c[0].force_n.x(),
                c[0].force_n.y(), c[0].force_n.z(), st.contact_rows);
    if (d < 0.0) {
      EXPECT_FALSE(c[0].in_contact);
      continue;
    }
    ASSERT_TRUE(c[0].in_contact);
    EXPECT_EQ(c[0].mesh, p->cylinder);
    EXPECT_GT(c[0].force_n.z(), last);
    last = c[0].force_n.z();
  }
}

// (b) Against an independent solve: the monolithic tied system (cube + cylinder, the tie as
// constraints, assembled and solved directly here) with the displacements the simulation gives
// at the loaded nodes prescribed. Its reactions there are the forces the tool must put on the
// tissue, and equal the step's slot forces (and their sum the tool's force) at three depths.
TEST(interaction_simulation_exposure, PressOnTheRaisedCylinderEqualsTheMonolithicTiedSolve) {
  const auto p = raised_press();
  const CoupledBody& body = *p->sim->body_of(p->cylinder);
  const auto& tie = body.ties().at(0);
  const mesh::TetMesh& host = body.host();
  const mesh::TetMesh& emb = tie.geometry();
  const int na3 = 3 * static_cast<int>(host.num_vertices());
  const int n = na3 + 3 * static_cast<int>(emb.num_vertices());
  const auto ka = fem::assemble_stiffness(host, fem::MaterialMap::uniform(p->model.meshes[p->cube].material));
  const auto kb = fem::assemble_stiffness(emb, fem::MaterialMap::uniform(tie.material()));
  for (double d : {0.00025, 0.0005, 0.001}) {
    const ToolPose pose = p->pose_at(d);
    std::vector<ToolContact> c;
    StepStats st;
    p->sim->step({pose}, c, st);
    ASSERT_TRUE(st.converged);
    std::vector<int> slots;
    std::vector<Vec3> forces;
    p->sim->last_contact_forces(p->cube, slots, forces);
    ASSERT_FALSE(slots.empty());
    Eigen::VectorXd ua, ub;
    p->sim->displacements(p->cube, ua);
    p->sim->displacements(p->cylinder, ub);
    // The loaded nodes prescribed to the simulation's displacements: their multipliers are the
    // reactions.
    TiedKkt kkt(body, ka, kb);
    std::vector<int> loaded_row;
    for (int s : slots) {
      const auto cp = body.contact_point(s);
      const int dof = (cp.tie < 0 ? 0 : na3) + 3 * cp.node;
      loaded_row.push_back(kkt.row);
      for (int a = 0; a < 3; ++a) kkt.constrain({{dof + a, 1.0}}, (cp.tie < 0 ? ua : ub)[3 * cp.node + a]);
    }
    const Eigen::VectorXd x = kkt.solve(Eigen::VectorXd::Zero(n));
    const double scale = kkt.scale;
    // K u + scale C^T mu = 0: the force the prescription puts on a loaded node is -scale mu.
    Vec3 total_ref = Vec3::Zero(), total = Vec3::Zero();
    double worst = 0.0, largest = 0.0;
    for (std::size_t k = 0; k < slots.size(); ++k) {
      const Vec3 ref = -scale * x.segment<3>(loaded_row[k]);
      total_ref += ref;
      total += forces[k];
      worst = std::max(worst, (ref - forces[k]).norm());
      largest = std::max(largest, forces[k].norm());
    }
    std::printf("d %.2f mm: %zu loaded nodes, tool F %.6f N, slot forces %.6f N, monolithic "
                "reactions %.6f N, worst node difference %.2e of the largest node force\n",
                d * 1e3, slots.size(), c[0].force_n.z(), -total.z(), -total_ref.z(), worst / largest);
    EXPECT_LE(worst, 1e-6 * largest) << "depth " << d;
    EXPECT_NEAR(-total_ref.z(), c[0].force_n.z(), 1e-6 * c[0].force_n.z()) << "depth " << d;
  }
}

// (c) No gap across the rim: the tip pressed where the cube's top meets the cylinder's wall
// (0.5 mm into each) is pushed back by both, the force shared by the cube's and the cylinder's
// nodes.
TEST(interaction_simulation_exposure, PressAcrossTheRimFeelsTheCubeAndTheCylinder) {
  const auto p = raised_press();
  // The wall leaves the cube's top (z = 0.1 m) at x = 0.05 + sqrt(15^2 - 5^2) mm; a tip centre
  // at 3 + 15 - 0.5 mm from the cylinder's axis and 3 - 0.5 mm above the cube's top.
  const double r = p->tip_radius_m;
  const double dz = 0.1 + r - 0.0005 - 0.105;
  const double dx = std::sqrt(std::pow(0.015 + r - 0.0005, 2) - dz * dz);
  ToolPose pose;
  pose.tip_m = Vec3(0.05 + dx, 0.05, 0.105 + dz);
  pose.axis = Vec3(1.0, 0.0, 1.0).normalized();  // the shaft away from the wall
  std::vector<ToolContact> c;
  StepStats st;
  p->sim->step({pose}, c, st);
  ASSERT_TRUE(st.converged);
  ASSERT_TRUE(c[0].in_contact);
  Vec3 on_host, on_tied;
  forces_by_mesh(*p->sim, p->cube, on_host, on_tied);
  std::printf("rim press at x %.2f mm: F (%.5f, %.5f, %.5f) N, rows %d; on the cube's nodes "
              "(%.5f, %.5f, %.5f) N, on the cylinder's (%.5f, %.5f, %.5f) N\n",
              pose.tip_m.x() * 1e3, c[0].force_n.x(), c[0].force_n.y(), c[0].force_n.z(),
              st.contact_rows, -on_host.x(), -on_host.y(), -on_host.z(), -on_tied.x(),
              -on_tied.y(), -on_tied.z());
  const double f = c[0].force_n.norm();
  ASSERT_GT(f, 0.0);
  // Both push: the cube's top up, the cylinder's wall outwards (+x) and up.
  EXPECT_GT(on_host.norm(), 0.1 * f);
  EXPECT_GT(on_tied.norm(), 0.1 * f);
  EXPECT_GT(c[0].force_n.x(), 0.1 * f);
  EXPECT_GT(c[0].force_n.z(), 0.1 * f);
  EXPECT_NEAR((-(on_host + on_tied) - c[0].force_n).norm(), 0.0, 1e-9 * f);
}

// ---- SLIDING with the exposed cylinder (LINEAR): the tool on B's exposed top, B's own columns
// reaching the cube through the sliding rows in the same LCP (CoupledBody::expose_slide).

// The monolithic sliding system of the cube (A) and the cylinder (B), assembled and solved here
// (not the simulation's compliances, operators or LCP solvers): unknowns A's 3 N_A dofs, B's
// 3 N_B, B's six rigid-mode amplitudes y (a floating B anchored in its rigid modes only, as
// sliding_coupling.hpp specifies: K_B + kappa R R^T, written [K_B R; R^T -1/kappa] with R B's
// orthonormal rigid modes and kappa = anchor ratio x the mean diagonal of K_B; y = 0 when B has
// fixed nodes), then one multiplier per fixed dof of A and B, per prescribed dof and per active
// sliding row. The sliding rows
// g_k = n_k . (sum_a w_a u_A,a - u_B,k) + g0_k >= 0 with forces lambda_k >= 0 (A pushed along
// +n_k, B along -n_k), by a primal-dual active-set iteration (one sparse LU per set), the answer
// certified by the conditions lambda >= 0, g >= 0, lambda g = 0.
struct SlidingKktAnswer {
  Eigen::VectorXd u_a, u_b, lambda, gap;
  std::vector<double> reactions;  // per prescribed dof: the force the prescription puts there
  int iterations{0};
  bool converged{false};
};

SlidingKktAnswer solve_sliding_kkt(const mesh::TetMesh& a, const fem::Material& ma,
                                   const std::vector<int>& fixed_a, const mesh::TetMesh& b,
                                   const fem::Material& mb, const std::vector<int>& fixed_b,
                                   double anchor_ratio,
                                   const std::vector<SlidingPairState>& pairs,
                                   const std::vector<std::pair<int, double>>& prescribed_b) {
  const fem::SparseMatrix ka = fem::assemble_stiffness(a, fem::MaterialMap::uniform(ma));
  const fem::SparseMatrix kb = fem::assemble_stiffness(b, fem::MaterialMap::uniform(mb));
  const int na3 = static_cast<int>(ka.rows()), nb3 = static_cast<int>(kb.rows());
  const int n = na3 + nb3 + 6;
  const double scale = 1e-3 * ka.diagonal().maxCoeff();
  const double kappa = anchor_ratio * kb.diagonal().mean();
  // B's rigid modes: translations and rotations about its centroid, orthonormalized.
  const auto& xb = b.vertices();
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& x : xb) c += x / static_cast<double>(xb.size());
  Eigen::MatrixXd r = Eigen::MatrixXd::Zero(nb3, 6);
  for (std::size_t v = 0; v < xb.size(); ++v)
    for (int d = 0; d < 3; ++d) {
      r(3 * static_cast<int>(v) + d, d) = 1.0;
      r.block<3, 1>(3 * static_cast<int>(v), 3 + d) = Eigen::Vector3d::Unit(d).cross(xb[v] - c);
    }
  for (int j = 0; j < 6; ++j) {  // Gram-Schmidt, twice
    for (int pass = 0; pass < 2; ++pass)
      for (int i = 0; i < j; ++i) r.col(j) -= r.col(i).dot(r.col(j)) * r.col(i);
    r.col(j).normalize();
  }
  std::vector<Eigen::Triplet<double>> base;
  for (int k = 0; k < ka.outerSize(); ++k)
    for (fem::SparseMatrix::InnerIterator it(ka, k); it; ++it)
      base.emplace_back(static_cast<int>(it.row()), static_cast<int>(it.col()), it.value());
  for (int k = 0; k < kb.outerSize(); ++k)
    for (fem::SparseMatrix::InnerIterator it(kb, k); it; ++it)
      base.emplace_back(na3 + static_cast<int>(it.row()), na3 + static_cast<int>(it.col()),
                        it.value());
  for (int j = 0; j < 6 && !fixed_b.empty(); ++j)  // B held by its fixed nodes: y = 0
    base.emplace_back(na3 + nb3 + j, na3 + nb3 + j, -scale);
  for (int j = 0; j < 6 && fixed_b.empty(); ++j) {
    for (int i = 0; i < nb3; ++i) {
      if (r(i, j) == 0.0) continue;
      base.emplace_back(na3 + i, na3 + nb3 + j, scale * r(i, j));
      base.emplace_back(na3 + nb3 + j, na3 + i, scale * r(i, j));
    }
    base.emplace_back(na3 + nb3 + j, na3 + nb3 + j, -scale * scale / kappa);
  }
  int rows = n;
  std::vector<double> rhs_rows;  // constraint right-hand sides (scaled)
  auto constrain = [&](std::vector<Eigen::Triplet<double>>& t,
                       const std::vector<std::pair<int, double>>& terms, double value) {
    for (const auto& [dof, w] : terms) {
      t.emplace_back(rows, dof, scale * w);
      t.emplace_back(dof, rows, scale * w);
    }
    rhs_rows.push_back(scale * value);
    return rows++;
  };
  for (int v : fixed_a)
    for (int d = 0; d < 3; ++d) constrain(base, {{3 * v + d, 1.0}}, 0.0);
  for (int v : fixed_b)
    for (int d = 0; d < 3; ++d) constrain(base, {{na3 + 3 * v + d, 1.0}}, 0.0);
  std::vector<int> prescribed_row;
  for (const auto& [dof, value] : prescribed_b)
    prescribed_row.push_back(constrain(base, {{na3 + dof, 1.0}}, value));
  const int fixed_rows = rows;
  const std::vector<double> fixed_rhs = rhs_rows;
  // Row k of J: n_k w_a on A's triangle, -n_k at B's node.
  auto row_terms = [&](const SlidingPairState& p) {
    std::vector<std::pair<int, double>> terms;
    for (int q = 0; q < 3; ++q)
      for (int d = 0; d < 3; ++d)
        terms.push_back({3 * p.host_nodes[q] + d, p.weights[q] * p.normal[d]});
    for (int d = 0; d < 3; ++d) terms.push_back({na3 + 3 * p.embedded_node + d, -p.normal[d]});
    return terms;
  };
  const int np = static_cast<int>(pairs.size());
  SlidingKktAnswer out;
  std::vector<char> active(np, 1);
  const double c_pdas = ka.diagonal().maxCoeff();
  for (out.iterations = 1; out.iterations <= 60; ++out.iterations) {
    std::vector<Eigen::Triplet<double>> t = base;
    rows = fixed_rows;
    rhs_rows = fixed_rhs;
    std::vector<int> row_of(np, -1);
    for (int k = 0; k < np; ++k)  // active: g_k = 0, i.e. J_k u = -g0_k
      if (active[k]) row_of[k] = constrain(t, row_terms(pairs[k]), -pairs[k].initial_gap_m);
    Eigen::SparseMatrix<double> kkt(rows, rows);
    kkt.setFromTriplets(t.begin(), t.end());
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(rows);
    for (std::size_t k = 0; k < rhs_rows.size(); ++k) rhs[n + static_cast<int>(k)] = rhs_rows[k];
    const Eigen::VectorXd x = kkt_lu(std::move(kkt), "sliding KKT").solve(rhs);
    out.u_a = x.head(na3);
    out.u_b = x.segment(na3, nb3);
    out.lambda = Eigen::VectorXd::Zero(np);
    out.gap.resize(np);
    // K u + scale C^T mu = f (here 0): a row's force on the dofs is -scale mu C^T, so the
    // sliding force J^T lambda has lambda = -scale mu.
    for (int k = 0; k < np; ++k) {
      if (active[k]) out.lambda[k] = -scale * x[row_of[k]];
      double g = pairs[k].initial_gap_m;
      for (const auto& [dof, w] : row_terms(pairs[k])) g += w * x[dof];
      out.gap[k] = g;
    }
    out.reactions.clear();
    for (int row : prescribed_row) out.reactions.push_back(-scale * x[row]);
    bool changed = false;
    for (int k = 0; k < np; ++k) {
      const char now = out.lambda[k] - c_pdas * out.gap[k] > 0.0 ? 1 : 0;
      changed = changed || now != active[k];
      active[k] = now;
    }
    if (!changed) {
      out.converged = true;
      break;
    }
  }
  return out;
}

// The simulation with the cylinder raised 20 mm out of the cube and coupled by SLIDING (floating:
// the scene's cylinder has no fixed node, so it is anchored in its rigid modes only).
// fixed_end: the cylinder's end cap at y = 20 mm held (B with fixed nodes, not anchored).
std::unique_ptr<RaisedPress> raised_sliding_press(const SimulationOptions& options = {},
                                                  bool fixed_end = false) {
  return raised_press(scene::Effects::LINEAR, options, [&](scene::Scene& s) {
    s.mutable_couplings(0)->set_kind(scene::Coupling::SLIDING);
    if (!fixed_end) return;
    auto* box = s.mutable_meshes(scene::find_mesh(s, "cylinder"))->add_fixed()->mutable_box();
    box->mutable_min_m()->set_x(-1.0);
    box->mutable_min_m()->set_y(-1.0);
    box->mutable_min_m()->set_z(-1.0);
    box->mutable_max_m()->set_x(1.0);
    box->mutable_max_m()->set_y(0.0201);
    box->mutable_max_m()->set_z(1.0);
  });
}

// (d) The tip pressing the exposed top of the SLIDING cylinder against the sliding system
// assembled and solved above: with the displacements the simulation gives at the loaded nodes
// prescribed, the reactions there equal the step's slot forces (and their sum the tool's force),
// the sliding forces equal the step's, and both meshes' fields equal the simulation's, at three
// depths. The cylinder only slides on the cube (it is not bonded): the same press on the TIE
// coupling is at least as stiff. The served LCP path (sliding_inactive_set: W_ss^-1 formed at
// load) holds to 1e-6 (measured 9.4e-9 at the nodes, 3.9e-8 for the sliding forces: the floating
// cylinder's anchored rigid modes make W_ss ill-conditioned); the reference path (principal
// pivoting on W itself) to 1e-10 (measured 6e-13, 1.2e-11). The cylinder with its end cap held
// (fixed nodes: B's compliance from its own factor, no anchor): 1e-10 on the served path.
TEST(interaction_simulation_exposure, PressOnASlidingRaisedCylinderEqualsTheSlidingKkt) {
  SimulationOptions reference_path;
  reference_path.sliding_inactive_set = false;
  const auto tie = raised_press();
  for (int variant = 0; variant < 3; ++variant) {
    const bool served = variant != 1, fixed_end = variant == 2;
    const auto p = raised_sliding_press(served ? SimulationOptions{} : reference_path, fixed_end);
    ASSERT_EQ(p->top_node, tie->top_node);
    const CoupledBody& body = *p->sim->body_of(p->cylinder);
    ASSERT_TRUE(body.ties().empty());
    ASSERT_TRUE(body.has_exposed_slide());
    const SlidingCoupling& sl = *body.exposed_slide(0);
    ASSERT_EQ(sl.mesh(), p->cylinder);
    ASSERT_EQ(sl.operator_b().floating(), !fixed_end);
    ASSERT_EQ(sl.fixed_nodes().empty(), !fixed_end);
    const int on_b = static_cast<int>(body.contact_nodes().size()) - body.num_host_contact();
    std::printf("SLIDING (%s LCP path, %s): %d contact slots on the cube, %d on the cylinder, %d "
                "sliding rows\n",
                served ? "served" : "reference", fixed_end ? "end cap held" : "floating",
                body.num_host_contact(), on_b, body.sliding().size());
    ASSERT_GT(on_b, 0);
    const double tol = variant == 0 ? 1e-6 : 1e-10;
    double last = 0.0;
    for (double d : {0.00025, 0.0005, 0.001}) {
      if (variant > 0 && d != 0.001) continue;
      const ToolPose pose = p->pose_at(d);
      std::vector<ToolContact> c, ct;
      StepStats st;
      p->sim->step({pose}, c, st);
      ASSERT_TRUE(st.converged) << "depth " << d;
      ASSERT_TRUE(c[0].in_contact) << "depth " << d;
      EXPECT_EQ(c[0].mesh, p->cylinder);
      EXPECT_NE(std::find(c[0].nodes.begin(), c[0].nodes.end(), p->top_node), c[0].nodes.end());
      EXPECT_GT(c[0].force_n.z(), last) << "depth " << d;
      last = c[0].force_n.z();
      tie->sim->step({pose}, ct, st);
      ASSERT_TRUE(st.converged);
      std::vector<int> slots;
      std::vector<Vec3> forces;
      p->sim->last_contact_forces(p->cube, slots, forces);
      ASSERT_FALSE(slots.empty());
      std::vector<SlidingPairState> pairs;
      p->sim->sliding_pairs(p->cylinder, pairs);
      ASSERT_EQ(static_cast<int>(pairs.size()), sl.size());
      Eigen::VectorXd ua, ub;
      p->sim->displacements(p->cube, ua);
      p->sim->displacements(p->cylinder, ub);
      std::vector<std::pair<int, double>> prescribed;
      for (int s : slots) {
        const auto cp = body.contact_point(s);
        ASSERT_EQ(cp.slide, 0) << "a loaded slot off the cylinder, slot " << s;
        for (int a = 0; a < 3; ++a) prescribed.push_back({3 * cp.node + a, ub[3 * cp.node + a]});
      }
      const auto t0 = std::chrono::steady_clock::now();
      const SlidingKktAnswer ref =
          solve_sliding_kkt(p->sim->mesh(p->cube), p->model.meshes[p->cube].material,
                            p->sim->fixed_nodes(p->cube), p->sim->mesh(p->cylinder), sl.material(),
                            sl.fixed_nodes(), SimulationOptions{}.sliding_anchor_ratio, pairs,
                            prescribed);
      const double kkt_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      ASSERT_TRUE(ref.converged) << "depth " << d;
      // Certified: forces >= 0, gaps >= 0, complementary (to round-off of the solve).
      const double lmax = std::max(ref.lambda.cwiseAbs().maxCoeff(), 1e-30);
      int active = 0;
      for (int k = 0; k < ref.lambda.size(); ++k) {
        EXPECT_GE(ref.lambda[k], -1e-9 * lmax) << "pair " << k;
        EXPECT_GE(ref.gap[k], -1e-12) << "pair " << k;
        EXPECT_LE(std::abs(ref.lambda[k] * ref.gap[k]), 1e-12 * lmax) << "pair " << k;
        active += ref.lambda[k] > 0.0;
      }
      Vec3 total = Vec3::Zero(), total_ref = Vec3::Zero();
      double worst = 0.0, largest = 0.0;
      for (std::size_t k = 0; k < slots.size(); ++k) {
        const Vec3 r(ref.reactions[3 * k], ref.reactions[3 * k + 1], ref.reactions[3 * k + 2]);
        total += forces[k];
        total_ref += r;
        worst = std::max(worst, (r - forces[k]).norm());
        largest = std::max(largest, forces[k].norm());
      }
      double dl = 0.0, lsim = 0.0;
      for (int k = 0; k < sl.size(); ++k) {
        dl = std::max(dl, std::abs(pairs[k].force_n - ref.lambda[k]));
        lsim = std::max(lsim, pairs[k].force_n);
      }
      const double umax = std::max(ub.cwiseAbs().maxCoeff(), ua.cwiseAbs().maxCoeff());
      const double du =
          std::max((ua - ref.u_a).cwiseAbs().maxCoeff(), (ub - ref.u_b).cwiseAbs().maxCoeff()) /
          umax;
      const double pen = p->sim->sliding_penetration_m();
      std::printf(
          "SLIDING d %.2f mm: tool F %.6f N (TIE %.6f N), %zu loaded nodes, slot forces "
          "%.6f N, KKT reactions %.6f N, worst node %.2e of the largest; sliding forces "
          "%.2e of the largest (%.4f N, %d active of %d, KKT %d sets, %.2f s); fields "
          "%.2e of max |u| %.4f mm; penetration %.2e m\n",
          d * 1e3, c[0].force_n.z(), ct[0].force_n.z(), slots.size(), -total.z(), -total_ref.z(),
          worst / largest, dl / lsim, lsim, active, sl.size(), ref.iterations, kkt_s, du,
          umax * 1e3, pen);
      EXPECT_LE(worst, tol * largest) << "depth " << d;
      EXPECT_NEAR(-total_ref.z(), c[0].force_n.z(), tol * c[0].force_n.z()) << "depth " << d;
      EXPECT_NEAR(-total.z(), c[0].force_n.z(), 1e-9 * c[0].force_n.z()) << "depth " << d;
      EXPECT_LE(dl, tol * lsim) << "depth " << d;
      EXPECT_LE(du, tol) << "depth " << d;
      EXPECT_GT(active, 0);
      EXPECT_LE(pen, tol * umax);
      // Sliding holds the cylinder by normal forces only: no stiffer than the tie.
      EXPECT_LE(c[0].force_n.z(), ct[0].force_n.z() * (1.0 + 1e-9)) << "depth " << d;
      if (variant > 0) continue;
      // The warm step's time, held at this depth, SLIDING and TIE interleaved (printed only).
      std::vector<double> us[2];
      for (int k = 0; k < 400; ++k) {
        Simulation& sim = k % 2 == 0 ? *p->sim : *tie->sim;
        const auto s0 = std::chrono::steady_clock::now();
        sim.step({pose}, k % 2 == 0 ? c : ct, st);
        us[k % 2].push_back(
            1e6 * std::chrono::duration<double>(std::chrono::steady_clock::now() - s0).count());
      }
      for (auto& v : us) std::sort(v.begin(), v.end());
      std::printf("  warm step at %.2f mm: SLIDING p50 %.1f us (p90 %.1f), TIE p50 %.1f us (p90 "
                  "%.1f)\n",
                  d * 1e3, us[0][100], us[0][180], us[1][100], us[1][180]);
    }
  }
}

// K (the stiffness the haptic station gets) on the SLIDING cylinder's top against central
// differences of the step's force in the tip position (h = 0.1 um): the press column within 1 %
// (measured 1.0e-9 and 5.7e-10 at 0.5 and 1 mm: K is -N (W_AA^-1)_gg N^T over the active set,
// the sliding rows of the same LCP free, ContactLcp::contact_stiffness). The whole matrix is
// printed, not asserted: moving the tip across (x) changes F_z by -93 N/m at 0.5 mm where K has
// -0.3, and the TIE coupling's press at the same pose shows the same (the smooth tip's rows on the
// cylinder's curved top, not the coupling).
TEST(interaction_simulation_exposure, SlidingCylinderStiffnessIsTheForcesDerivative) {
  const auto p = raised_sliding_press();
  const double h = 1e-7;
  for (double d : {0.0005, 0.001}) {
    const ToolPose pose = p->pose_at(d);
    std::vector<ToolContact> c;
    StepStats st;
    p->sim->step({pose}, c, st);
    ASSERT_TRUE(st.converged);
    ASSERT_TRUE(c[0].in_contact);
    ASSERT_EQ(c[0].mesh, p->cylinder);
    const Mat3 k = c[0].stiffness_n_per_m;
    Mat3 fd;
    for (int a = 0; a < 3; ++a) {
      ToolPose q = pose;
      q.tip_m[a] += h;
      p->sim->step({q}, c, st);
      ASSERT_TRUE(st.converged);
      const Vec3 plus = c[0].force_n;
      q.tip_m[a] -= 2.0 * h;
      p->sim->step({q}, c, st);
      ASSERT_TRUE(st.converged);
      fd.col(a) = (plus - c[0].force_n) / (2.0 * h);
    }
    std::printf(
        "SLIDING d %.1f mm: K e_z (%.2f %.2f %.2f), dF/dz (%.2f %.2f %.2f) N/m, off %.2e; "
        "whole K %.2e off; K e_x (%.2f %.2f %.2f), dF/dx (%.2f %.2f %.2f)\n",
        d * 1e3, k(0, 2), k(1, 2), k(2, 2), fd(0, 2), fd(1, 2), fd(2, 2),
        (k.col(2) - fd.col(2)).norm() / fd.col(2).norm(), (k - fd).norm() / fd.norm(), k(0, 0),
        k(1, 0), k(2, 0), fd(0, 0), fd(1, 0), fd(2, 0));
    EXPECT_LT(k(2, 2), 0.0);
    EXPECT_LE((k.col(2) - fd.col(2)).norm(), 0.01 * fd.col(2).norm()) << "depth " << d;
  }
}

// ---- The NONLINEAR tier (TierEquilibrium: the exposed part's slots are the cylinder's nodes in
// the stacked equilibrium) against references written here.

// u (stacked: the cube's 3 N_A dofs, then the cylinder's 3 N_B) for the nodal loads f (stacked)
// with stiffnesses ka, kb: the monolithic tied system, fixed nodes and the tie as constraints
// (Lagrange multipliers), one sparse LU. The tier's stiffness at rest (linear) or its tangent.
Eigen::VectorXd monolithic_tied_solve(const CoupledBody& body, const fem::SparseMatrix& ka,
                                      const fem::SparseMatrix& kb, const Eigen::VectorXd& f) {
  const TiedKkt kkt(body, ka, kb);
  return kkt.solve(f).head(kkt.n);
}

struct RaisedTier {
  std::unique_ptr<RaisedPress> p;
  const CoupledBody* body{nullptr};
  fem::Material host_material, tied_material;
  int top_slot{-1};
  TierEquilibriumDefinition def;
};

RaisedTier raised_tier() {
  RaisedTier r;
  r.p = raised_press(scene::Effects::NONLINEAR);
  r.body = r.p->sim->body_of(r.p->cylinder);
  r.host_material = r.p->model.meshes[r.p->cube].material;
  r.tied_material = r.body->ties().at(0).material();
  r.top_slot = r.body->contact_slot(r.body->tie_vertex_offset(0) + r.p->top_node);
  r.def.body = r.body;
  r.def.host_material = r.host_material;
  r.def.host_fixed_nodes = r.body->host_solver().fixed_nodes();
  r.def.tier = fem::Tier::kNonlinear;
  r.def.newton.tolerance = 1e-12;
  return r;
}

// A small load on the cylinder's exposed top (1 mN down, 0.3 mN sideways; ~1 um, and a tenth of
// it): the NONLINEAR equilibrium is the linear tied solve written here (its linearization at
// rest) to 1e-4 of the largest displacement, and 1e-5 at a tenth of the load (the difference is
// the tier's nonlinearity: measured 3.6e-5 and 3.6e-6), at every node of both meshes and at
// every contact slot (the slots on the cylinder read its dofs); the linearization's offset
// u0 = u* - R C R^T f* (C: the columns of the cylinder's slots) vanishes to the same order, with
// the columns kept and with one coupled solve (budget 0).
TEST(interaction_simulation_exposure, NonlinearTierAtASmallLoadIsTheLinearTiedSolve) {
  RaisedTier r = raised_tier();
  ASSERT_GE(r.top_slot, r.body->num_host_contact());
  const int na3 = 3 * static_cast<int>(r.body->host().num_vertices());
  const auto& emb = r.body->ties()[0].geometry();
  for (double scale_load : {1.0, 0.1}) {
  const Vec3 force = scale_load * Vec3(0.0003, 0.0, -0.001);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(na3 + 3 * static_cast<int>(emb.num_vertices()));
  f.segment<3>(na3 + 3 * r.p->top_node) = force;
  const Eigen::VectorXd ref = monolithic_tied_solve(
      *r.body, fem::assemble_stiffness(r.body->host(), fem::MaterialMap::uniform(r.host_material)),
      fem::assemble_stiffness(emb, fem::MaterialMap::uniform(r.tied_material)), f);
  const double scale = ref.cwiseAbs().maxCoeff();
  ASSERT_GT(scale, 1e-7);
  for (std::size_t budget : {TierEquilibriumDefinition{}.column_budget_bytes, std::size_t{0}}) {
    SCOPED_TRACE("column budget " + std::to_string(budget));
    r.def.column_budget_bytes = budget;
    TierEquilibrium eq(r.def);
    TierLoad load;
    load.slots = {r.top_slot};
    load.forces_n = {force};
    TierLinearization lin;
    eq.update(load, lin);
    ASSERT_EQ(lin.u_m.size(), ref.size());
    double field = 0.0, slots = 0.0, offset = 0.0;
    field = (lin.u_m - ref).cwiseAbs().maxCoeff();
    for (int s = 0; s < eq.num_slots(); ++s) {
      slots = std::max(slots, (lin.displacement_m[s] - ref.segment<3>(eq.slot_dof(s))).norm());
      offset = std::max(offset, lin.offset_m[s].norm());
    }
    std::printf("small load: top of the cylinder moved %.4g um; NONLINEAR - linear tied solve: "
                "field %.2e, slots %.2e, offset u0 %.2e of it; %d Newton iterations\n",
                1e6 * ref.segment<3>(na3 + 3 * r.p->top_node).norm(), field / scale,
                slots / scale, offset / scale, lin.iterations);
    EXPECT_EQ(eq.slot_dof(r.top_slot), na3 + 3 * r.p->top_node);
    EXPECT_LE(field, 1e-4 * scale_load * scale);
    EXPECT_LE(slots, 1e-4 * scale_load * scale);
    EXPECT_LE(offset, 1e-4 * scale_load * scale);
    EXPECT_EQ(eq.linearization_solves(), budget == 0 ? 1u : 0u);
  }
  }
}

// A large load on the exposed top (2 N down, 0.5 N sideways; millimetres): the NONLINEAR
// equilibrium holds against the internal forces computed here from each mesh's own
// fem::ElasticForces (the tied nodes' residual carried to the cube by the tie's weights) to
// 1e-8 of the load; it is not the linear answer; and its response to a load change (central
// differences, +-0.1 %) is the tangent's: the monolithic tied solve with both meshes' tangents
// at u*, each checked itself against central differences of the internal forces along that
// response.
TEST(interaction_simulation_exposure, NonlinearTierAtALargeLoadHoldsAndFollowsItsTangent) {
  RaisedTier r = raised_tier();
  const CoupledBody& body = *r.body;
  const auto& tie = body.ties()[0];
  const auto& emb = tie.geometry();
  const int na3 = 3 * static_cast<int>(body.host().num_vertices());
  const int nb3 = 3 * static_cast<int>(emb.num_vertices());
  const Vec3 force(0.5, 0.0, -2.0);
  TierEquilibrium eq(r.def);
  TierLoad load;
  load.slots = {r.top_slot};
  load.forces_n = {force};
  TierLinearization lin;
  eq.update(load, lin);
  ASSERT_TRUE(lin.converged);
  ASSERT_TRUE(lin.u_m.allFinite());
  const Eigen::VectorXd u = lin.u_m;
  const fem::ElasticForces fa(body.host(), fem::MaterialMap::uniform(r.host_material), fem::Tier::kNonlinear);
  const fem::ElasticForces fb(emb, fem::MaterialMap::uniform(r.tied_material), fem::Tier::kNonlinear);
  // r = T^T (f_int(u) - f_ext) on the free dofs of q (the cube's free dofs, the cylinder's dofs
  // that are neither tied nor fixed).
  auto residual = [&](const Eigen::VectorXd& uu, const Eigen::VectorXd& f_ext) {
    Eigen::VectorXd ra, rb;
    fa.internal_force(uu.head(na3), ra);
    fb.internal_force(uu.tail(nb3), rb);
    ra -= f_ext.head(na3);
    rb -= f_ext.tail(nb3);
    for (std::size_t k = 0; k < tie.tied_nodes().size(); ++k) {
      const int v = tie.tied_nodes()[k];
      for (int j = 0; j < 3; ++j)
        ra.segment<3>(3 * tie.host_nodes()[k][j]) += tie.weights()[k][j] * rb.segment<3>(3 * v);
      rb.segment<3>(3 * v).setZero();
    }
    for (int v : body.host_solver().fixed_nodes()) ra.segment<3>(3 * v).setZero();
    for (int v : tie.fixed_nodes()) rb.segment<3>(3 * v).setZero();
    Eigen::VectorXd out(na3 + nb3);
    out << ra, rb;
    return out;
  };
  Eigen::VectorXd f_ext = Eigen::VectorXd::Zero(na3 + nb3);
  f_ext.segment<3>(na3 + 3 * r.p->top_node) = force;
  const double res = residual(u, f_ext).cwiseAbs().maxCoeff();
  // Not the linear answer.
  const Eigen::VectorXd u_lin = monolithic_tied_solve(
      body, fem::assemble_stiffness(body.host(), fem::MaterialMap::uniform(r.host_material)),
      fem::assemble_stiffness(emb, fem::MaterialMap::uniform(r.tied_material)), f_ext);
  const Vec3 top = u.segment<3>(na3 + 3 * r.p->top_node), top_lin = u_lin.segment<3>(na3 + 3 * r.p->top_node);
  std::printf("large load: top moved (%.4f, %.4f, %.4f) mm (linear (%.4f, %.4f, %.4f) mm), "
              "residual %.2e of the load, %d Newton iterations, %d inverted elements\n",
              1e3 * top.x(), 1e3 * top.y(), 1e3 * top.z(), 1e3 * top_lin.x(), 1e3 * top_lin.y(),
              1e3 * top_lin.z(), res / force.norm(), lin.iterations, lin.inverted_elements);
  EXPECT_LE(res, 1e-8 * force.norm());
  EXPECT_LT(top.z(), -5e-4);
  EXPECT_GT((top - top_lin).norm(), 1e-2 * top_lin.norm());
  EXPECT_EQ(lin.inverted_elements, 0);
  EXPECT_LE((lin.displacement_m[r.top_slot] - top).norm(), 0.0);

  // The response to a load change along z at the top node, by central differences of two
  // further equilibria, against the tangent's monolithic solve.
  const double h = 1e-3 * force.norm();
  Eigen::VectorXd up, down;
  for (double sign : {1.0, -1.0}) {
    TierLoad l = load;
    l.forces_n[0].z() += sign * h;
    TierLinearization o;
    eq.update(l, o);
    ASSERT_TRUE(o.converged);
    (sign > 0 ? up : down) = o.u_m;
  }
  const Eigen::VectorXd du = (up - down) / (2.0 * h);
  fem::SparseMatrix ka, kb;
  fa.tangent(u.head(na3), false, ka);
  fb.tangent(u.tail(nb3), false, kb);
  Eigen::VectorXd e = Eigen::VectorXd::Zero(na3 + nb3);
  e[na3 + 3 * r.p->top_node + 2] = 1.0;
  const Eigen::VectorXd x = monolithic_tied_solve(body, ka, kb, e);
  const double fd = (du - x).cwiseAbs().maxCoeff() / x.cwiseAbs().maxCoeff();
  // The tangents themselves: K x against central differences of the internal forces along x.
  const double step = 1e-4 / x.cwiseAbs().maxCoeff() * 1e-3;  // 0.1 um at the largest entry
  Eigen::VectorXd fp_a, fm_a, fp_b, fm_b;
  fa.internal_force((u + step * x).head(na3), fp_a);
  fa.internal_force((u - step * x).head(na3), fm_a);
  fb.internal_force((u + step * x).tail(nb3), fp_b);
  fb.internal_force((u - step * x).tail(nb3), fm_b);
  const Eigen::VectorXd kx_a = ka * x.head(na3), kx_b = kb * x.tail(nb3);
  const double tangent_a = ((fp_a - fm_a) / (2.0 * step) - kx_a).cwiseAbs().maxCoeff() / kx_a.cwiseAbs().maxCoeff();
  const double tangent_b = ((fp_b - fm_b) / (2.0 * step) - kx_b).cwiseAbs().maxCoeff() / kx_b.cwiseAbs().maxCoeff();
  std::printf("response to a load change: %.4g mm/N at the top (z), central differences vs the "
              "tangent's tied solve %.2e; tangents vs differences of the internal forces: cube "
              "%.2e, cylinder %.2e\n",
              1e3 * x[na3 + 3 * r.p->top_node + 2], fd, tangent_a, tangent_b);
  EXPECT_LE(fd, 1e-4);
  EXPECT_LE(tangent_a, 1e-5);
  EXPECT_LE(tangent_b, 1e-5);
}

// The tool pressing the raised cylinder's top in the NONLINEAR tier (synchronous updates, each
// pose held until the force settles): at 20 um the force is LINEAR's (barycentric rows in both)
// to 2e-3, at 2 um to a fifth of that (the difference is the nonlinearity); down to 10 mm and back in 1 mm steps it stays finite, grows on the way down, returns
// on the way up to the same force at the same depth (elastic: 1e-6), and is zero above the top.
TEST(interaction_simulation_exposure, NonlinearPressOnTheRaisedCylinderThroughATenMillimetreCycle) {
  SimulationOptions o;
  o.tier_worker_thread = false;
  o.tier_newton_tolerance = 1e-12;
  o.contact_spread = 0.0;
  o.contact_smooth_normals = false;
  o.contact_near_field = false;
  const auto p = raised_press(scene::Effects::NONLINEAR, o);
  const auto pl = raised_press(scene::Effects::LINEAR, o);
  auto pose_at = [&](double d) { return p->pose_at(d); };
  std::vector<ToolContact> c;
  StepStats st;
  // Holds a pose until the force changes by less than 1e-10 relative (at most 200 steps).
  auto hold = [&](Simulation& sim, double d, int& steps) {
    Vec3 prev = Vec3::Constant(1e300);
    for (steps = 1; steps <= 200; ++steps) {
      sim.step({pose_at(d)}, c, st);
      EXPECT_TRUE(st.converged) << "depth " << d;
      const Vec3 f = c[0].force_n;
      if ((f - prev).norm() <= 1e-10 * std::max(f.norm(), 1e-300)) break;
      prev = f;
    }
    return c[0].force_n;
  };
  int steps = 0, steps_lin = 0;
  double small[2];
  for (int k = 0; k < 2; ++k) {
    const double d = k == 0 ? 2e-5 : 2e-6;
    const Vec3 fl = hold(*pl->sim, d, steps_lin);
    const Vec3 fn = hold(*p->sim, d, steps);
    small[k] = (fn - fl).norm() / fl.norm();
    std::printf("%.0f um: NONLINEAR F %.6g N (%d steps), LINEAR %.6g N, %+.2e\n", 1e6 * d, fn.z(),
                steps, fl.z(), (fn.z() - fl.z()) / fl.z());
    ASSERT_GT(fl.z(), 0.0);
  }
  // The difference is the tier's nonlinearity (measured 6.1e-4 at 20 um): a tenth at a tenth of
  // the depth.
  EXPECT_LE(small[0], 2e-3);
  EXPECT_LE(small[1], 0.2 * small[0]);
  std::vector<double> down;
  double last = 0.0;
  for (int mm = 1; mm <= 10; ++mm) {
    const Vec3 f = hold(*p->sim, 1e-3 * mm, steps);
    const int rows = st.contact_rows, inverted = st.inverted_elements;
    const Vec3 f_lin = hold(*pl->sim, 1e-3 * mm, steps_lin);
    std::printf("down %2d mm: NONLINEAR F (%.4f, %.4f, %.4f) N, %d steps, rows %d, inverted %d; "
                "LINEAR %.4f N\n",
                mm, f.x(), f.y(), f.z(), steps, rows, inverted, f_lin.z());
    ASSERT_TRUE(f.allFinite()) << mm << " mm";
    EXPECT_EQ(c[0].mesh, p->cylinder);
    EXPECT_GT(f.z(), last) << mm << " mm";
    EXPECT_LT(f.z(), 5.0 * f_lin.z()) << mm << " mm";
    EXPECT_GT(f.z(), 0.2 * f_lin.z()) << mm << " mm";
    last = f.z();
    down.push_back(f.z());
    if (mm == 5) {
      // The fields shown are the tier's equilibrium under the step's slot forces (a fresh
      // fem::EquilibriumSolver from rest, the forces put on the stacked dofs here by each slot's
      // mesh and node): the answer's forces and the fields agree, on both meshes.
      const CoupledBody& body = *p->sim->body_of(p->cube);
      fem::EquilibriumSolver solver(equilibrium_definition(
          body, p->model.meshes[p->cube].material, body.host_solver().fixed_nodes(),
          fem::Tier::kNonlinear));
      std::vector<int> slots;
      std::vector<Vec3> forces;
      p->sim->last_contact_forces(p->cube, slots, forces);
      Eigen::VectorXd load = Eigen::VectorXd::Zero(solver.num_dofs());
      int on_cylinder = 0;
      for (std::size_t k = 0; k < slots.size(); ++k) {
        const auto cp = body.contact_point(slots[k]);
        on_cylinder += cp.tie == 0;
        load.segment<3>(solver.body_offset(cp.tie + 1) + 3 * cp.node) += forces[k];
      }
      const Eigen::VectorXd ref = solver.solve(load).displacement_m;
      Eigen::VectorXd ua, ub;
      p->sim->displacements(p->cube, ua);
      p->sim->displacements(p->cylinder, ub);
      const double scale = ref.cwiseAbs().maxCoeff();
      const double err = std::max((ua - ref.head(ua.size())).cwiseAbs().maxCoeff(),
                                  (ub - ref.tail(ub.size())).cwiseAbs().maxCoeff());
      std::printf("5 mm: %zu loaded slots (%d on the cylinder); fields vs the equilibrium from "
                  "rest %.2e of %.3f mm\n", slots.size(), on_cylinder, err / scale, 1e3 * scale);
      EXPECT_GT(on_cylinder, 0);
      EXPECT_LE(err, 1e-8 * scale);
    }
  }
  for (int mm = 9; mm >= 1; --mm) {
    const Vec3 f = hold(*p->sim, 1e-3 * mm, steps);
    std::printf("up %2d mm: NONLINEAR F %.6f N (down %.6f N), %d steps\n", mm, f.z(),
                down[static_cast<std::size_t>(mm - 1)], steps);
    ASSERT_TRUE(f.allFinite()) << mm << " mm";
    EXPECT_NEAR(f.z(), down[static_cast<std::size_t>(mm - 1)], 1e-6 * down[static_cast<std::size_t>(mm - 1)]) << mm << " mm";
  }
  const Vec3 f = hold(*p->sim, -0.0002, steps);
  EXPECT_FALSE(c[0].in_contact);
  EXPECT_EQ(f.norm(), 0.0);
}

// The server's mode (the tier's updates on the worker thread, refactorizations in the
// background): a 3 mm press on the raised cylinder's top reaches the synchronous answer (1e-9).
// Settled: at least one update done and the force still for a second; at most a minute (a
// bound on the wait, not an assertion on time).
TEST(interaction_simulation_exposure, NonlinearWorkerThreadReachesTheSynchronousAnswer) {
  SimulationOptions sync_options;
  sync_options.tier_worker_thread = false;
  sync_options.tier_newton_tolerance = 1e-12;
  SimulationOptions worker_options;
  worker_options.tier_newton_tolerance = 1e-12;
  const auto ps = raised_press(scene::Effects::NONLINEAR, sync_options);
  const auto pw = raised_press(scene::Effects::NONLINEAR, worker_options);
  const ToolPose pose = ps->pose_at(0.003);
  std::vector<ToolContact> c;
  StepStats st;
  Vec3 prev = Vec3::Constant(1e300);
  for (int k = 0; k < 200; ++k) {
    ps->sim->step({pose}, c, st);
    if ((c[0].force_n - prev).norm() <= 1e-11 * c[0].force_n.norm()) break;
    prev = c[0].force_n;
  }
  const Vec3 fs = c[0].force_n;
  ASSERT_GT(fs.z(), 0.0);
  prev = Vec3::Zero();
  const auto t0 = std::chrono::steady_clock::now();
  auto still_since = t0;
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60)) {
    pw->sim->step({pose}, c, st);
    const auto now = std::chrono::steady_clock::now();
    if ((c[0].force_n - prev).norm() > 1e-11 * c[0].force_n.norm() ||
        pw->sim->tier_update_rate_hz() == 0.0)
      still_since = now;
    if (now - still_since > std::chrono::seconds(1)) break;
    prev = c[0].force_n;
    std::this_thread::sleep_for(std::chrono::microseconds(1000));
  }
  std::printf("3 mm on the raised cylinder, NONLINEAR: worker %.9g N, synchronous %.9g N\n",
              c[0].force_n.norm(), fs.norm());
  EXPECT_EQ(c[0].mesh, pw->cylinder);
  EXPECT_LE((c[0].force_n - fs).norm(), 1e-9 * fs.norm());
  EXPECT_GT(pw->sim->tier_update_rate_hz(), 0.0);
}

// Relaxing tissue in the NONLINEAR tier (cube and cylinder with the same Prony kernel: quasi-linear
// viscoelasticity per mesh of the stacked equilibrium, TierEquilibrium; the exposed slots' forces
// on the cylinder's dofs). The tip stepped 2 mm into the exposed top at t = 0 and held; each time
// iterated to its fixed point (the steps at one time replace each other's update). QLV with one
// kernel and the displacement held from a step at t = 0 gives S(t) = g(t) S_e(u) for the elastic
// press's own field u (equilibrium and contact unchanged, every stress scaled by g(t): exact for
// the model and for its exponential integrator), so, against two elastic NONLINEAR presses:
//  - at t = 0 the force is the elastic press's (g(0) = 1);
//  - at each t it is F_el g(t) (the Prony shape), decreasing, finite, all on the cylinder's nodes;
//  - after 20 tau_max it is the press on both meshes with every modulus scaled by g_inf (a third
//    simulation, E g_inf; the relaxed limit of QLV, exact).
TEST(interaction_simulation_exposure, NonlinearHeldPressOnTheRaisedCylindersTopRelaxesToTheScaledAnswer) {
  const std::vector<fem::PronyTerm> terms{{0.3, 0.05}, {0.2, 0.5}};
  const double g_inf = 1.0 - 0.3 - 0.2;
  SimulationOptions o;
  o.tier_worker_thread = false;  // deterministic: the update runs inside each step
  o.tier_newton_tolerance = 1e-12;
  const auto elastic = raised_press(scene::Effects::NONLINEAR, o);
  const auto relaxed = raised_press(scene::Effects::NONLINEAR, o, [&](scene::Scene& s) {
    for (const char* mesh : {"cube", "cylinder"}) {
      auto* mat = s.mutable_meshes(scene::find_mesh(s, mesh))->mutable_material();
      mat->set_youngs_modulus_pa(g_inf * mat->youngs_modulus_pa());
    }
  });
  const auto visco = raised_press(scene::Effects::NONLINEAR, o, [&](scene::Scene& s) {
    add_kernel(s, {"cube", "cylinder"}, terms);
  });
  ASSERT_TRUE(visco->sim->body_of(visco->cylinder)->has_exposed_contact());
  ASSERT_EQ(visco->top_node, elastic->top_node);
  ASSERT_EQ(relaxed->top_node, elastic->top_node);
  constexpr double kDepth = 0.002;
  const ToolPose pose = elastic->pose_at(kDepth);
  std::vector<ToolContact> c;
  auto settle_at = [&](Simulation& sim, double t, int& steps) {
    return settle(sim, t, pose, c, &steps);
  };
  int steps = 0;
  const Vec3 f_el = settle_at(*elastic->sim, 0.0, steps);
  const Vec3 f_rel = settle_at(*relaxed->sim, 0.0, steps);
  ASSERT_EQ(c[0].mesh, relaxed->cylinder);
  ASSERT_GT(f_el.z(), 0.5);
  fem::Viscoelastic g;
  g.terms = terms;
  const Vec3 f0 = settle_at(*visco->sim, 0.0, steps);
  ASSERT_TRUE(f0.allFinite());
  EXPECT_EQ(c[0].mesh, visco->cylinder);
  const double instant = (f0 - f_el).norm() / f_el.norm();
  std::printf("NONLINEAR 2 mm on the exposed top: elastic %.9f N, relaxing at t = 0 %.9f N (%d "
              "steps): %.2e apart; E g_inf %.9f N = %.9f g_inf F_el (%.2e)\n",
              f_el.z(), f0.z(), steps, instant, f_rel.z(), f_rel.z() / (g_inf * f_el.z()),
              (f_rel - g_inf * f_el).norm() / (g_inf * f_el.norm()));
  EXPECT_LE(instant, 1e-9);
  double worst = 0.0, last = f0.z();
  for (double t : {0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0}) {
    const Vec3 f = settle_at(*visco->sim, t, steps);
    ASSERT_TRUE(f.allFinite()) << "t " << t;
    EXPECT_EQ(c[0].mesh, visco->cylinder) << "t " << t;
    const double shape = (f - g.relaxation(t) * f_el).norm() / f_el.norm();
    worst = std::max(worst, shape);
    std::printf("t %5.2f s: F %.9f N (%d steps), F / F_el %.9f, g(t) %.9f\n", t, f.z(), steps,
                f.z() / f_el.z(), g.relaxation(t));
    EXPECT_LT(f.z(), last) << "t " << t;
    last = f.z();
  }
  Vec3 on_host, on_tied;
  forces_by_mesh(*visco->sim, visco->cube, on_host, on_tied);
  const double end = (c[0].force_n - f_rel).norm() / f_rel.norm();
  std::printf("worst |F(t) - F_el g(t)| / F_el %.2e; after 10 s %.9f N, relaxed answer %.9f N: "
              "%.2e apart; on the cylinder's nodes %.9f N, on the cube's %.3g N\n",
              worst, c[0].force_n.z(), f_rel.z(), end, -on_tied.z(), on_host.norm());
  // Measured: 0 at t = 0, 2.1e-9 (the shape), 4.8e-9 (the relaxed answer).
  EXPECT_LE(worst, 1e-7);
  EXPECT_LE(end, 1e-7);
  EXPECT_NEAR(-on_tied.z(), c[0].force_n.z(), 1e-9 * c[0].force_n.z());
  EXPECT_LT(on_host.norm(), 1e-9 * c[0].force_n.z());
}

// Each mesh with its own kernel (cube g = 0.3 / 0.05 s, g_inf 0.7; cylinder g = 0.3 / 0.05 s,
// 0.2 / 0.5 s, g_inf 0.5): the same 2 mm press stepped on and held. Now the meshes relax at
// different rates and the field moves, but the relaxed limit is still exact for QLV: the elastic
// NONLINEAR press with each mesh's moduli scaled by its own g_inf (measured 5.7e-9 at 40 s = 80
// tau_max). The times are spread to the end: the exponential integrator takes S_e linear over a
// step, so one step across the redistribution (2 s -> 10 s) kept beta (S_e,n+1 - S_e,n) in the
// history, 1.2e-5 off at 10 s. At t = 0 the elastic press. The tip's near field is off (it takes
// the host's material and kernel for rows on the cylinder too).
TEST(interaction_simulation_exposure, NonlinearHeldPressWithAKernelPerMeshRelaxesToEachMeshsScaledAnswer) {
  const std::vector<fem::PronyTerm> cube_terms{{0.3, 0.05}}, cyl_terms{{0.3, 0.05}, {0.2, 0.5}};
  SimulationOptions o;
  o.tier_worker_thread = false;
  o.tier_newton_tolerance = 1e-12;
  o.contact_near_field = false;
  auto with = [](const std::vector<fem::PronyTerm>& terms, double scale) {
    return [terms, scale](scene::Scene& s, const char* mesh) {
      auto* mat = s.mutable_meshes(scene::find_mesh(s, mesh))->mutable_material();
      mat->set_youngs_modulus_pa(scale * mat->youngs_modulus_pa());
      for (const auto& t : terms) {
        auto* term = mat->mutable_viscoelastic()->add_terms();
        term->set_g(t.g);
        term->set_tau_s(t.tau_s);
      }
    };
  };
  const auto elastic = raised_press(scene::Effects::NONLINEAR, o);
  const auto relaxed = raised_press(scene::Effects::NONLINEAR, o, [&](scene::Scene& s) {
    with({}, 0.7)(s, "cube");
    with({}, 0.5)(s, "cylinder");
  });
  const auto visco = raised_press(scene::Effects::NONLINEAR, o, [&](scene::Scene& s) {
    with(cube_terms, 1.0)(s, "cube");
    with(cyl_terms, 1.0)(s, "cylinder");
  });
  ASSERT_EQ(visco->top_node, elastic->top_node);
  const ToolPose pose = elastic->pose_at(0.002);
  std::vector<ToolContact> c;
  auto settle_at = [&](Simulation& sim, double t) { return settle(sim, t, pose, c); };
  const Vec3 f_el = settle_at(*elastic->sim, 0.0);
  const Vec3 f_rel = settle_at(*relaxed->sim, 0.0);
  const Vec3 f0 = settle_at(*visco->sim, 0.0);
  ASSERT_GT(f_el.z(), 0.5);
  double last = f0.z();
  for (double t : {0.02, 0.1, 0.5, 2.0, 5.0, 10.0, 20.0, 40.0}) {
    const Vec3 f = settle_at(*visco->sim, t);
    ASSERT_TRUE(f.allFinite()) << "t " << t;
    EXPECT_EQ(c[0].mesh, visco->cylinder) << "t " << t;
    EXPECT_LT(f.z(), last) << "t " << t;
    last = f.z();
  }
  const double instant = (f0 - f_el).norm() / f_el.norm();
  const double end = (c[0].force_n - f_rel).norm() / f_rel.norm();
  std::printf("kernel per mesh, 2 mm: elastic %.9f N, at t = 0 %.9f N (%.2e); after 40 s %.9f N, "
              "each mesh scaled by its g_inf %.9f N (%.2e)\n",
              f_el.z(), f0.z(), instant, c[0].force_n.z(), f_rel.z(), end);
  EXPECT_LE(instant, 1e-9);
  EXPECT_LE(end, 1e-7);
}
}  // namespace
}  // namespace neurosim::interaction
