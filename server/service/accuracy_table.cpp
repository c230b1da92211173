#include "server/service/accuracy_table.hpp"

#include "server/fem/element.hpp"
#include "server/fem/served_tiers.hpp"
#include "server/service/csv_fields.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace neurosim::service {

namespace {

constexpr const char* kHeader = "scene,tier,max_strain,force_rel_error,element,poisson_ratio";
// The header before the element axis (4 fields).
constexpr const char* kOldHeader = "scene,tier,max_strain,force_rel_error";

}  // namespace

AccuracyTable AccuracyTable::read(const std::filesystem::path& file) {
  CsvFields in(file, "accuracy table");
  const std::size_t fields = in.header({kHeader, kOldHeader});
  std::vector<Row> rows;
  while (in.next()) {
    in.split(fields);
    Row r;
    r.scene = in.text(0);
    const auto tier = fem::parse_tier(in.text(1));
    if (!tier) in.fail("unknown tier '" + in.text(1) + "'");
    // A withdrawn tier's rows would never be read (no scene runs it): a stale table.
    if (!fem::tier_served(*tier))
      in.fail("tier '" + in.text(1) + "' is withdrawn (no scene runs it): remove its rows");
    r.tier = *tier;
    r.max_strain = in.number(2, "max_strain");
    r.force_rel_error = in.number(3, "force_rel_error");
    if (fields == 6) {
      if (!fem::parse_element(in.text(4)))
        in.fail("unknown element '" + in.text(4) + "' (known: " + fem::element_names() + ")");
      r.element = in.text(4);
      r.poisson_ratio = in.number(5, "poisson_ratio");
    }
    rows.push_back(std::move(r));
  }
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
