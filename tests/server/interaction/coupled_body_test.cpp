// CoupledBody against the monolithic tied system solved directly (tied_box_fixtures.hpp): the
// coupled compliance columns at contact slots, the host displacement for a load on several
// slots and the tied mesh's displacement equal the direct solve; the answer differs from the
// host alone (the tie matters); contact nodes are the free nodes of the surface faces B does not
// cover (nodes on S' included where such a face touches them); a body read
// from the boundary-operator cache gives the same columns; a tied mesh's exposed part
// (expose_tie) gets contact slots whose columns, at every slot, equal the monolithic solve too.
#include "server/interaction/coupled_body.hpp"

#include "server/interaction/contact_columns.hpp"

#include "test_support.hpp"
#include "tied_box_fixtures.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>

namespace neurosim::interaction {
namespace {

using tied_box::make_tied_box;
using tied_box::MonolithicSolver;

std::unique_ptr<CoupledBody> make_body(const tied_box::TiedBox& c, const std::string& cache = {}) {
  auto body = std::make_unique<CoupledBody>(0, c.host, c.host_material, c.host_fixed);
  body->add_tie(c.def);
  // B covers the triangles it is tied to (as the simulation covers S').
  std::vector<mesh::Tri> covered;
  for (const auto& t : c.def.tri_nodes) covered.push_back({t[0], t[1], t[2]});
  body->cover_faces(covered);
  if (!cache.empty()) body->set_cache_dir(cache);
  body->finalize();
  return body;
}

// Every 7th contact slot (spread over the sides of A) and one on S'.
std::vector<int> some_slots(const CoupledBody& body) {
  std::vector<int> slots;
  for (int s = 0; s < static_cast<int>(body.contact_nodes().size()); s += 7) slots.push_back(s);
  // And a node on S' (the top's rim: contactable, tied B pulls on it directly).
  const auto& b = body.boundary_nodes();
  for (int s = 0; s < static_cast<int>(body.contact_nodes().size()); ++s)
    if (std::binary_search(b.begin(), b.end(), body.contact_nodes()[s])) {
      if (std::find(slots.begin(), slots.end(), s) == slots.end()) slots.push_back(s);
      break;
    }
  return slots;
}

TEST(interaction_coupled_body, ContactColumnsEqualTheMonolithicTiedSolve) {
  const auto owner = make_tied_box();
  const auto& c = *owner;
  const auto body = make_body(c);
  const MonolithicSolver mono(c);
  const std::vector<int> slots = some_slots(*body);
  ASSERT_GE(slots.size(), 4u);
  Eigen::MatrixXd x;
  body->solve_contact_columns(slots, x);
  const auto& free = body->host_solver().free_dofs();
  ASSERT_EQ(x.rows(), static_cast<int>(free.size()));
  ASSERT_EQ(x.cols(), 3 * static_cast<int>(slots.size()));
  const int n3 = 3 * static_cast<int>(c.host.num_vertices());
  Eigen::MatrixXd unit = Eigen::MatrixXd::Zero(n3, x.cols());
  for (std::size_t k = 0; k < slots.size(); ++k)
    for (int a = 0; a < 3; ++a)
      unit(3 * body->contact_nodes()[slots[k]] + a, 3 * static_cast<int>(k) + a) = 1.0;
  Eigen::MatrixXd u_full;
  body->coupled_displacement(unit, u_full);
  double tie_effect = 0.0, scale = 0.0;
  for (int col = 0; col < x.cols(); ++col) {
    const auto ref = mono.solve(unit.col(col));
    Eigen::VectorXd ref_free(x.rows());
    for (int r = 0; r < x.rows(); ++r) ref_free[r] = ref.u_host_m[free[r]];
    ASSERT_GT(ref_free.norm(), 0.0);
    EXPECT_LE((x.col(col) - ref_free).norm(), 1e-8 * ref_free.norm()) << "column " << col;
    EXPECT_LE((u_full.col(col) - ref.u_host_m).norm(), 1e-8 * ref.u_host_m.norm())
        << "column " << col;
    const Eigen::VectorXd host_only = body->host_solver().solve(Eigen::VectorXd(unit.col(col)));
    tie_effect = std::max(tie_effect, (host_only - ref.u_host_m).norm());
    scale = std::max(scale, ref.u_host_m.norm());
  }
  // Not a test that the host alone would pass: B changes A's compliance noticeably.
  EXPECT_GT(tie_effect, 1e-2 * scale);
}

TEST(interaction_coupled_body, HostAndTiedDisplacementEqualTheMonolithicTiedSolve) {
  const auto owner = make_tied_box();
  const auto& c = *owner;
  const auto body = make_body(c);
  const MonolithicSolver mono(c);
  const std::vector<int> slots = some_slots(*body);
  std::vector<mesh::Vec3> forces;
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * static_cast<int>(c.host.num_vertices()));
  for (std::size_t k = 0; k < slots.size(); ++k) {
    // Pressing inwards, plus a fixed tangential part (unit N).
    const mesh::Vec3 fk = -0.01 * body->contact_normals()[slots[k]] +
                          0.003 * mesh::Vec3(1.0, -0.5, 0.25) * static_cast<double>(k % 3);
    forces.push_back(fk);
    f.segment<3>(3 * body->contact_nodes()[slots[k]]) += fk;
  }
  Eigen::VectorXd u_host;
  body->host_displacement(slots, forces, u_host);
  const auto ref = mono.solve(f);
  EXPECT_LE((u_host - ref.u_host_m).norm(), 1e-8 * ref.u_host_m.norm());
  ASSERT_EQ(body->ties().size(), 1u);
  Eigen::VectorXd u_emb;
  body->ties()[0].displacement(u_host, u_emb);
  ASSERT_GT(ref.u_embedded_m.norm(), 0.0);
  EXPECT_LE((u_emb - ref.u_embedded_m).norm(), 1e-8 * ref.u_embedded_m.norm());
  EXPECT_THROW(body->host_displacement(slots, {}, u_host), std::invalid_argument);
}

TEST(interaction_coupled_body, ContactNodesAreTheFreeNodesOfTheUncoveredFaces) {
  const auto owner = make_tied_box();
  const auto& c = *owner;
  const auto body = make_body(c);
  const auto& boundary = body->boundary_nodes();
  ASSERT_TRUE(std::is_sorted(boundary.begin(), boundary.end()));
  std::vector<int> expected_boundary;
  std::vector<std::array<int, 3>> covered;
  for (const auto& tri : c.def.tri_nodes) {
    expected_boundary.insert(expected_boundary.end(), tri.begin(), tri.end());
    std::array<int, 3> f = tri;
    std::sort(f.begin(), f.end());
    covered.push_back(f);
  }
  std::sort(expected_boundary.begin(), expected_boundary.end());
  expected_boundary.erase(std::unique(expected_boundary.begin(), expected_boundary.end()),
                          expected_boundary.end());
  EXPECT_EQ(boundary, expected_boundary);
  std::sort(covered.begin(), covered.end());
  covered.erase(std::unique(covered.begin(), covered.end()), covered.end());
  EXPECT_EQ(body->covered_faces(), covered);
  // A node is contactable when it is free and on a surface face B does not cover.
  std::vector<char> on_uncovered(c.host.num_vertices(), 0);
  for (const auto& t : c.host.surface()) {
    std::array<int, 3> f{t[0], t[1], t[2]};
    std::sort(f.begin(), f.end());
    if (std::binary_search(covered.begin(), covered.end(), f)) continue;
    for (int v : t) on_uncovered[v] = 1;
  }
  std::vector<int> expected;
  int boundary_contactable = 0, boundary_covered_only = 0;
  for (int v : c.host.surface_vertices()) {
    if (std::binary_search(c.host_fixed.begin(), c.host_fixed.end(), v)) continue;
    const bool on_boundary = std::binary_search(boundary.begin(), boundary.end(), v);
    if (!on_uncovered[v]) {
      boundary_covered_only += on_boundary;
      continue;
    }
    boundary_contactable += on_boundary;
    expected.push_back(v);
  }
  ASSERT_FALSE(expected.empty());
  // Both kinds occur: S' nodes under B only (the top's inside) and on the top's rim.
  EXPECT_GT(boundary_covered_only, 0);
  EXPECT_GT(boundary_contactable, 0);
  EXPECT_EQ(body->contact_nodes(), expected);
  ASSERT_EQ(body->contact_normals().size(), expected.size());
  for (std::size_t s = 0; s < expected.size(); ++s) {
    EXPECT_EQ(body->contact_slot(expected[s]), static_cast<int>(s));
    EXPECT_NEAR(body->contact_normals()[s].norm(), 1.0, 1e-12);
    // The box's outward normal points away from its centre.
    const mesh::Vec3 out = c.host.vertices()[expected[s]] - mesh::Vec3(0.02, 0.02, 0.02);
    EXPECT_GT(body->contact_normals()[s].dot(out), 0.0) << "node " << expected[s];
  }
  for (int v : boundary) {
    if (!on_uncovered[v]) {
      EXPECT_EQ(body->contact_slot(v), -1);
    }
  }
  EXPECT_THROW(body->add_tie(c.def), std::logic_error);
  EXPECT_THROW(body->cover_faces({}), std::logic_error);
}

TEST(interaction_coupled_body, PressOnTheExposedTopOfABottomTiedMeshEqualsTheMonolithicKkt) {
  // B stands on A tied by its bottom only; a press on B's exposed top (and a pull on one tied
  // node) reaches A through B's interior: host and B displacement equal the monolithic solve.
  const auto owner = tied_box::make_bottom_tied_box();
  const auto& c = *owner;
  ASSERT_GT(c.def.surface_nodes.size(), 3u);
  ASSERT_LT(c.def.surface_nodes.size(), c.embedded.surface_vertices().size());
  const auto body = make_body(c);
  const MonolithicSolver mono(c);
  const int nb3 = 3 * static_cast<int>(c.embedded.num_vertices());
  Eigen::VectorXd f = Eigen::VectorXd::Zero(nb3);
  int pressed = 0;
  for (int v : c.embedded.surface_vertices()) {
    if (c.embedded.vertices()[v].z() < 0.06 - 1e-9) continue;
    f.segment<3>(3 * v) = mesh::Vec3(0.002 * (pressed % 3), -0.001, -0.01);
    ++pressed;
  }
  ASSERT_GT(pressed, 0);
  f.segment<3>(3 * c.def.surface_nodes[0]) += mesh::Vec3(0.0, 0.003, 0.001);
  Eigen::VectorXd u_host, u_emb;
  body->tied_mesh_displacement(0, f, u_host, u_emb);
  const auto ref = mono.solve(Eigen::VectorXd::Zero(3 * static_cast<int>(c.host.num_vertices())), f);
  ASSERT_GT(ref.u_host_m.norm(), 0.0);
  std::printf("%d tied, %d pressed: relative difference to the KKT solve host %.2e, B %.2e\n",
              static_cast<int>(c.def.surface_nodes.size()), pressed,
              (u_host - ref.u_host_m).norm() / ref.u_host_m.norm(),
              (u_emb - ref.u_embedded_m).norm() / ref.u_embedded_m.norm());
  EXPECT_LE((u_host - ref.u_host_m).norm(), 1e-8 * ref.u_host_m.norm());
  EXPECT_LE((u_emb - ref.u_embedded_m).norm(), 1e-8 * ref.u_embedded_m.norm());
  EXPECT_LE(body->ties()[0].residual(u_host, u_emb), 1e-10 * u_emb.cwiseAbs().maxCoeff());
  // Not a rigid translation of B: the press compresses it (its top sinks more than its bottom).
  double top = 0.0, bottom = 0.0;
  int nt = 0, nbot = 0;
  for (int v : c.embedded.surface_vertices()) {
    const double z = c.embedded.vertices()[v].z();
    if (z > 0.06 - 1e-9) top += u_emb[3 * v + 2], ++nt;
    if (z < 0.04 + 1e-9) bottom += u_emb[3 * v + 2], ++nbot;
  }
  EXPECT_LT(top / nt, 1.2 * (bottom / nbot));
  EXPECT_LT(bottom / nbot, 0.0);
  EXPECT_THROW(body->tied_mesh_displacement(1, f, u_host, u_emb), std::invalid_argument);
  EXPECT_THROW(body->tied_mesh_displacement(0, Eigen::VectorXd::Zero(3), u_host, u_emb),
               std::invalid_argument);
}

// B standing on A, tied by its bottom only; its sides and top exposed (expose_tie): slots on B
// after A's, and the columns of every slot (on A, on B's rim, on B's top) at every slot equal the
// monolithic KKT solve with a unit force at that slot's node (on A or on B).
TEST(interaction_coupled_body, ExposedTieContactColumnsEqualTheMonolithicKkt) {
  const auto owner = tied_box::make_bottom_tied_box();
  const auto& c = *owner;
  auto body = std::make_unique<CoupledBody>(0, c.host, c.host_material, c.host_fixed);
  body->add_tie(c.def);
  std::vector<char> outside(c.embedded.num_vertices(), 0);
  for (int v : c.embedded.surface_vertices())
    outside[v] = c.embedded.vertices()[v].z() > 0.04 + 1e-9;
  body->expose_tie(0, outside);
  EXPECT_THROW(body->expose_tie(1, outside), std::invalid_argument);
  body->finalize();
  ASSERT_TRUE(body->has_exposed_contact());
  const int n_slots = static_cast<int>(body->contact_nodes().size());
  const int host_slots = body->num_host_contact();
  // B's free surface nodes are all on a face with an exposed node (the bottom's rim included);
  // its bottom's interior nodes are not.
  int on_b = 0, rim = 0, top = 0;
  for (int s = host_slots; s < n_slots; ++s) {
    const auto p = body->contact_point(s);
    ASSERT_EQ(p.tie, 0);
    EXPECT_EQ(body->contact_mesh().vertices()[body->contact_nodes()[s]], c.embedded.vertices()[p.node]);
    ++on_b;
    rim += !outside[p.node];
    top += c.embedded.vertices()[p.node].z() > 0.06 - 1e-9;
  }
  EXPECT_GT(on_b, 0);
  EXPECT_GT(rim, 0);
  EXPECT_GT(top, 0);
  std::printf("slots: %d on A, %d on B (%d on the tied rim, %d on the top)\n", host_slots, on_b,
              rim, top);
  // Contactable faces of B: none with all three nodes tied (its bottom is under A's top).
  for (const auto& f : c.embedded.surface()) {
    std::array<int, 3> e{f[0] + body->tie_vertex_offset(0), f[1] + body->tie_vertex_offset(0),
                         f[2] + body->tie_vertex_offset(0)};
    std::sort(e.begin(), e.end());
    const bool excluded = std::binary_search(body->contact_excluded_faces().begin(),
                                             body->contact_excluded_faces().end(), e);
    EXPECT_EQ(excluded, !outside[f[0]] && !outside[f[1]] && !outside[f[2]]);
  }
  ContactColumns columns(*body);
  std::vector<int> all(n_slots);
  for (int s = 0; s < n_slots; ++s) all[s] = s;
  columns.ensure(all);
  const MonolithicSolver mono(c);
  const int na3 = 3 * static_cast<int>(c.host.num_vertices());
  const int nb3 = 3 * static_cast<int>(c.embedded.num_vertices());
  std::vector<int> probe = {0, host_slots / 2, host_slots - 1, host_slots, (host_slots + n_slots) / 2,
                            n_slots - 1};
  double worst = 0.0;
  for (int j : probe) {
    const auto pj = body->contact_point(j);
    for (int a = 0; a < 3; ++a) {
      Eigen::VectorXd fa = Eigen::VectorXd::Zero(na3), fb = Eigen::VectorXd::Zero(nb3);
      (pj.tie < 0 ? fa : fb)[3 * pj.node + a] = 1.0;
      const auto ref = mono.solve(fa, fb);
      const double scale = std::max(ref.u_host_m.cwiseAbs().maxCoeff(), ref.u_embedded_m.cwiseAbs().maxCoeff());
      for (int i = 0; i < n_slots; ++i) {
        const auto pi = body->contact_point(i);
        const Eigen::Vector3d want =
            (pi.tie < 0 ? ref.u_host_m : ref.u_embedded_m).segment<3>(3 * pi.node);
        const Eigen::Vector3d got = columns.block(i, j).col(a);
        worst = std::max(worst, (got - want).norm() / scale);
      }
    }
  }
  std::printf("columns at all %d slots of %zu probed slots vs the KKT solve: worst %.2e relative\n",
              n_slots, probe.size(), worst);
  EXPECT_LE(worst, 1e-8);
  // The field for forces on slots of A and of B together (host_displacement, add_contact_loads,
  // B's interior with its forces) equals the KKT solve.
  const std::vector<int> slots = {host_slots / 3, host_slots, n_slots - 1};
  const std::vector<mesh::Vec3> forces = {mesh::Vec3(0.001, 0.0, -0.004), mesh::Vec3(0.002, -0.001, 0.0),
                                          mesh::Vec3(0.0, 0.001, -0.01)};
  Eigen::VectorXd fa = Eigen::VectorXd::Zero(na3), fb = Eigen::VectorXd::Zero(nb3);
  for (std::size_t k = 0; k < slots.size(); ++k) {
    const auto p = body->contact_point(slots[k]);
    (p.tie < 0 ? fa : fb).segment<3>(3 * p.node) += forces[k];
  }
  const auto ref = mono.solve(fa, fb);
  Eigen::VectorXd u_host, u_emb, f_b;
  body->host_displacement(slots, forces, u_host);
  ASSERT_TRUE(body->tie_contact_forces(0, slots, forces, f_b));
  EXPECT_LE((f_b - fb).norm(), 1e-15);
  body->ties()[0].displacement(u_host, f_b, u_emb);
  std::printf("field for forces on A and B: host %.2e, B %.2e relative\n",
              (u_host - ref.u_host_m).norm() / ref.u_host_m.norm(),
              (u_emb - ref.u_embedded_m).norm() / ref.u_embedded_m.norm());
  EXPECT_LE((u_host - ref.u_host_m).norm(), 1e-8 * ref.u_host_m.norm());
  EXPECT_LE((u_emb - ref.u_embedded_m).norm(), 1e-8 * ref.u_embedded_m.norm());
}

TEST(interaction_coupled_body, CachedBoundaryOperatorGivesTheSameColumns) {
  const auto owner = make_tied_box();
  const auto& c = *owner;
  const std::string dir = testing::temp_dir("coupled_body_cache").string();
  const auto first = make_body(c, dir);
  EXPECT_FALSE(first->cache_hit());
  const auto second = make_body(c, dir);
  EXPECT_TRUE(second->cache_hit());
  const std::vector<int> slots = some_slots(*first);
  Eigen::MatrixXd x1, x2;
  first->solve_contact_columns(slots, x1);
  second->solve_contact_columns(slots, x2);
  ASSERT_EQ(x1.rows(), x2.rows());
  ASSERT_EQ(x1.cols(), x2.cols());
  EXPECT_LE((x1 - x2).norm(), 1e-14 * x1.norm());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::interaction
