// The discretization error (element + mesh) of a host mesh against the converged answer
// (share/accuracy/discretization_error.csv: the brain's rows by press_refinement_bench, a patch
// press on nested refinements of the mesh extrapolated to the continuum; the cube's by
// accuracy_bench, the same on the whole cube's patch press): the part of SimStatus's
// total error estimate the tier table (accuracy_table.hpp, the tier against NONLINEAR on the same
// mesh and element) leaves out. Looked up once at set-up for the host that runs; no row: unknown,
// never a guess.
#pragma once

#include "server/fem/element.hpp"

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace neurosim::service {

class DiscretizationTable {
 public:
  struct Row {
    std::string scene;              // the scene it was measured on (for messages)
    fem::Element element{fem::Element::kLinearTet};
    double poisson_ratio{0.0};      // the host's nu, dimensionless
    std::size_t host_vertices{0};
    std::size_t host_tetrahedra{0};
    double discretization_error{0.0};  // fraction vs the converged answer (0.08 = 8 %)
  };

  // CSV with '#' comment lines and the header
  // "scene,element,poisson_ratio,host_vertices,host_tetrahedra,discretization_error". Throws
  // std::runtime_error naming the file and line on a missing file, a bad header, an unknown
  // element, or a value that is not a finite number >= 0.
  static DiscretizationTable read(const std::filesystem::path& file);
  explicit DiscretizationTable(std::vector<Row> rows);

  // The row of this host: same element, nu within 1e-9 and the same vertex and tetrahedron
  // counts (the mesh); nullopt when there is none.
  std::optional<Row> find(fem::Element element, double poisson_ratio, std::size_t vertices,
                          std::size_t tetrahedra) const;

  const std::vector<Row>& rows() const { return rows_; }

 private:
  std::vector<Row> rows_;
};

}  // namespace neurosim::service
