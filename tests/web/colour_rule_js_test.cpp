// The page's tool colour against the C++ rule: web/page/src/colour.js, with the
// force_colour_rule.js the build generated from common/force_colour.hpp (web/colour_rule_js.cpp),
// run in node for forces across the whole rule (rest, the blend, red, beyond, negative, not
// finite, other force units) must give common::force_colour's colours; and the page's note
// states the rule those numbers make.
#include "common/force_colour.hpp"
#include "common/json.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <vector>

#ifndef NEUROSIM_NODE
#error "NEUROSIM_NODE must be defined (tests/web/CMakeLists.txt: the node executable)"
#endif
#ifndef NEUROSIM_WEB_GENERATED_DIR
#error "NEUROSIM_WEB_GENERATED_DIR must be defined (tests/web/CMakeLists.txt)"
#endif

namespace {

namespace fs = std::filesystem;
namespace nt = neurosim::testing;
using neurosim::common::Json;

// Runs `script` (an ES module) with node in `dir`; its standard output.
std::string run_node(const fs::path& dir, const std::string& script) {
  const fs::path file = dir / "probe.mjs", out = dir / "out.txt";
  std::ofstream(file) << script;
  const std::string cmd = std::string(NEUROSIM_NODE) + " " + file.string() + " > " +
                          out.string() + " 2>&1";
  const int rc = std::system(cmd.c_str());
  const std::string text = nt::slurp(out);
  EXPECT_EQ(rc, 0) << text;
  return text;
}

class ColourRuleJs : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = nt::temp_dir("colour_rule_js");
    // The page's layout: src/colour.js importing ./generated/force_colour_rule.js.
    fs::create_directories(dir_ / "generated");
    fs::copy_file(nt::source_dir() / "web/page/src/colour.js", dir_ / "colour.js");
    fs::copy_file(fs::path(NEUROSIM_WEB_GENERATED_DIR) / "force_colour_rule.js",
                  dir_ / "generated/force_colour_rule.js");
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(ColourRuleJs, ThePageColoursAsTheCppRule) {
  // force (N) and force unit (N); the non-finite ones are written as JavaScript values.
  struct Case {
    double force_n, unit_n;
    const char* js;
  };
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<Case> cases{
      {0.0, 1.0, "0"},       {0.05, 1.0, "0.05"},  {0.1, 1.0, "0.1"},      {0.2, 1.0, "0.2"},
      {0.37, 1.0, "0.37"},   {0.8, 1.0, "0.8"},    {0.81, 1.0, "0.81"},    {5.0, 1.0, "5"},
      {-0.1, 1.0, "-0.1"},   {2.0, 4.0, "2"},      {0.3, 0.25, "0.3"},     {1e-9, 1.0, "1e-9"},
      {inf, 1.0, "Infinity"}, {-inf, 1.0, "-Infinity"}, {nan, 1.0, "NaN"}, {nan, 3.0, "NaN"}};
  std::string list;
  for (const Case& c : cases)
    list += std::string(list.empty() ? "" : ", ") + "[" + c.js + ", " + std::to_string(c.unit_n) + "]";
  const std::string out = run_node(
      dir_, "import { forceColour } from './colour.js';\n"
            "const cases = [" + list + "];\n"
            "console.log(JSON.stringify(cases.map(([f, u]) => forceColour(f, u))));\n");
  const Json js = Json::parse(out);
  ASSERT_EQ(js.size(), cases.size()) << out;
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const auto cpp = neurosim::common::force_colour(cases[i].force_n, cases[i].unit_n);
    for (std::size_t k = 0; k < 3; ++k)
      EXPECT_EQ(js[i][k].get<double>(), cpp[k])
          << "force " << cases[i].js << " N, unit " << cases[i].unit_n << " N, channel " << k;
  }
}

TEST_F(ColourRuleJs, ThePageNoteStatesThePapersRule) {
  const std::string out = run_node(
      dir_, "import { describeRule } from './colour.js';\nconsole.log(describeRule());\n");
  EXPECT_EQ(out, "(R,G,B) = (min(0.2+f,1), max(0.2\u2212f,0), max(0.2\u2212f,0))\n");
}

}  // namespace
