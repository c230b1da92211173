#include "server/service/discretization_table.hpp"

#include "server/service/csv_fields.hpp"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace neurosim::service {

namespace {

constexpr const char* kHeader =
    "scene,element,poisson_ratio,host_vertices,host_tetrahedra,discretization_error";

}  // namespace

DiscretizationTable DiscretizationTable::read(const std::filesystem::path& file) {
  CsvFields in(file, "discretization table");
  in.header({kHeader});
  std::vector<Row> rows;
  while (in.next()) {
    in.split(6);
    Row r;
    r.scene = in.text(0);
    const auto element = fem::parse_element(in.text(1));
    if (!element)
      in.fail("unknown element '" + in.text(1) + "' (known: " + fem::element_names() + ")");
    r.element = *element;
    r.poisson_ratio = in.number(2, "poisson_ratio");
    r.host_vertices = in.count(3, "host_vertices");
    r.host_tetrahedra = in.count(4, "host_tetrahedra");
    r.discretization_error = in.number(5, "discretization_error");
    rows.push_back(std::move(r));
  }
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
