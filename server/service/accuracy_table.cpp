#include "server/service/accuracy_table.hpp"

#include "server/fem/element.hpp"

#include <algorithm>
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
  if (used == 0 || used != text.size() || !std::isfinite(v) || v < 0.0) {
    throw std::runtime_error(where + ": '" + text + "' is not a finite number >= 0");
  }
  return v;
}

}  // namespace

AccuracyTable AccuracyTable::read(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error(file.string() + ": cannot open the accuracy table");
  std::vector<Row> rows;
  std::string line;
  int n = 0;
  bool header = false;
  std::size_t fields = 4;
  while (std::getline(in, line)) {
    ++n;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    const std::string where = file.string() + ":" + std::to_string(n);
    if (!header) {
      if (line == "scene,tier,max_strain,force_rel_error") {
        fields = 4;
      } else if (line == "scene,tier,max_strain,force_rel_error,element,poisson_ratio") {
        fields = 6;
      } else {
        throw std::runtime_error(where + ": expected the header "
                                         "'scene,tier,max_strain,force_rel_error,element,"
                                         "poisson_ratio', got '" +
                                 line + "'");
      }
      header = true;
      continue;
    }
    const auto f = split(line);
    if (f.size() != fields) {
      throw std::runtime_error(where + ": " + std::to_string(f.size()) + " fields, expected " +
                               std::to_string(fields));
    }
    Row r;
    r.scene = f[0];
    const auto tier = fem::parse_tier(f[1]);
    if (!tier) throw std::runtime_error(where + ": unknown tier '" + f[1] + "'");
    r.tier = *tier;
    r.max_strain = number(f[2], where + " max_strain");
    r.force_rel_error = number(f[3], where + " force_rel_error");
    if (fields == 6) {
      if (!fem::parse_element(f[4]))
        throw std::runtime_error(where + ": unknown element '" + f[4] + "' (known: " +
                                 fem::element_names() + ")");
      r.element = f[4];
      r.poisson_ratio = number(f[5], where + " poisson_ratio");
    }
    rows.push_back(std::move(r));
  }
  if (!header) throw std::runtime_error(file.string() + ": no header line (empty table)");
  return AccuracyTable(std::move(rows));
}

AccuracyTable::AccuracyTable(std::vector<Row> rows) : rows_(std::move(rows)) {}

ExpectedError AccuracyTable::expected(fem::Tier tier, double strain, const std::string& scene,
                                      const std::string& element, double poisson_ratio) const {
  ExpectedError out;
  const auto fits = [&](const Row& r) {
    if (r.tier != tier) return false;
    if (!element.empty() && r.element != element) return false;
    if (std::isfinite(poisson_ratio) &&
        !(std::isfinite(r.poisson_ratio) && std::abs(r.poisson_ratio - poisson_ratio) <= 1e-9))
      return false;
    return true;
  };
  std::vector<std::pair<double, double>> pts;
  for (const auto& r : rows_)
    if (fits(r) && r.scene == scene) pts.emplace_back(r.max_strain, r.force_rel_error);
  out.basis = scene;
  if (pts.empty()) {
    for (const auto& r : rows_)
      if (fits(r)) pts.emplace_back(r.max_strain, r.force_rel_error);
    out.basis = "every scene";
  }
  if (!element.empty()) out.basis += ", " + element;
  if (pts.empty() || !std::isfinite(strain)) return out;
  out.known = true;
  std::sort(pts.begin(), pts.end());
  // Upper envelope: non-decreasing in strain, starting from (0, 0).
  std::vector<std::pair<double, double>> env{{0.0, 0.0}};
  for (const auto& p : pts) {
    const double e = std::max(p.second, env.back().second);
    if (p.first == env.back().first) env.back().second = e;
    else env.emplace_back(p.first, e);
  }
  strain = std::max(0.0, strain);
  if (strain >= env.back().first) {
    out.force_rel_error = env.back().second;
    out.beyond_table = strain > env.back().first;
    return out;
  }
  for (std::size_t i = 1; i < env.size(); ++i) {
    if (strain <= env[i].first) {
      const double s0 = env[i - 1].first, s1 = env[i].first;
      const double w = s1 > s0 ? (strain - s0) / (s1 - s0) : 1.0;
      out.force_rel_error = env[i - 1].second + w * (env[i].second - env[i - 1].second);
      return out;
    }
  }
  return out;
}

}  // namespace neurosim::service
