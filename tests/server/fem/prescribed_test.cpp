// Prescribed displacements by component: parsing a subset of "xyz", merging definitions into
// constrained dofs, refusing empty, conflicting and fixed-and-prescribed definitions.
#include "server/fem/prescribed.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <stdexcept>
#include <string>

namespace neurosim::fem {
namespace {

void expect_invalid(const std::function<void()>& f, const std::string& needle) {
  try {
    f();
    FAIL() << "no exception; expected one mentioning '" << needle << "'";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(FemPrescribed, ParseComponents) {
  EXPECT_EQ(parse_components("z"), (Components{false, false, true}));
  EXPECT_EQ(parse_components("xy"), (Components{true, true, false}));
  EXPECT_EQ(parse_components("zx"), (Components{true, false, true}));
  EXPECT_EQ(parse_components("zyx"), kAllComponents);
  EXPECT_EQ(components_string(parse_components("zyx")), "xyz");
  EXPECT_EQ(components_string(parse_components("y")), "y");
  EXPECT_EQ(components_string(Components{false, false, false}), "");
  expect_invalid([] { parse_components(""); }, "empty");
  expect_invalid([] { parse_components("xw"); }, "unknown component 'w'");
  expect_invalid([] { parse_components("X"); }, "unknown component 'X'");
  expect_invalid([] { parse_components("x z"); }, "unknown component ' '");
  expect_invalid([] { parse_components("zz"); }, "component 'z' given twice");
}

TEST(FemPrescribed, DefaultIsAllComponents) {
  const PrescribedDofs p{{4, 2}, {1e-3, -2e-3, 3e-3}};
  EXPECT_EQ(p.components, kAllComponents);
  const PrescribedDofList list = expand_prescribed({p}, 5);
  EXPECT_EQ(list.dofs, (std::vector<int>{6, 7, 8, 12, 13, 14}));
  EXPECT_EQ(list.nodes, (std::vector<int>{2, 4}));
  ASSERT_EQ(list.values_m.size(), 6);
  for (int k = 0; k < 6; ++k) {
    EXPECT_EQ(list.values_m[k], p.displacement_m[k % 3]);
  }
}

TEST(FemPrescribed, SubsetsMergeByNode) {
  // Node 3: z from the first definition, x from the second; node 1 z only; node 0 z twice with
  // the same value (merged).
  const std::vector<PrescribedDofs> defs{
      {{3, 1, 0}, {0.0, 0.0, -1e-3}, parse_components("z")},
      {{3}, {2e-4, 9.0, 9.0}, parse_components("x")},
      {{0, 0}, {0.0, 0.0, -1e-3}, parse_components("z")},
  };
  const PrescribedDofList list = expand_prescribed(defs, 4);
  EXPECT_EQ(list.dofs, (std::vector<int>{2, 5, 9, 11}));
  EXPECT_EQ(list.nodes, (std::vector<int>{0, 1, 3}));
  EXPECT_EQ(list.values_m[0], -1e-3);
  EXPECT_EQ(list.values_m[1], -1e-3);
  EXPECT_EQ(list.values_m[2], 2e-4);
  EXPECT_EQ(list.values_m[3], -1e-3);
  // Values of components that are not prescribed are ignored, even non-finite ones.
  EXPECT_NO_THROW(expand_prescribed({{{0}, {std::nan(""), 0.0, 1e-3}, parse_components("z")}}, 1));
}

TEST(FemPrescribed, BadDefinitionsAreRefusedNamingTheNode) {
  expect_invalid([] { expand_prescribed({{{}, {0, 0, 1e-3}}}, 4); }, "prescribed[0]: no node");
  expect_invalid(
      [] {
        expand_prescribed({{{1}, {0, 0, 1e-3}, {false, false, false}}}, 4);
      },
      "prescribed[0]: no component prescribed");
  expect_invalid(
      [] {
        expand_prescribed({{{1}, {0, 0, 0}}, {{7}, {0, 0, 1e-3}}}, 4);
      },
      "prescribed[1]: node 7 out of range [0, 4)");
  expect_invalid([] { expand_prescribed({{{-1}, {0, 0, 1e-3}}}, 4); }, "node -1 out of range");
  expect_invalid(
      [] {
        expand_prescribed({{{1}, {0, 0, std::nan("")}, parse_components("z")}}, 4);
      },
      "prescribed[0]: non-finite displacement in z");
  // Fixed and prescribed at once.
  expect_invalid(
      [] {
        expand_prescribed({{{1, 2}, {0, 0, -1e-3}, parse_components("z")}}, 4, {2});
      },
      "prescribed[0]: node 2 is both fixed");
  // The same component of one node with two different values, across or within definitions.
  expect_invalid(
      [] {
        expand_prescribed({{{0, 1}, {0, 0, -1e-3}, parse_components("z")},
                           {{2, 1}, {0, 0, -2e-3}, parse_components("yz")}},
                          4);
      },
      "prescribed[1]: node 1 component z prescribed twice with different values: -0.001 m by "
      "prescribed[0]");
  // A different component of the same node is no conflict.
  EXPECT_NO_THROW(expand_prescribed({{{0, 1}, {0, 0, -1e-3}, parse_components("z")},
                                     {{1}, {5e-4, 0, -2e-3}, parse_components("x")}},
                                    4));
}

}  // namespace
}  // namespace neurosim::fem
