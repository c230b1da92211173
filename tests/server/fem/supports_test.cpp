// Supports: connected parts and the ones the fixed nodes leave free. The node rule (what
// StaticSolver checks) against the face rule (what the model builder uses), on a part hanging
// by one edge and on two disjoint grids.
#include "server/fem/supports.hpp"

#include "fem_test_meshes.hpp"

#include <gtest/gtest.h>

namespace neurosim::fem {
namespace {

// Two tetrahedra sharing the edge {0, 1}; the first one's nodes fixed.
mesh::TetMesh hinge() {
  const std::vector<mesh::Vec3> x{{0, 0, 0},           {0.01, 0, 0},          {0, 0.01, 0},
                                  {0, 0, 0.01},        {0.005, -0.01, 0.003}, {0.004, -0.003, -0.01}};
  return mesh::TetMesh::build(x, {{0, 1, 2, 3}, {0, 1, 4, 5}});
}

TEST(FemSupports, APartHangingOnAnEdgeIsFreeByFacesButHeldByNodes) {
  const mesh::TetMesh m = hinge();
  EXPECT_TRUE(unsupported_parts(m, {0, 1, 2, 3}, Joint::kNode).empty());
  const auto by_face = unsupported_parts(m, {0, 1, 2, 3}, Joint::kFace);
  ASSERT_EQ(by_face.size(), 1u);
  EXPECT_EQ(by_face[0].nodes, (std::vector<int>{0, 1, 4, 5}));
  EXPECT_EQ(by_face[0].fixed, 2);
  EXPECT_NE(by_face[0].problem.find("collinear"), std::string::npos) << by_face[0].problem;
  // One more fixed node off the edge holds it.
  EXPECT_TRUE(unsupported_parts(m, {0, 1, 2, 3, 4}, Joint::kFace).empty());
}

TEST(FemSupports, DisjointGridsAreSeparatePartsEachNeedingItsOwnSupports) {
  const mesh::TetMesh a = testing::box_mesh({2, 2, 2, {0, 0, 0}, {0.02, 0.02, 0.02}, 0.0, 1});
  std::vector<mesh::Vec3> x = a.vertices();
  std::vector<mesh::Tet> t = a.tets();
  const int off = static_cast<int>(x.size());
  for (const auto& p : a.vertices()) x.push_back(p + mesh::Vec3(0.05, 0, 0));
  for (auto tet : a.tets()) {
    for (int& v : tet) v += off;
    t.push_back(tet);
  }
  const mesh::TetMesh m = mesh::TetMesh::build(x, t);
  int parts = 0;
  const std::vector<int> part = connected_parts(m, parts);
  EXPECT_EQ(parts, 2);
  EXPECT_NE(part[0], part[off]);
  const auto bottom = testing::nodes_where(a, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  for (Joint j : {Joint::kNode, Joint::kFace}) {
    const auto free_parts = unsupported_parts(m, bottom, j);
    ASSERT_EQ(free_parts.size(), 1u);
    EXPECT_EQ(free_parts[0].nodes.front(), off);
    EXPECT_EQ(free_parts[0].fixed, 0);
  }
}

}  // namespace
}  // namespace neurosim::fem
