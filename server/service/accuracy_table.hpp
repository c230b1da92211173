// The tiers' measured force error against strain (share/accuracy/force_error.csv, written by
// accuracy_bench): what the server reports as the expected tool-force error of the tier that
// runs at the largest strain in the field (SimStatus.expected_force_error).
#pragma once

#include "server/fem/tier.hpp"

#include <filesystem>
#include <limits>
#include <string>
#include <vector>

namespace neurosim::service {

struct ExpectedError {
  bool known{false};          // the table has rows for this tier
  double force_rel_error{0};  // fraction (0.09 = 9 %)
  bool beyond_table{false};   // strain above every measured one: the largest measured error
  std::string basis;          // the scene whose rows were used
};

class AccuracyTable {
 public:
  struct Row {
    std::string scene;
    fem::Tier tier{fem::Tier::kLinear};
    double max_strain{0.0};       // dimensionless
    double force_rel_error{0.0};  // fraction
    // The element and host nu it was measured with; "" / NaN in a table of the old header
    // (measured before the element axis: such rows match no element-specific lookup).
    std::string element;
    double poisson_ratio{std::numeric_limits<double>::quiet_NaN()};
  };

  // CSV with '#' comment lines and the header
  // "scene,tier,max_strain,force_rel_error,element,poisson_ratio" (or the old
  // "scene,tier,max_strain,force_rel_error"). Throws std::runtime_error naming the file and line
  // on a missing file, a bad header, an unknown tier or element, a row of a withdrawn tier
  // (fem::tier_served: COROTATIONAL, which no scene runs), or a value that is not a finite
  // number >= 0.
  static AccuracyTable read(const std::filesystem::path& file);
  explicit AccuracyTable(std::vector<Row> rows);

  // The expected error of `tier` at `strain`: the rows of `scene` if it has any for the tier,
  // else those of every scene. Interpolated linearly in strain over the upper envelope of the
  // measured errors (non-decreasing in strain, from 0 at zero strain), so an estimate is never
  // below a measured error at a smaller strain; above the largest measured strain, the largest
  // error with beyond_table set. A non-empty `element` (fem::element_name) and a finite
  // `poisson_ratio` keep only the rows measured with that element and nu (within 1e-9): the
  // server's lookup, which says unknown rather than use another element's error.
  ExpectedError expected(fem::Tier tier, double strain, const std::string& scene,
                         const std::string& element = {},
                         double poisson_ratio = std::numeric_limits<double>::quiet_NaN()) const;

  const std::vector<Row>& rows() const { return rows_; }

 private:
  std::vector<Row> rows_;
};

}  // namespace neurosim::service
