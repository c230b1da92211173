// Disk cache of a body's boundary operator: the same key reads back what was stored, bit for
// bit; another key, other sizes or a damaged file are never used.
#include "server/interaction/boundary_cache.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace neurosim::interaction {
namespace {

BoundaryOperator random_operator(int m3, int s3) {
  BoundaryOperator op;
  op.l_bb = Eigen::MatrixXd::Random(m3, m3);
  op.l_sb = Eigen::MatrixXd::Random(s3, m3);
  op.k_add = Eigen::MatrixXd::Random(m3, m3);
  op.g = Eigen::MatrixXd::Random(m3, m3);
  return op;
}

TEST(interaction_boundary_cache, RoundTripAndRefusals) {
  const auto dir = testing::temp_dir("boundary_cache");
  const std::string file = (dir / "sub" / "op.bin").string();
  const BoundaryOperator op = random_operator(6, 9);
  CacheKey a, b;
  a.add(std::vector<int>{1, 2});
  a.add(std::vector<int>{3});
  b.add(std::vector<int>{1});
  b.add(std::vector<int>{2, 3});
  ASSERT_NE(a.value(), b.value()) << "sizes are part of the key";
  save_boundary_operator(file, a.value(), op);
  BoundaryOperator back;
  ASSERT_TRUE(load_boundary_operator(file, a.value(), 6, 9, back));
  EXPECT_EQ(back.l_bb, op.l_bb);
  EXPECT_EQ(back.l_sb, op.l_sb);
  EXPECT_EQ(back.k_add, op.k_add);
  EXPECT_EQ(back.g, op.g);
  EXPECT_FALSE(load_boundary_operator(file, b.value(), 6, 9, back));  // another key
  EXPECT_FALSE(load_boundary_operator(file, a.value(), 9, 9, back));  // other sizes
  EXPECT_FALSE(load_boundary_operator((dir / "none.bin").string(), a.value(), 6, 9, back));
  // Damaged: truncated in the middle of the matrices.
  std::filesystem::resize_file(file, std::filesystem::file_size(file) / 2);
  EXPECT_FALSE(load_boundary_operator(file, a.value(), 6, 9, back));
  // Damaged: a NaN in the stored values.
  BoundaryOperator bad = op;
  bad.g(1, 1) = std::numeric_limits<double>::quiet_NaN();
  save_boundary_operator(file, a.value(), bad);
  EXPECT_FALSE(load_boundary_operator(file, a.value(), 6, 9, back));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::interaction
