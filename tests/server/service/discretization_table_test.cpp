// DiscretizationTable: reading accuracy_bench's discretization table (errors name file and line),
// the row of a host (element, nu, mesh size), and the committed table: the bundled brain has its
// row (smoothed-tet, nu 0.49), an element measured on no mesh has none (unknown, not a guess).
#include "server/service/discretization_table.hpp"

#include "server/scene/compile.hpp"
#include "server/service/accuracy_table.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

namespace neurosim::service {
namespace {

using neurosim::testing::contains;

std::filesystem::path write(const std::string& name, const std::string& text) {
  return neurosim::testing::write_temp_file("discretization_table", name, text);
}

constexpr const char* kHeader =
    "scene,element,poisson_ratio,host_vertices,host_tetrahedra,discretization_error\n";

TEST(DiscretizationTable, ReadsAndFindsTheHost) {
  const auto file = write("ok.csv", std::string("# comment\n") + kHeader +
                                        "brain,smoothed-tet,0.49,5354,24948,0.056\n"
                                        "brain,linear-tet,0.49,5354,24948,0.58\n"
                                        "brain,smoothed-tet,0.45,5354,24948,0.083\n");
  const DiscretizationTable t = DiscretizationTable::read(file);
  ASSERT_EQ(t.rows().size(), 3u);
  auto r = t.find(fem::Element::kSmoothedTet, 0.49, 5354, 24948);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->discretization_error, 0.056);
  EXPECT_EQ(r->scene, "brain");
  r = t.find(fem::Element::kLinearTet, 0.49, 5354, 24948);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->discretization_error, 0.58);
  EXPECT_EQ(t.find(fem::Element::kSmoothedTet, 0.45, 5354, 24948)->discretization_error, 0.083);
  // Any other element, nu or mesh: no row.
  EXPECT_FALSE(t.find(fem::Element::kAnpTet, 0.49, 5354, 24948));
  EXPECT_FALSE(t.find(fem::Element::kSmoothedTet, 0.499, 5354, 24948));
  EXPECT_FALSE(t.find(fem::Element::kSmoothedTet, 0.49, 5355, 24948));
  EXPECT_FALSE(t.find(fem::Element::kSmoothedTet, 0.49, 5354, 24949));
}

// The element is the table's own check; the header, fields, numbers and the file:line of every
// error are CsvFields' (csv_fields_test).
TEST(DiscretizationTable, MalformedTablesNameFileAndLine) {
  const auto error_of = [](const std::string& text) {
    return neurosim::testing::message_of(
        [&] { DiscretizationTable::read(write("bad.csv", text)); });
  };
  EXPECT_PRED2(contains, error_of("scene,element\n"),
               "bad.csv:1: expected the header '" + std::string(kHeader).substr(0, 6));
  EXPECT_PRED2(contains, error_of(kHeader + std::string("#\nbrain,quadratic-tet,0.49,5,5,0.1\n")),
               "bad.csv:3: unknown element 'quadratic-tet'");
  EXPECT_PRED2(contains,
               error_of(kHeader + std::string("brain,smoothed-tet,0.49,5354.5,24948,0.1\n")),
               "bad.csv:2 host_vertices: '5354.5' is not a count");
}

// The committed tables against the bundled brain scene: the discretization row of its host and
// the tier rows of its element and nu exist and are sane; on anp-tet (measured on no mesh) both
// lookups say unknown.
TEST(DiscretizationTable, TheBundledBrainHasItsRowAndAnotherElementIsUnknown) {
  const auto share = neurosim::testing::source_dir() / "share/accuracy";
  const DiscretizationTable t = DiscretizationTable::read(share / "discretization_error.csv");
  const scene::Model model =
      scene::load_model(neurosim::testing::source_dir() / "scenes/brain_artery.scene");
  const auto& host = model.meshes.at(0);
  ASSERT_EQ(host.material.element, fem::Element::kSmoothedTet);
  ASSERT_EQ(host.material.poisson_ratio, 0.49);
  const auto row = t.find(host.material.element, host.material.poisson_ratio,
                          host.mesh.num_vertices(), host.mesh.num_tets());
  ASSERT_TRUE(row) << "no row for the bundled brain";
  EXPECT_GT(row->discretization_error, 0.0);
  EXPECT_LT(row->discretization_error, 0.2) << "smoothed-tet on the bundled brain: a few %";
  EXPECT_FALSE(t.find(fem::Element::kAnpTet, host.material.poisson_ratio, host.mesh.num_vertices(),
                      host.mesh.num_tets()));

  const AccuracyTable tiers = AccuracyTable::read(share / "force_error.csv");
  for (auto tier : {fem::Tier::kLinear, fem::Tier::kNonlinear}) {
    const ExpectedError e = tiers.expected(tier, 0.3, model.name, "smoothed-tet", 0.49);
    EXPECT_TRUE(e.known) << fem::tier_name(tier);
    EXPECT_EQ(e.basis, model.name + ", smoothed-tet");
    EXPECT_GE(e.force_rel_error, 0.0);
    EXPECT_LT(e.force_rel_error, 2.0);
    EXPECT_FALSE(tiers.expected(tier, 0.3, model.name, "anp-tet", 0.49).known);
  }
}

// The other bundled scenes' hosts as they load have their rows too: the viscoelastic brain
// (linear-tet at nu 0.45 on the bundled mesh: locking, tens of %) and the cube (linear-tet at
// nu 0.4, 1798 vertices); each against the converged answer, so above zero.
TEST(DiscretizationTable, TheViscoelasticBrainAndTheCubeHaveTheirRows) {
  const DiscretizationTable t = DiscretizationTable::read(
      neurosim::testing::source_dir() / "share/accuracy/discretization_error.csv");
  for (const char* name : {"brain_viscoelastic", "cube_cylinder"}) {
    const scene::Model model = scene::load_model(neurosim::testing::source_dir() / "scenes" /
                                                 (std::string(name) + ".scene"));
    const auto& host = model.meshes.at(0);
    const auto row = t.find(host.material.element, host.material.poisson_ratio,
                            host.mesh.num_vertices(), host.mesh.num_tets());
    ASSERT_TRUE(row) << name << ": no row for " << fem::element_name(host.material.element)
                     << ", nu " << host.material.poisson_ratio << ", "
                     << host.mesh.num_vertices() << " vertices";
    EXPECT_GT(row->discretization_error, 0.05) << name;
    EXPECT_LT(row->discretization_error, 1.0) << name;
  }
}

}  // namespace
}  // namespace neurosim::service
