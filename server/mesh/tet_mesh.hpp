// Tetrahedral mesh: rest geometry (metres), connectivity, surface and adjacency.
//
// A TetMesh is built once (from a file, a generator or arrays) and is then constant:
// it is part of the Model, never of the per-step State.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>  // Vec3::cross

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace neurosim::mesh {

using Vec3 = Eigen::Vector3d;
using Tet = std::array<int, 4>;
using Tri = std::array<int, 3>;

// Options for TetMesh::build.
struct BuildOptions {
  // Drop vertices no tetrahedron uses (CGAL's Medit output has some). The original index of
  // every kept vertex stays in TetMesh::source_vertex_ids.
  bool drop_unused_vertices{true};
  // A tetrahedron whose |volume| <= degenerate_volume_ratio * (mean edge length)^3 is refused.
  double degenerate_volume_ratio{1e-12};
  // Where the data came from, for messages ("brain.mesh", "generated cube").
  std::string source{"<memory>"};
};

class TetMesh {
 public:
  // Validates and builds: coordinates finite, indices in range, no repeated vertex in a
  // tetrahedron; inverted tetrahedra are reoriented (counted, with a warning on stderr);
  // degenerate ones are refused with their ids (std::invalid_argument).
  // Then computes the surface and the adjacency.
  static TetMesh build(std::vector<Vec3> vertices_m, std::vector<Tet> tets,
                       const BuildOptions& options = {});

  const std::vector<Vec3>& vertices() const { return vertices_; }  // rest positions, unit m
  const std::vector<Tet>& tets() const { return tets_; }            // positive volume order
  // Per-tetrahedron label (subdomain id from the file; 0 when the file has none).
  const std::vector<int>& tet_labels() const { return tet_labels_; }
  void set_tet_labels(std::vector<int> labels);

  // Boundary faces (faces that belong to exactly one tetrahedron), oriented outward
  // (right-hand normal points out of the mesh), and the tetrahedron each belongs to.
  const std::vector<Tri>& surface() const { return surface_; }
  const std::vector<int>& surface_tet() const { return surface_tet_; }
  // Vertices on the surface, sorted ascending.
  const std::vector<int>& surface_vertices() const { return surface_vertices_; }

  // neighbours()[t][k]: tetrahedron across the face opposite local vertex k, or -1 (surface).
  const std::vector<std::array<int, 4>>& neighbours() const { return neighbours_; }
  // Tetrahedra around vertex v: vertex_tets(v) in CSR form.
  const std::vector<int>& vertex_tet_offsets() const { return vertex_tet_offsets_; }
  const std::vector<int>& vertex_tet_list() const { return vertex_tet_list_; }

  // Index in the source of each kept vertex (identity unless unused vertices were dropped).
  const std::vector<int>& source_vertex_ids() const { return source_vertex_ids_; }
  int inverted_fixed() const { return inverted_fixed_; }  // reoriented tetrahedra at build

  std::size_t num_vertices() const { return vertices_.size(); }
  std::size_t num_tets() const { return tets_.size(); }
  const std::string& source() const { return source_; }

  // Signed volume of tetrahedron t (m^3); positive after build.
  double tet_volume(int t) const;
  // Axis-aligned bounds of the rest configuration (m).
  void bounds(Vec3& lo, Vec3& hi) const;
  // Mean edge length (m), over all tetrahedron edges.
  double mean_edge_length() const;

 private:
  std::string source_;
  std::vector<Vec3> vertices_;
  std::vector<Tet> tets_;
  std::vector<int> tet_labels_;
  std::vector<Tri> surface_;
  std::vector<int> surface_tet_;
  std::vector<int> surface_vertices_;
  std::vector<std::array<int, 4>> neighbours_;
  std::vector<int> vertex_tet_offsets_;
  std::vector<int> vertex_tet_list_;
  std::vector<int> source_vertex_ids_;
  int inverted_fixed_{0};
};

// Local faces of a tetrahedron: face k is opposite vertex k, ordered so that with a
// positively oriented tetrahedron its normal points outward.
inline constexpr std::array<std::array<int, 3>, 4> kTetFaces{
    {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}}};

// Signed volume (m^3) of (a, b, c, d): ((b-a) x (c-a)) . (d-a) / 6.
double signed_volume(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d);

}  // namespace neurosim::mesh
