// Global stiffness: equals a plain triplet assembly of element matrices, symmetric, rigid
// motions in its null space, per-tetrahedron materials, refill in place.
#include "server/fem/assembly.hpp"
#include "fem_test_meshes.hpp"
#include "server/fem/tet_element.hpp"

#include <gtest/gtest.h>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::BoxSpec;

SparseMatrix triplet_assembly(const mesh::TetMesh& m, const MaterialMap& mats) {
  std::vector<Eigen::Triplet<double>> trip;
  for (std::size_t t = 0; t < m.num_tets(); ++t) {
    const auto& tet = m.tets()[t];
    const ElementMatrix k = tet_stiffness(
        {m.vertices()[tet[0]], m.vertices()[tet[1]], m.vertices()[tet[2]], m.vertices()[tet[3]]},
        mats.of_tet(t), static_cast<int>(t));
    for (int a = 0; a < 4; ++a) {
      for (int b = 0; b < 4; ++b) {
        for (int i = 0; i < 3; ++i) {
          for (int j = 0; j < 3; ++j) {
            trip.emplace_back(3 * tet[a] + i, 3 * tet[b] + j, k(3 * a + i, 3 * b + j));
          }
        }
      }
    }
  }
  SparseMatrix k(3 * m.num_vertices(), 3 * m.num_vertices());
  k.setFromTriplets(trip.begin(), trip.end());
  return k;
}

TEST(FemAssembly, MatchesTripletAssemblyAndIsSymmetric) {
  const auto m = box_mesh(BoxSpec{4, 3, 2, {0, 0, 0}, {0.04, 0.03, 0.02}, 0.2, 5});
  const MaterialMap mats = MaterialMap::uniform({1e6, 0.4, "brain"});
  const SparseMatrix k = assemble_stiffness(m, mats);
  const SparseMatrix ref = triplet_assembly(m, mats);
  EXPECT_EQ(k.rows(), 3 * static_cast<Eigen::Index>(m.num_vertices()));
  const double scale = Eigen::MatrixXd(ref).cwiseAbs().maxCoeff();
  EXPECT_LE(Eigen::MatrixXd(k - ref).cwiseAbs().maxCoeff(), 1e-12 * scale);
  EXPECT_LE(Eigen::MatrixXd(k - SparseMatrix(k.transpose())).cwiseAbs().maxCoeff(), 1e-12 * scale);
}

TEST(FemAssembly, RigidMotionsAreInTheNullSpace) {
  const auto m = box_mesh(BoxSpec{3, 3, 3, {0, 0, 0}, {1, 1, 1}, 0.25, 2});
  const SparseMatrix k = assemble_stiffness(m, MaterialMap::uniform({1e6, 0.45, "brain"}));
  const double scale = Eigen::MatrixXd(k).cwiseAbs().maxCoeff();
  for (int mode = 0; mode < 6; ++mode) {
    Eigen::VectorXd u(3 * m.num_vertices());
    for (std::size_t v = 0; v < m.num_vertices(); ++v) {
      u.segment<3>(3 * v) =
          mode < 3 ? Eigen::Vector3d(Eigen::Vector3d::Unit(mode))
                   : Eigen::Vector3d(Eigen::Vector3d::Unit(mode - 3).cross(m.vertices()[v]));
    }
    EXPECT_LE((k * u).cwiseAbs().maxCoeff(), 1e-12 * scale * u.cwiseAbs().maxCoeff())
        << "mode " << mode;
  }
}

TEST(FemAssembly, PerTetMaterialsAndInPlaceRefill) {
  const auto m = box_mesh(BoxSpec{2, 2, 2});
  std::vector<int> ids(m.num_tets());
  for (std::size_t t = 0; t < ids.size(); ++t) {
    ids[t] = static_cast<int>(t % 2);
  }
  const MaterialMap two = MaterialMap::per_tet({{1e6, 0.4, "soft"}, {1e10, 0.3, "stiff"}}, ids);
  StiffnessAssembler assembler(m);
  SparseMatrix k;
  assembler.assemble(m, MaterialMap::uniform({1e6, 0.4, "soft"}), k);
  const double* values_before = k.valuePtr();
  assembler.assemble(m, two, k);
  EXPECT_EQ(values_before, k.valuePtr()) << "refill must reuse the pattern";
  const SparseMatrix ref = triplet_assembly(m, two);
  const double scale = Eigen::MatrixXd(ref).cwiseAbs().maxCoeff();
  EXPECT_LE(Eigen::MatrixXd(k - ref).cwiseAbs().maxCoeff(), 1e-12 * scale);

  MaterialMap wrong = two;
  wrong.tet_material.pop_back();
  EXPECT_THROW(assembler.assemble(m, wrong, k), std::invalid_argument);
  wrong = two;
  wrong.tet_material[3] = 5;
  try {
    assembler.assemble(m, wrong, k);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tetrahedron 3"), std::string::npos) << e.what();
  }
  const auto other = box_mesh(BoxSpec{3, 2, 2});
  EXPECT_THROW(assembler.assemble(other, two, k), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fem
