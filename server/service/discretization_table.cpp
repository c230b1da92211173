#include "server/service/discretization_table.hpp"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace neurosim::service {

namespace {

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

double number(const std::string& text, const std::string& where) {
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || !std::isfinite(v) || v < 0.0)
    throw std::runtime_error(where + ": '" + text + "' is not a finite number >= 0");
  return v;
}

std::size_t count(const std::string& text, const std::string& where) {
  const double v = number(text, where);
  if (v != std::floor(v) || v < 1.0)
    throw std::runtime_error(where + ": '" + text + "' is not a count >= 1");
  return static_cast<std::size_t>(v);
}

constexpr const char* kHeader =
    "scene,element,poisson_ratio,host_vertices,host_tetrahedra,discretization_error";

}  // namespace

DiscretizationTable DiscretizationTable::read(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error(file.string() + ": cannot open the discretization table");
  std::vector<Row> rows;
  std::string line;
  int n = 0;
  bool header = false;
  while (std::getline(in, line)) {
    ++n;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    const std::string where = file.string() + ":" + std::to_string(n);
    if (!header) {
      if (line != kHeader)
        throw std::runtime_error(where + ": expected the header '" + kHeader + "', got '" + line +
                                 "'");
      header = true;
      continue;
    }
    const auto f = split(line);
    if (f.size() != 6)
      throw std::runtime_error(where + ": " + std::to_string(f.size()) + " fields, expected 6");
    Row r;
    r.scene = f[0];
    const auto element = fem::parse_element(f[1]);
    if (!element)
      throw std::runtime_error(where + ": unknown element '" + f[1] + "' (known: " +
                               fem::element_names() + ")");
    r.element = *element;
    r.poisson_ratio = number(f[2], where + " poisson_ratio");
    r.host_vertices = count(f[3], where + " host_vertices");
    r.host_tetrahedra = count(f[4], where + " host_tetrahedra");
    r.discretization_error = number(f[5], where + " discretization_error");
    rows.push_back(std::move(r));
  }
  if (!header) throw std::runtime_error(file.string() + ": no header line (empty table)");
  return DiscretizationTable(std::move(rows));
}

DiscretizationTable::DiscretizationTable(std::vector<Row> rows) : rows_(std::move(rows)) {}

std::optional<DiscretizationTable::Row> DiscretizationTable::find(fem::Element element,
                                                                  double poisson_ratio,
                                                                  std::size_t vertices,
                                                                  std::size_t tetrahedra) const {
  for (const auto& r : rows_)
    if (r.element == element && std::abs(r.poisson_ratio - poisson_ratio) <= 1e-9 &&
        r.host_vertices == vertices && r.host_tetrahedra == tetrahedra)
      return r;
  return std::nullopt;
}

}  // namespace neurosim::service
