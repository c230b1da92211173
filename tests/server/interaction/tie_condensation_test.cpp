// TieCondensation: the condensed stiffness K_add = J^T S_B J applied to a boundary displacement
// equals the force B puts on the host when a full solve of B (fem::StaticSolver) has that
// displacement prescribed on its tied nodes; B's displacement satisfies the tie to round-off
// and equals that full solve; a bad coupling map is refused with a message naming the node.
#include "server/interaction/tie_condensation.hpp"

#include "server/fem/assembly.hpp"
#include "server/mesh/generate.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <memory>
#include <random>

namespace neurosim::interaction {
namespace {

// A fictitious host of kHostNodes nodes: the map uses every other node (odd ids), so a boundary
// slot is never equal to the node id.
constexpr int kHostNodes = 41;

struct TieCase {
  mesh::TetMesh embedded;  // def.embedded points here: the case is never copied
  TieDefinition def;
  std::vector<int> boundary_nodes;  // A ids used by the map, ascending
  std::vector<int> boundary_slot;   // A id -> slot or -1
};

// B: a 30 mm box, E 3 kPa; fixed at z = 0 unless floating; every surface node tied to three
// host nodes with random positive weights.
std::unique_ptr<const TieCase> make_case(bool floating) {
  auto owner = std::make_unique<TieCase>();
  TieCase& c = *owner;
  mesh::MeshingOptions o;
  o.cell_size_m = 0.01;
  o.seed = 3;
  c.embedded = mesh::generate_box({0, 0, 0}, {0.03, 0.03, 0.03}, o).mesh;
  c.def.mesh = 1;
  c.def.embedded = &c.embedded;
  c.def.material.youngs_modulus_pa = 3000.0;
  c.def.material.poisson_ratio = 0.45;
  c.def.material.name = "embedded";
  if (!floating) {
    for (std::size_t v = 0; v < c.embedded.num_vertices(); ++v)
      if (c.embedded.vertices()[v].z() < 1e-9) c.def.fixed_nodes.push_back(static_cast<int>(v));
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.1, 1.0);
  const auto& surface = c.embedded.surface_vertices();
  for (std::size_t k = 0; k < surface.size(); ++k) {
    c.def.surface_nodes.push_back(surface[k]);  // fixed ones included: they must be dropped
    const int j = static_cast<int>(k % 20);
    c.def.tri_nodes.push_back({2 * j + 1, 2 * ((j + 3) % 20) + 1, 2 * ((j + 7) % 20) + 1});
    const double a = unit(rng), b = unit(rng), d = unit(rng);
    c.def.weights.push_back({a / (a + b + d), b / (a + b + d), d / (a + b + d)});
  }
  c.def.max_map_distance_m = 1e-4;
  for (const auto& tri : c.def.tri_nodes)
    c.boundary_nodes.insert(c.boundary_nodes.end(), tri.begin(), tri.end());
  std::sort(c.boundary_nodes.begin(), c.boundary_nodes.end());
  c.boundary_nodes.erase(std::unique(c.boundary_nodes.begin(), c.boundary_nodes.end()),
                         c.boundary_nodes.end());
  c.boundary_slot.assign(kHostNodes, -1);
  for (std::size_t s = 0; s < c.boundary_nodes.size(); ++s)
    c.boundary_slot[c.boundary_nodes[s]] = static_cast<int>(s);
  return owner;
}

// u_s = J u_A written out from the definition (independent of the class).
Eigen::VectorXd tied_values(const TieCondensation& tie, const Eigen::VectorXd& u_host_m) {
  const auto& tied = tie.tied_nodes();
  Eigen::VectorXd u_s = Eigen::VectorXd::Zero(3 * static_cast<int>(tied.size()));
  for (std::size_t k = 0; k < tied.size(); ++k)
    for (int a = 0; a < 3; ++a) {
      const int h = tie.host_nodes()[k][a];
      u_s.segment<3>(3 * static_cast<int>(k)) += tie.weights()[k][a] * u_host_m.segment<3>(3 * h);
    }
  return u_s;
}

// Full solve of B with u_s prescribed on its tied nodes. A floating B is held by its tied nodes
// on z = 0 as fixed nodes (prescribed with their values) and the rest through the solver's
// prescribed-displacement path; a B with fixed nodes by those.
fem::PrescribedSolution full_solve(const TieCase& c, const TieCondensation& tie,
                                   const Eigen::VectorXd& u_s) {
  std::vector<int> support = tie.fixed_nodes();
  if (support.empty()) {
    for (int v : tie.tied_nodes())
      if (c.embedded.vertices()[v].z() < 1e-9) support.push_back(v);
  }
  const fem::StaticSolver solver(c.embedded, fem::MaterialMap::uniform(c.def.material), support);
  return solver.solve_prescribed(tie.tied_nodes(), u_s);
}

void check_against_full_solve(bool floating) {
  const auto owner = make_case(floating);
  const TieCase& c = *owner;
  const TieCondensation tie(c.def, kHostNodes);
  ASSERT_EQ(tie.mesh(), 1);
  ASSERT_EQ(&tie.geometry(), &c.embedded);
  // Every surface node not fixed is tied; the fixed ones are not.
  std::size_t expected = 0;
  for (int v : c.embedded.surface_vertices())
    if (!std::binary_search(c.def.fixed_nodes.begin(), c.def.fixed_nodes.end(), v)) ++expected;
  ASSERT_EQ(tie.tied_nodes().size(), expected);
  ASSERT_EQ(tie.host_nodes().size(), expected);
  for (int v : tie.tied_nodes())
    EXPECT_FALSE(std::binary_search(tie.fixed_nodes().begin(), tie.fixed_nodes().end(), v));

  const int m3 = 3 * static_cast<int>(c.boundary_nodes.size());
  Eigen::MatrixXd k_add = Eigen::MatrixXd::Zero(m3, m3);
  tie.add_stiffness(c.boundary_slot, k_add);
  ASSERT_TRUE(k_add.allFinite());
  EXPECT_LE((k_add - k_add.transpose()).norm(), 1e-10 * k_add.norm()) << "J^T S_B J symmetric";

  std::mt19937 rng(11);
  std::uniform_real_distribution<double> mm(-1e-3, 1e-3);
  for (int trial = 0; trial < 3; ++trial) {
    Eigen::VectorXd u_b(m3);
    for (int r = 0; r < m3; ++r) u_b[r] = mm(rng);
    Eigen::VectorXd u_host = Eigen::VectorXd::Zero(3 * kHostNodes);
    for (std::size_t s = 0; s < c.boundary_nodes.size(); ++s)
      u_host.segment<3>(3 * c.boundary_nodes[s]) = u_b.segment<3>(3 * static_cast<int>(s));
    const Eigen::VectorXd u_s = tied_values(tie, u_host);
    const fem::PrescribedSolution ref = full_solve(c, tie, u_s);

    // K_add u_b = J^T r_s: B's reaction at its tied nodes, spread on A's nodes by the weights.
    Eigen::VectorXd f_ref = Eigen::VectorXd::Zero(m3);
    for (std::size_t k = 0; k < tie.tied_nodes().size(); ++k)
      for (int a = 0; a < 3; ++a)
        f_ref.segment<3>(3 * c.boundary_slot[tie.host_nodes()[k][a]]) +=
            tie.weights()[k][a] * ref.reaction_n.segment<3>(3 * tie.tied_nodes()[k]);
    const Eigen::VectorXd f = k_add * u_b;
    ASSERT_GT(f_ref.norm(), 0.0);
    EXPECT_LE((f - f_ref).norm(), 1e-9 * f_ref.norm()) << "trial " << trial;

    // B's displacement: the tie to round-off, equal to the full solve, zero at fixed nodes,
    // in equilibrium at its interior nodes.
    Eigen::VectorXd u_tied, u_emb;
    tie.tied_displacement(u_host, u_tied);
    EXPECT_LE((u_tied - u_s).norm(), 1e-15 * u_s.norm());
    tie.displacement(u_host, u_emb);
    ASSERT_EQ(u_emb.size(), 3 * static_cast<int>(c.embedded.num_vertices()));
    EXPECT_LE(tie.residual(u_host, u_emb), 1e-12 * u_s.lpNorm<Eigen::Infinity>());
    EXPECT_LE((u_emb - ref.displacement_m).norm(), 1e-9 * ref.displacement_m.norm());
    for (int v : tie.fixed_nodes()) EXPECT_EQ(u_emb.segment<3>(3 * v).norm(), 0.0) << v;
    const Eigen::VectorXd internal =
        fem::assemble_stiffness(c.embedded, fem::MaterialMap::uniform(c.def.material)) * u_emb;
    std::vector<char> constrained(c.embedded.num_vertices(), 0);
    for (int v : tie.tied_nodes()) constrained[v] = 1;
    for (int v : tie.fixed_nodes()) constrained[v] = 1;
    double interior = 0.0;
    int interior_nodes = 0;
    for (std::size_t v = 0; v < constrained.size(); ++v) {
      if (constrained[v]) continue;
      ++interior_nodes;
      interior = std::max(interior, internal.segment<3>(3 * static_cast<int>(v)).norm());
    }
    ASSERT_GT(interior_nodes, 0) << "B has an interior (K_ii not empty)";
    EXPECT_LE(interior, 1e-9 * ref.reaction_n.lpNorm<Eigen::Infinity>());

    // The residual sees a displacement that breaks the tie.
    Eigen::VectorXd broken = u_emb;
    broken[3 * tie.tied_nodes().front() + 1] += 1e-5;
    EXPECT_NEAR(tie.residual(u_host, broken), 1e-5, 1e-12);
  }
}

TEST(interaction_tie_condensation, StiffnessEqualsReactionOfFullSolveWithFixedNodes) {
  check_against_full_solve(false);
}

TEST(interaction_tie_condensation, StiffnessEqualsReactionOfFullSolveFloating) {
  check_against_full_solve(true);
}

TEST(interaction_tie_condensation, BadMapsAreRefusedNamingTheNode) {
  const auto owner = make_case(false);
  const TieCase& good = *owner;
  const int tied = good.def.surface_nodes.back();  // not on z = 0 (surface_vertices ascending)
  ASSERT_FALSE(std::binary_search(good.def.fixed_nodes.begin(), good.def.fixed_nodes.end(), tied));
  auto refused = [&](const TieDefinition& def) {
    return testing::message_of([&] { const TieCondensation t(def, kHostNodes); });
  };
  {
    TieDefinition d = good.def;
    d.embedded = nullptr;
    EXPECT_NE(refused(d).find("no mesh"), std::string::npos) << refused(d);
  }
  {
    TieDefinition d = good.def;
    d.weights.pop_back();
    EXPECT_NE(refused(d).find("sizes differ"), std::string::npos) << refused(d);
  }
  {
    TieDefinition d = good.def;
    d.surface_nodes.back() = static_cast<int>(good.embedded.num_vertices());
    const std::string m = refused(d);
    EXPECT_NE(
        m.find("embedded node " + std::to_string(good.embedded.num_vertices()) + " out of range"),
        std::string::npos)
        << m;
  }
  {
    TieDefinition d = good.def;
    d.tri_nodes.back()[1] = kHostNodes;
    const std::string m = refused(d);
    EXPECT_NE(m.find("bad coupling map entry for embedded node " + std::to_string(tied)),
              std::string::npos)
        << m;
  }
  {
    TieDefinition d = good.def;
    d.weights.back()[2] = std::numeric_limits<double>::quiet_NaN();
    const std::string m = refused(d);
    EXPECT_NE(m.find("bad coupling map entry for embedded node " + std::to_string(tied)),
              std::string::npos)
        << m;
  }
  {
    TieDefinition d = good.def;
    d.weights.back()[0] += 0.1;
    const std::string m = refused(d);
    EXPECT_NE(m.find("weights of embedded node " + std::to_string(tied) + " sum to 1.1"),
              std::string::npos)
        << m;
  }
  {
    TieDefinition d = good.def;  // only fixed nodes left to tie
    d.surface_nodes = d.fixed_nodes;
    d.tri_nodes.resize(d.surface_nodes.size(), {1, 3, 5});
    d.weights.resize(d.surface_nodes.size(), {0.2, 0.3, 0.5});
    EXPECT_NE(refused(d).find("no node of the embedded mesh to tie"), std::string::npos)
        << refused(d);
  }
  // A host node of the map without a boundary slot: refused, never written elsewhere.
  const TieCondensation tie(good.def, kHostNodes);
  std::vector<int> slots = good.boundary_slot;
  slots[tie.host_nodes().front()[0]] = -1;
  const int m3 = 3 * static_cast<int>(good.boundary_nodes.size());
  Eigen::MatrixXd k_add = Eigen::MatrixXd::Zero(m3, m3);
  const std::string m = testing::message_of([&] { tie.add_stiffness(slots, k_add); });
  EXPECT_NE(
      m.find("host node " + std::to_string(tie.host_nodes().front()[0]) + " has no boundary slot"),
      std::string::npos)
      << m;
}

}  // namespace
}  // namespace neurosim::interaction
