// AccuracyTable: reading accuracy_bench's table (errors name file and line) and the expected
// error at a strain (upper envelope of the measured errors, linear in strain, from 0 at zero
// strain; the scene's rows first, else every scene's; beyond the table the largest error).
#include "server/service/accuracy_table.hpp"

#include "server/fem/served_tiers.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

namespace neurosim::service {
namespace {

using neurosim::testing::contains;

std::filesystem::path write(const std::string& name, const std::string& text) {
  return neurosim::testing::write_temp_file("accuracy_table", name, text);
}

TEST(AccuracyTable, ReadsTheBenchTableAndInterpolates) {
  const auto file = write("ok.csv",
                          "# comment\n"
                          "scene,tier,max_strain,force_rel_error\n"
                          "cube,LINEAR,0.1,0.02\n"
                          "cube,LINEAR,0.3,0.12\n"
                          "cube,LINEAR,0.2,0.01\n"  // below the envelope: raised to 0.02
                          "brain,linear,0.05,0.5\n"
                          "cube,NONLINEAR,0.2,0\n");
  const AccuracyTable t = AccuracyTable::read(file);
  ASSERT_EQ(t.rows().size(), 5u);
  // From (0, 0) to (0.1, 0.02): half way.
  ExpectedError e = t.expected(fem::Tier::kLinear, 0.05, "cube");
  EXPECT_TRUE(e.known);
  EXPECT_FALSE(e.beyond_table);
  EXPECT_NEAR(e.force_rel_error, 0.01, 1e-15);
  EXPECT_EQ(e.basis, "cube");
  // Envelope: 0.02 at 0.2 (not the measured 0.01), then to 0.12 at 0.3.
  EXPECT_NEAR(t.expected(fem::Tier::kLinear, 0.2, "cube").force_rel_error, 0.02, 1e-15);
  EXPECT_NEAR(t.expected(fem::Tier::kLinear, 0.25, "cube").force_rel_error, 0.07, 1e-15);
  e = t.expected(fem::Tier::kLinear, 0.5, "cube");
  EXPECT_TRUE(e.beyond_table);
  EXPECT_NEAR(e.force_rel_error, 0.12, 1e-15);
  // Another scene's rows only when this scene has none for the tier.
  EXPECT_NEAR(t.expected(fem::Tier::kLinear, 0.05, "brain").force_rel_error, 0.5, 1e-15);
  e = t.expected(fem::Tier::kNonlinear, 0.1, "brain");
  EXPECT_TRUE(e.known);
  EXPECT_EQ(e.basis, "every scene");
  EXPECT_EQ(e.force_rel_error, 0.0);
  EXPECT_FALSE(t.expected(fem::Tier::kCorotational, 0.1, "cube").known);
}

// The table with the element and host nu columns: a lookup for an element and nu uses only
// their rows (none: unknown, not another element's error); without them, every row as before.
TEST(AccuracyTable, RowsOfTheRunningElementAndNuOnly) {
  const auto file = write("element.csv",
                          "scene,tier,max_strain,force_rel_error,element,poisson_ratio\n"
                          "brain,LINEAR,0.4,0.3,smoothed-tet,0.49\n"
                          "brain,LINEAR,0.4,0.1,linear-tet,0.49\n"
                          "brain,LINEAR,0.4,0.05,linear-tet,0.45\n");
  const AccuracyTable t = AccuracyTable::read(file);
  ASSERT_EQ(t.rows().size(), 3u);
  EXPECT_EQ(t.rows()[0].element, "smoothed-tet");
  EXPECT_EQ(t.rows()[0].poisson_ratio, 0.49);
  ExpectedError e = t.expected(fem::Tier::kLinear, 0.4, "brain", "smoothed-tet", 0.49);
  EXPECT_TRUE(e.known);
  EXPECT_NEAR(e.force_rel_error, 0.3, 1e-15);
  EXPECT_EQ(e.basis, "brain, smoothed-tet");
  EXPECT_NEAR(t.expected(fem::Tier::kLinear, 0.4, "brain", "linear-tet", 0.45).force_rel_error,
              0.05, 1e-15);
  EXPECT_FALSE(t.expected(fem::Tier::kLinear, 0.4, "brain", "anp-tet", 0.49).known);
  EXPECT_FALSE(t.expected(fem::Tier::kLinear, 0.4, "brain", "smoothed-tet", 0.499).known);
  EXPECT_NEAR(t.expected(fem::Tier::kLinear, 0.4, "brain").force_rel_error, 0.3, 1e-15)
      << "no element given: the envelope of every row";
  // A table of the old header has no element: it answers no element-specific lookup.
  const AccuracyTable old = AccuracyTable::read(
      write("old.csv", "scene,tier,max_strain,force_rel_error\nbrain,LINEAR,0.4,0.3\n"));
  EXPECT_FALSE(old.expected(fem::Tier::kLinear, 0.4, "brain", "smoothed-tet", 0.49).known);
  EXPECT_TRUE(old.expected(fem::Tier::kLinear, 0.4, "brain").known);
}

// The tier and the element are the table's own checks; the header, fields, numbers and the
// file:line of every error are CsvFields' (csv_fields_test).
TEST(AccuracyTable, MalformedTablesNameFileAndLine) {
  const auto error_of = [](const std::string& text) {
    return neurosim::testing::message_of([&] { AccuracyTable::read(write("bad.csv", text)); });
  };
  const std::string old = "scene,tier,max_strain,force_rel_error\n";
  const std::string now = "scene,tier,max_strain,force_rel_error,element,poisson_ratio\n";
  EXPECT_PRED2(contains, error_of(old + "cube,QUADRATIC,0.1,0.2\n"),
               "bad.csv:2: unknown tier 'QUADRATIC'");
  EXPECT_PRED2(contains, error_of(now + "cube,COROTATIONAL,0.1,0.2,linear-tet,0.4\n"),
               "bad.csv:2: tier 'COROTATIONAL' is withdrawn")
      << "a withdrawn tier's rows are never read";
  EXPECT_PRED2(contains, error_of(now + "#\ncube,LINEAR,0.1,0.2,quadratic-tet,0.4\n"),
               "bad.csv:3: unknown element 'quadratic-tet'");
  EXPECT_PRED2(contains, error_of(old + "cube,LINEAR,0.1,0.2,linear-tet,0.4\n"),
               "bad.csv:2: 6 fields, expected 4")
      << "the old header: no element columns";
  EXPECT_PRED2(contains, error_of(now + "cube,LINEAR,0.1,0.2,linear-tet,nan\n"),
               "bad.csv:2 poisson_ratio: 'nan'");
}

// The committed table reads (no rows of the withdrawn COROTATIONAL tier) and has the served
// tiers' rows of both scenes.
TEST(AccuracyTable, TheCommittedTableReads) {
  const AccuracyTable t =
      AccuracyTable::read(neurosim::testing::source_dir() / "share/accuracy/force_error.csv");
  for (const auto& r : t.rows()) EXPECT_TRUE(fem::tier_served(r.tier)) << r.scene;
  for (auto tier : {fem::Tier::kLinear, fem::Tier::kNonlinear}) {
    for (const char* scene : {"cube_cylinder", "brain_artery"}) {
      const ExpectedError e = t.expected(tier, 0.1, scene);
      EXPECT_TRUE(e.known) << fem::tier_name(tier) << " " << scene;
      EXPECT_EQ(e.basis, scene);
    }
  }
}

}  // namespace
}  // namespace neurosim::service
