// ContactColumns: the cached coupled compliance columns of a body without ties equal the host's
// compliance from independent solves (CoupledBody::host_block), the full-column field equals the
// sparse-solve field, and only missing columns are computed; eviction frees only the slots the
// reader grants (not those it holds), and a freed slot solved again has the same columns.
#include "server/interaction/contact_columns.hpp"

#include "server/mesh/generate.hpp"

#include <gtest/gtest.h>

namespace neurosim::interaction {
namespace {

struct Block {
  mesh::TetMesh mesh;
  std::vector<int> fixed;
  std::unique_ptr<CoupledBody> body;
};

Block make_block() {
  Block b;
  mesh::MeshingOptions o;
  o.cell_size_m = 0.01;
  o.seed = 1;
  b.mesh = mesh::generate_box({0, 0, 0}, {0.04, 0.04, 0.04}, o).mesh;
  for (std::size_t v = 0; v < b.mesh.num_vertices(); ++v)
    if (b.mesh.vertices()[v].z() < 1e-9) b.fixed.push_back(static_cast<int>(v));
  fem::Material m;
  m.youngs_modulus_pa = 3000.0;
  m.poisson_ratio = 0.45;
  m.name = "block";
  b.body = std::make_unique<CoupledBody>(0, b.mesh, m, b.fixed);
  b.body->finalize();
  return b;
}

TEST(interaction_contact_columns, BlocksEqualIndependentSolvesAndOnlyMissingAreComputed) {
  const Block b = make_block();
  const int slots = static_cast<int>(b.body->contact_nodes().size());
  ASSERT_GT(slots, 10);
  ContactColumns cols(*b.body, true);
  EXPECT_EQ(cols.size(), 0u);
  const std::vector<int> touched{0, 3, slots - 1};
  cols.ensure(touched);
  EXPECT_EQ(cols.size(), 3u);
  cols.ensure({3, 0});  // cached: nothing new
  EXPECT_EQ(cols.size(), 3u);
  EXPECT_FALSE(cols.has(1));
  for (int i : touched) {
    for (int j : touched) {
      const Eigen::Matrix3d ref = b.body->host_block(i, j);
      EXPECT_LE((cols.block(i, j) - ref).norm(), 1e-9 * ref.norm()) << i << ", " << j;
    }
  }
  // The field of forces on cached slots: sum of full columns = one sparse solve.
  const std::vector<mesh::Vec3> forces{{0.0, 0.0, -0.1}, {0.02, 0.0, 0.0}, {0.0, -0.05, 0.01}};
  Eigen::VectorXd from_columns, from_solve;
  ASSERT_TRUE(cols.full_field(touched, forces, from_columns));
  b.body->host_displacement(touched, forces, from_solve);
  EXPECT_LE((from_columns - from_solve).norm(), 1e-9 * from_solve.norm());
  // A slot without columns: no field from columns, never a wrong one.
  EXPECT_FALSE(cols.full_field({1}, {{0.0, 0.0, 1.0}}, from_columns));
  EXPECT_THROW(cols.ensure({slots}), std::invalid_argument);
}

TEST(interaction_contact_columns, EvictionFreesOnlyGrantedSlotsAndASolvedAgainSlotIsTheSame) {
  const Block b = make_block();
  const int slots = static_cast<int>(b.body->contact_nodes().size());
  ContactColumns cols(*b.body);
  EXPECT_EQ(cols.bytes_per_slot(), sizeof(double) * 3 * (3 * static_cast<std::size_t>(slots)));
  cols.ensure({0, 1, 2, 3});
  const Eigen::Matrix3d before = cols.block(2, 2);
  // Nothing granted before the reader's grant: reclaim frees nothing.
  ASSERT_TRUE(cols.propose_eviction({1, 2, 3}));
  EXPECT_FALSE(cols.propose_eviction({0})) << "one proposal at a time";
  EXPECT_EQ(cols.reclaim(), 0);
  EXPECT_TRUE(cols.has(1) && cols.has(2) && cols.has(3));
  // The reader holds slot 3 (a force slot): it keeps it; 1 and 2 are given up.
  cols.grant_eviction([](int s) { return s == 3; });
  EXPECT_FALSE(cols.has(1));
  EXPECT_FALSE(cols.has(2));
  EXPECT_TRUE(cols.has(3));
  EXPECT_EQ(cols.size(), 2u);
  EXPECT_EQ(cols.reclaim(), 2);
  EXPECT_EQ(cols.evicted(), 2u);
  EXPECT_EQ(cols.reclaim(), 0) << "the mailbox is idle again";
  // Slot 1 granted, then solved again by the writer before reclaim: kept (fresh storage).
  ASSERT_TRUE(cols.propose_eviction({1}));
  cols.ensure({1, 2});
  EXPECT_EQ(cols.size(), 4u);
  cols.grant_eviction([](int) { return false; });  // nothing held: slot 1 granted
  EXPECT_FALSE(cols.has(1));
  cols.ensure({1});  // published again by the writer after the grant
  EXPECT_EQ(cols.reclaim(), 0) << "a slot published again after its grant is not freed";
  EXPECT_TRUE(cols.has(1));
  EXPECT_EQ(cols.size(), 4u);
  // Solved again: the same numbers (same factor, same right-hand side) to round-off. Not to the
  // bit: slot 2 was solved first in a block of four right-hand sides and now in a block of two,
  // and CHOLMOD's supernodal solve hands a block to BLAS kernels whose rounding depends on its
  // width: 1.6e-17 apart with OpenBLAS's AVX-512 kernels on an AMD EPYC, bit-equal with its AVX2
  // kernels on the same machine (OPENBLAS_CORETYPE=Haswell). A wrong right-hand side or stale
  // storage would be off by the column itself.
  EXPECT_LE((cols.block(2, 2) - before).norm(), 1e-12 * before.norm());
  EXPECT_GT(before.norm(), 0.0);
  EXPECT_THROW(cols.propose_eviction({slots}), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::interaction
