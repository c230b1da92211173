// VTK XML UnstructuredGrid (.vtu) files: results with point and cell data that open in ParaView.
// Tetrahedral meshes and triangle surfaces are written the same way (cell type 10 or 5).
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::mesh {

// A named data array: values.size() == count * components, components fastest
// (x0 y0 z0 x1 y1 z1 ... for a 3-vector). Say the unit in the name: "displacement_m".
struct VtuField {
  std::string name;
  int components{1};
  std::vector<double> values;
};

VtuField make_field(std::string name, const std::vector<double>& scalars);
VtuField make_field(std::string name, const std::vector<int>& scalars);  // labels, ids
VtuField make_field(std::string name, const std::vector<Vec3>& vectors);

// s with &, <, > and " as XML entities (attribute values and text of .vtu/.pvd files).
std::string xml_escape(const std::string& s);

// Writes an ASCII .vtu (exact round-trip doubles). Throws std::invalid_argument on a
// non-finite point or value (naming field and index), a field of the wrong size or an index
// out of range; std::runtime_error when the file cannot be written.
void write_vtu(const std::string& path, const std::vector<Vec3>& points_m,
               const std::vector<Tet>& tets, const std::vector<VtuField>& point_data = {},
               const std::vector<VtuField>& cell_data = {});
void write_vtu(const std::string& path, const std::vector<Vec3>& points_m,
               const std::vector<Tri>& triangles, const std::vector<VtuField>& point_data = {},
               const std::vector<VtuField>& cell_data = {});
// The mesh's rest geometry; its tet labels are added as cell data "label".
void write_vtu(const std::string& path, const TetMesh& mesh,
               const std::vector<VtuField>& point_data = {},
               const std::vector<VtuField>& cell_data = {});

// What read_vtu returns: tets or triangles (one cell type per file), and the data arrays.
struct VtuData {
  std::vector<Vec3> points_m;
  std::vector<Tet> tets;
  std::vector<Tri> triangles;
  std::vector<VtuField> point_data;
  std::vector<VtuField> cell_data;
  // nullptr when absent.
  const VtuField* point_field(const std::string& name) const;
  const VtuField* cell_field(const std::string& name) const;
};

// Reads ASCII .vtu files with tetrahedron or triangle cells (as write_vtu writes them).
// Throws std::runtime_error("path:line: ...") otherwise.
VtuData read_vtu(const std::string& path);

}  // namespace neurosim::mesh
