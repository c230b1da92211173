#include "common/json.hpp"

#include <fstream>
#include <stdexcept>

namespace neurosim::common {

std::string to_text(const Json& j) { return j.dump(2) + "\n"; }

void write_json(const std::string& file, const Json& j) {
  std::ofstream f(file);
  if (!f) throw std::runtime_error(file + ": cannot open for writing");
  f << to_text(j);
  f.close();
  if (!f) throw std::runtime_error(file + ": write failed");
}

}  // namespace neurosim::common
