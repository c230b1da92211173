// JSON summaries keep key order, write null for NaN, end with a newline.
#include "common/json.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace nc = neurosim::common;

TEST(common_json, KeyOrderNullAndFile) {
  nc::Json j;
  j["zeta"] = 1.5;
  j["alpha"] = std::uint64_t{300};
  j["missing"] = nullptr;
  j["nan"] = std::nan("");
  const std::string text = nc::to_text(j);
  EXPECT_EQ(text, "{\n  \"zeta\": 1.5,\n  \"alpha\": 300,\n  \"missing\": null,\n  \"nan\": null\n}\n");

  const auto dir = neurosim::testing::temp_dir("common_json");
  nc::write_json((dir / "s.json").string(), j);
  std::ifstream f(dir / "s.json");
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()), text);
  EXPECT_THROW(nc::write_json((dir / "no/such/dir/s.json").string(), j), std::runtime_error);
  std::filesystem::remove_all(dir);
}
