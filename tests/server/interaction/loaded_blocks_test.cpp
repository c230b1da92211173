// LoadedBlocks: the compact copy of a body's compliance blocks between the loaded nodes holds
// the columns' blocks bit for bit, in rows by index; indices are stable until the copy starts
// over (capacity reached, clear, or an eviction of the columns seen by refresh), and a copy that
// started over holds the columns' blocks again, never a stale one.
#include "server/interaction/loaded_blocks.hpp"

#include "fixed_base_box.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <vector>

namespace neurosim::interaction {
namespace {

struct Body {
  fixtures::FixedBaseBox box;
  std::unique_ptr<CoupledBody> body;
};

Body make_body() {
  Body b;
  b.box = fixtures::fixed_base_box(0.01);
  fem::Material m;
  m.youngs_modulus_pa = 3000.0;
  m.poisson_ratio = 0.45;
  m.name = "block";
  b.body = std::make_unique<CoupledBody>(0, b.box.mesh, m, b.box.fixed);
  b.body->finalize();
  return b;
}

// The copy's block (i, j) is the columns' (slot i, slot j), every bit.
bool same_bits(LoadedBlocks& lb, const ContactColumns& cols, int i, int j, int si, int sj) {
  const double* copy = lb.block(cols, i, j);
  const auto ref = cols.block(si, sj);
  return std::memcmp(copy, ref.data(), 9 * sizeof(double)) == 0;
}

TEST(interaction_loaded_blocks, BlocksAreTheColumnsBitForBitInRowsByIndex) {
  const Body b = make_body();
  const int slots = static_cast<int>(b.body->contact_nodes().size());
  ASSERT_GT(slots, 10);
  ContactColumns cols(*b.body);
  const std::vector<int> loaded{7, 2, slots - 1, 0};
  cols.ensure(loaded);
  LoadedBlocks lb;
  lb.reserve(slots, 3);
  EXPECT_EQ(lb.capacity(), 3);
  lb.refresh(cols);
  std::vector<int> index;
  for (int s : loaded) index.push_back(lb.index(s));
  // First come, first numbered; the fourth node finds every index taken.
  EXPECT_EQ(index[0], 0);
  EXPECT_EQ(index[1], 1);
  EXPECT_EQ(index[2], 2);
  EXPECT_EQ(index[3], -1);
  EXPECT_EQ(lb.index(2), 1) << "a node keeps its index";
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      EXPECT_TRUE(same_bits(lb, cols, index[i], index[j], loaded[i], loaded[j])) << i << ", " << j;
      EXPECT_EQ(lb.block(cols, index[i], index[j]), lb.row(index[i]) + 9 * index[j]);
    }
  }
  // Block (i, j) is C(i, j), not its transpose: the copy is row-major like the columns' block.
  const double* b01 = lb.block(cols, 0, 1);
  const auto c01 = cols.block(loaded[0], loaded[1]);
  EXPECT_EQ(b01[1], c01(0, 1));
  EXPECT_EQ(b01[3], c01(1, 0));
  EXPECT_GT(c01.norm(), 0.0);

  // clear: every index free again, the blocks copied again for the new numbering.
  lb.clear();
  EXPECT_EQ(lb.index(loaded[3]), 0);
  EXPECT_EQ(lb.index(loaded[0]), 1);
  EXPECT_TRUE(same_bits(lb, cols, 0, 1, loaded[3], loaded[0]));
  EXPECT_TRUE(same_bits(lb, cols, 1, 0, loaded[0], loaded[3]));
  EXPECT_TRUE(same_bits(lb, cols, 0, 0, loaded[3], loaded[3]));
}

TEST(interaction_loaded_blocks, AnEvictionOfTheColumnsStartsTheCopyOver) {
  const Body b = make_body();
  const int slots = static_cast<int>(b.body->contact_nodes().size());
  ContactColumns cols(*b.body);
  cols.ensure({0, 1, 2});
  LoadedBlocks lb;
  lb.reserve(slots, 8);
  lb.refresh(cols);
  EXPECT_EQ(lb.index(1), 0);
  EXPECT_EQ(lb.index(2), 1);
  EXPECT_TRUE(same_bits(lb, cols, 0, 1, 1, 2));
  lb.refresh(cols);  // nothing evicted: the copy stays
  EXPECT_EQ(lb.index(2), 1);
  // The columns evict slot 1 (granted by the reader) and solve it again.
  ASSERT_TRUE(cols.propose_eviction({1}));
  cols.grant_eviction([](int) { return false; });
  EXPECT_EQ(cols.reclaim(), 1);
  cols.ensure({1});
  lb.refresh(cols);  // the copy starts over: slot 2 is numbered afresh
  EXPECT_EQ(lb.index(2), 0);
  EXPECT_EQ(lb.index(1), 1);
  EXPECT_TRUE(same_bits(lb, cols, 0, 1, 2, 1));
  EXPECT_TRUE(same_bits(lb, cols, 1, 1, 1, 1));
}

TEST(interaction_loaded_blocks, CapacityIsAtMostTheSlots) {
  LoadedBlocks lb;
  lb.reserve(5, 256);
  EXPECT_EQ(lb.capacity(), 5);
  for (int s = 0; s < 5; ++s) EXPECT_EQ(lb.index(s), s);
  lb.reserve(0, 256);
  EXPECT_EQ(lb.capacity(), 0);
}

}  // namespace
}  // namespace neurosim::interaction
