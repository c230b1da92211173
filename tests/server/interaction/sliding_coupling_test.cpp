// EmbeddedCompliance and SlidingCoupling against the embedded mesh's assembled stiffness K_B
// (fem::assemble_stiffness, independent of the solvers they use): with fixed nodes L_B inverts K_B
// on the free dofs; floating, a self-equilibrated load is answered exactly (K_B u = f, no rigid
// part) and a rigid load moves B rigidly by load / kappa; W_B is n_s . L_B(k_s, k_t) n_t,
// symmetric positive definite; B's displacement and the gap follow their formulas; bad pairs,
// forces and anchors are refused naming the coupling.
#include "server/interaction/sliding_coupling.hpp"

#include "fixed_base_box.hpp"
#include "server/fem/assembly.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace neurosim::interaction {
namespace {

constexpr double kCell = 0.006;  // m
constexpr double kEdge = 0.02;   // m

fem::Material tissue(fem::Element element) {
  fem::Material m;
  m.youngs_modulus_pa = 3000.0;
  m.poisson_ratio = 0.45;
  m.name = "vessel";
  m.element = element;
  return m;
}

// Deterministic loads (3N x cols, unit N), no random generator: a fixed pattern of sines.
Eigen::MatrixXd pattern_forces(int dofs, int cols) {
  Eigen::MatrixXd f(dofs, cols);
  for (int c = 0; c < cols; ++c)
    for (int i = 0; i < dofs; ++i) f(i, c) = 1e-3 * std::sin(0.37 * i + 1.3 * c + 0.1);
  return f;
}

// The six rigid modes of the mesh (3N x 6, not orthonormalized), written out independently.
Eigen::MatrixXd rigid_modes(const mesh::TetMesh& mesh) {
  const int nv = static_cast<int>(mesh.num_vertices());
  Eigen::MatrixXd r = Eigen::MatrixXd::Zero(3 * nv, 6);
  for (int v = 0; v < nv; ++v) {
    const mesh::Vec3& x = mesh.vertices()[v];
    for (int a = 0; a < 3; ++a) r(3 * v + a, a) = 1.0;
    r.block<3, 1>(3 * v, 3) = mesh::Vec3(0.0, -x.z(), x.y());  // e_x cross x
    r.block<3, 1>(3 * v, 4) = mesh::Vec3(x.z(), 0.0, -x.x());  // e_y cross x
    r.block<3, 1>(3 * v, 5) = mesh::Vec3(-x.y(), x.x(), 0.0);  // e_z cross x
  }
  return r;
}

// Pairs on B's top face (z = edge) with tilted unit normals and a few initial gaps.
std::vector<SlidingPair> top_pairs(const mesh::TetMesh& mesh, int count) {
  std::vector<SlidingPair> pairs;
  for (int v : mesh.surface_vertices()) {
    if (static_cast<int>(pairs.size()) == count) break;
    if (mesh.vertices()[v].z() < kEdge - 1e-9) continue;
    SlidingPair p;
    p.embedded_node = v;
    p.host_nodes = {0, 1, 2};
    p.weights = {0.2, 0.3, 0.5};
    const double k = static_cast<double>(pairs.size());
    p.normal = mesh::Vec3(0.2 * std::sin(k), 0.2 * std::cos(k), 1.0).normalized();
    p.initial_gap_m = 1e-5 * static_cast<double>(pairs.size() % 3);
    pairs.push_back(p);
  }
  return pairs;
}

class EmbeddedComplianceElements : public ::testing::TestWithParam<fem::Element> {};

TEST_P(EmbeddedComplianceElements, WithFixedNodesInvertsTheStiffnessOnTheFreeDofs) {
  const auto box = fixtures::fixed_base_box(kCell, kEdge);
  const fem::Material mat = tissue(GetParam());
  const EmbeddedCompliance l(box.mesh, mat, box.fixed, 1e-6, "vessel");
  EXPECT_FALSE(l.floating());
  const int dofs = 3 * static_cast<int>(box.mesh.num_vertices());
  const Eigen::MatrixXd f = pattern_forces(dofs, 3);
  Eigen::MatrixXd u;
  l.apply(f, u);
  ASSERT_EQ(u.rows(), dofs);
  ASSERT_TRUE(u.allFinite());
  std::vector<char> fixed(dofs, 0);
  for (int v : box.fixed)
    for (int d = 0; d < 3; ++d) fixed[3 * v + d] = 1;
  const fem::SparseMatrix k =
      fem::assemble_stiffness(box.mesh, fem::MaterialMap::uniform(mat));
  const Eigen::MatrixXd ku = k * u;
  for (int c = 0; c < 3; ++c) {
    double res = 0.0, scale = 0.0;
    for (int i = 0; i < dofs; ++i) {
      if (fixed[i]) {
        EXPECT_EQ(u(i, c), 0.0) << "fixed dof " << i;
        continue;
      }
      res = std::max(res, std::abs(ku(i, c) - f(i, c)));
      scale = std::max(scale, std::abs(f(i, c)));
    }
    EXPECT_LT(res, 1e-9 * scale) << "load case " << c;
  }
}

TEST_P(EmbeddedComplianceElements, FloatingAnswersSelfEquilibratedLoadsExactly) {
  const auto box = fixtures::fixed_base_box(kCell, kEdge);
  const fem::Material mat = tissue(GetParam());
  const double ratio = 1e-6;
  const EmbeddedCompliance l(box.mesh, mat, {}, ratio, "vessel");
  EXPECT_TRUE(l.floating());
  const int nv = static_cast<int>(box.mesh.num_vertices());
  const Eigen::MatrixXd r = rigid_modes(box.mesh);
  // The pattern with its rigid part removed (least squares against the modes): self-equilibrated.
  Eigen::MatrixXd f = pattern_forces(3 * nv, 2);
  f -= r * (r.transpose() * r).ldlt().solve(r.transpose() * f);
  ASSERT_LT((r.transpose() * f).cwiseAbs().maxCoeff(), 1e-12);
  Eigen::MatrixXd u;
  l.apply(f, u);
  ASSERT_TRUE(u.allFinite());
  const fem::SparseMatrix k = fem::assemble_stiffness(box.mesh, fem::MaterialMap::uniform(mat));
  const Eigen::MatrixXd ku = k * u;
  EXPECT_LT((ku - f).cwiseAbs().maxCoeff(), 1e-9 * f.cwiseAbs().maxCoeff());
  // No rigid part: u is orthogonal to every rigid mode.
  for (int c = 0; c < 2; ++c)
    EXPECT_LT((r.transpose() * u.col(c)).cwiseAbs().maxCoeff(),
              1e-9 * r.norm() * u.col(c).norm());

  // A uniform force F on every node (a pure translation load) moves every node by F / kappa,
  // kappa = ratio x mean diagonal of K_B.
  const double kappa = ratio * k.diagonal().mean();
  const mesh::Vec3 force(1e-4, -2e-4, 3e-4);
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(3 * nv, 1);
  for (int v = 0; v < nv; ++v) g.block<3, 1>(3 * v, 0) = force;
  l.apply(g, u);
  for (int v = 0; v < nv; ++v)
    EXPECT_LT((u.block<3, 1>(3 * v, 0) - force / kappa).norm(), 1e-9 * force.norm() / kappa)
        << "node " << v;
}

INSTANTIATE_TEST_SUITE_P(interaction_sliding_coupling, EmbeddedComplianceElements,
                         ::testing::Values(fem::Element::kLinearTet, fem::Element::kSmoothedTet),
                         [](const ::testing::TestParamInfo<fem::Element>& param_info) {
                           return param_info.param == fem::Element::kLinearTet ? "LinearTet"
                                                                               : "SmoothedTet";
                         });

SlidingDefinition definition(const fixtures::FixedBaseBox& box, std::vector<SlidingPair> pairs,
                             bool fixed) {
  SlidingDefinition d;
  d.mesh = 1;
  d.embedded = &box.mesh;
  d.material = tissue(fem::Element::kSmoothedTet);
  if (fixed) d.fixed_nodes = box.fixed;
  d.pairs = std::move(pairs);
  d.what = "SLIDING coupling brain / vessel";
  return d;
}

TEST(interaction_sliding_coupling, CompliancePairsTheNormalsThroughTheEmbeddedCompliance) {
  const auto box = fixtures::fixed_base_box(kCell, kEdge);
  for (bool fixed : {true, false}) {
    SCOPED_TRACE(fixed ? "fixed" : "floating");
    const auto pairs = top_pairs(box.mesh, 7);
    ASSERT_EQ(pairs.size(), 7u);
    const SlidingCoupling s(definition(box, pairs, fixed));
    ASSERT_EQ(s.size(), 7);
    const int dofs = 3 * static_cast<int>(box.mesh.num_vertices());
    Eigen::MatrixXd f = Eigen::MatrixXd::Zero(dofs, s.size()), u;
    for (int t = 0; t < s.size(); ++t)
      f.block<3, 1>(3 * pairs[t].embedded_node, t) = pairs[t].normal;
    s.operator_b().apply(f, u);
    const Eigen::MatrixXd& w = s.compliance();
    double scale = 0.0;
    for (int a = 0; a < s.size(); ++a)
      for (int b = 0; b < s.size(); ++b) {
        const double expect = pairs[a].normal.dot(u.block<3, 1>(3 * pairs[a].embedded_node, b));
        scale = std::max(scale, std::abs(expect));
        EXPECT_NEAR(w(a, b), expect, 1e-9 * std::abs(w(a, a))) << a << ", " << b;
        EXPECT_EQ(w(a, b), w(b, a));
      }
    EXPECT_GT(scale, 0.0);
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(w);
    EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
  }
}

TEST(interaction_sliding_coupling, DisplacementAndGapFollowTheRowForces) {
  const auto box = fixtures::fixed_base_box(kCell, kEdge);
  const auto pairs = top_pairs(box.mesh, 4);
  const SlidingCoupling s(definition(box, pairs, true));
  const int dofs = 3 * static_cast<int>(box.mesh.num_vertices());
  Eigen::VectorXd lambda(4);
  lambda << 0.01, 0.0, 0.02, 0.005;  // N
  Eigen::VectorXd u_b;
  s.displacement(lambda, u_b);
  // -lambda_k n_k on B's node k, through L_B.
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(dofs, 1), u;
  for (int k = 0; k < 4; ++k) f.block<3, 1>(3 * pairs[k].embedded_node, 0) -= lambda[k] * pairs[k].normal;
  s.operator_b().apply(f, u);
  EXPECT_LT((u_b - u.col(0)).cwiseAbs().maxCoeff(), 1e-15 + 1e-12 * u.cwiseAbs().maxCoeff());
  // The row forces push B's nodes inward (against their outward normals): each gap opens.
  for (int k = 0; k < 4; ++k) {
    if (lambda[k] > 0.0) {
      EXPECT_LT(pairs[k].normal.dot(u_b.segment<3>(3 * pairs[k].embedded_node)), 0.0);
    }
  }

  // g_k = n_k . (sum_a w_a u_A,a - u_B,k) + g0_k, with A's triangle nodes 0, 1, 2 moved by hand.
  Eigen::VectorXd u_a = Eigen::VectorXd::Zero(9);
  u_a.segment<3>(0) = mesh::Vec3(1e-4, 0.0, 0.0);
  u_a.segment<3>(3) = mesh::Vec3(0.0, 2e-4, 0.0);
  u_a.segment<3>(6) = mesh::Vec3(0.0, 0.0, 4e-4);
  const mesh::Vec3 ua = 0.2 * mesh::Vec3(1e-4, 0, 0) + 0.3 * mesh::Vec3(0, 2e-4, 0) +
                        0.5 * mesh::Vec3(0, 0, 4e-4);
  for (int k = 0; k < 4; ++k) {
    const double expect =
        pairs[k].normal.dot(ua - u_b.segment<3>(3 * pairs[k].embedded_node)) + pairs[k].initial_gap_m;
    EXPECT_NEAR(s.gap(k, u_a, u_b), expect, 1e-15) << "pair " << k;
  }
}

TEST(interaction_sliding_coupling, RefusesBadPairsForcesAndAnchors) {
  const auto box = fixtures::fixed_base_box(kCell, kEdge);
  const std::string what = "SLIDING coupling brain / vessel";
  auto refused = [&](std::vector<SlidingPair> pairs, const std::string& expect, bool fixed = true,
                     double ratio = 1e-6) {
    SlidingDefinition d = definition(box, std::move(pairs), fixed);
    d.anchor_ratio = ratio;
    const std::string msg = testing::message_of([&] { SlidingCoupling s(std::move(d)); });
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
    EXPECT_NE(msg.find(expect), std::string::npos) << msg;
  };
  refused({}, "no sliding pair");
  const auto good = top_pairs(box.mesh, 3);
  auto bad = good;
  bad[1].embedded_node = static_cast<int>(box.mesh.num_vertices());
  refused(bad, "bad sliding pair 1");
  bad = good;
  bad[2].normal = mesh::Vec3(0.0, 0.0, 2.0);
  refused(bad, "bad sliding pair 2");
  bad = good;
  bad[0].normal = mesh::Vec3(std::numeric_limits<double>::quiet_NaN(), 0.0, 1.0);
  refused(bad, "bad sliding pair 0");
  bad = good;
  bad[1].initial_gap_m = -1e-6;
  refused(bad, "bad sliding pair 1");
  bad = good;
  bad[1].initial_gap_m = std::numeric_limits<double>::infinity();
  refused(bad, "bad sliding pair 1");
  refused(good, "anchor ratio", false, 0.0);
  refused(good, "anchor ratio", false, std::numeric_limits<double>::quiet_NaN());

  const SlidingCoupling s(definition(box, good, true));
  const int dofs = 3 * static_cast<int>(box.mesh.num_vertices());
  Eigen::MatrixXd u;
  EXPECT_THROW(s.operator_b().apply(Eigen::MatrixXd::Zero(dofs - 3, 1), u), std::invalid_argument);
  Eigen::MatrixXd nan_force = Eigen::MatrixXd::Zero(dofs, 1);
  nan_force(4, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(s.operator_b().apply(nan_force, u), std::invalid_argument);
  Eigen::VectorXd ub;
  EXPECT_THROW(s.displacement(Eigen::VectorXd::Zero(2), ub), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::interaction
