// neurosim-figures on the paper's cube/cylinder scene: the command writes its CSVs, PNGs and
// .vtu frames, and the numbers show Figure 10 (the cylinder moves only with coupling) and
// Figure 14 (the force depends on the coupling).
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

// Last value of `column` for rows with coupling == c and side == "right".
double last_value(const fs::path& csv, int column, int coupling) {
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);  // header
  double value = -1.0;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    if (cells.size() > static_cast<std::size_t>(column) && std::stoi(cells[0]) == coupling &&
        cells[1] == "right") {
      value = std::stod(cells[column]);
    }
  }
  return value;
}

TEST(interaction_figures, PaperFigures10And14) {
  const fs::path out = neurosim::testing::temp_dir("interaction_figures");
  const std::string cmd = "cd " + neurosim::testing::source_dir().string() + " && " +
                          (neurosim::testing::bin_dir() / "neurosim-figures").string() + " --out " +
                          out.string() + " --frames 2 > " + (out / "log.txt").string() + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  for (const char* f : {"fig10_cylinder.csv", "fig14_force.csv", "fig13_residual.csv",
                        "fig10_cylinder.png", "fig14_force.png", "fig13_residual.png",
                        "fig10_coupled_right_2_cylinder.vtu", "fig10_uncoupled_right_2_cube.vtu"}) {
    EXPECT_TRUE(fs::exists(out / f)) << f;
    if (fs::exists(out / f)) {
      EXPECT_GT(fs::file_size(out / f), 0u) << f;
    }
  }
  // Figure 10: column 3 = largest cylinder displacement.
  EXPECT_EQ(last_value(out / "fig10_cylinder.csv", 3, 0), 0.0);
  EXPECT_GT(last_value(out / "fig10_cylinder.csv", 3, 1), 1e-4);
  // Figure 14: column 3 = force; both positive and different.
  const double off = last_value(out / "fig14_force.csv", 3, 0),
               on = last_value(out / "fig14_force.csv", 3, 1);
  EXPECT_GT(off, 0.0);
  EXPECT_GT(on, 0.0);
  EXPECT_GT(std::abs(on - off), 1e-3 * off);
  fs::remove_all(out);
}

}  // namespace
