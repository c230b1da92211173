// Inclusion decision (paper 2.5, Algorithm 1): the new boundary S' of a host mesh A around an
// embedded mesh B of higher priority.
//
// Semantics (identical in both versions below, all predicates exact):
// - A face of A "intersects B" when the closed face triangle and a closed surface triangle of B
//   share at least one point (touching, shared vertices/edges and coplanar overlap count).
// - For each tetrahedron of A, count its faces that intersect B; if 0 < count < 4 its other
//   faces are candidates (Algorithm 1 counts face/triangle pairs; we count faces,
//   so a face crossing two of B's triangles is one face).
// - A candidate face touches no triangle of B, so it lies entirely inside or entirely outside
//   the closed surface; it is kept when its vertices are outside (tested on one vertex by
//   segment parity with exact orientation predicates).
// - Each face of S' is reported once, oriented outward from the lowest-index tetrahedron that
//   contributed it, in tetrahedron order.
#pragma once

#include "server/fusion/triangle_surface.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <cstddef>
#include <vector>

namespace neurosim::fusion {

struct InclusionStats {
  std::size_t host_tets{0};
  // Table 3's "inside triangles": interior faces of A counted once per tetrahedron,
  // 4 * tets - surface faces (each interior face twice). Depends on A only.
  std::size_t inside_triangles{0};
  std::size_t tets_checked{0};       // tetrahedra tested face by face
  std::size_t tets_culled{0};        // tetrahedra skipped by a box test
  std::size_t face_queries{0};       // face-against-surface queries (brute: 4 per tet)
  std::size_t triangle_tests{0};     // exact triangle-triangle predicates evaluated
  std::size_t point_queries{0};      // inside/outside parity queries
  std::size_t intersected_faces{0};  // distinct faces of A that meet B's surface
  std::size_t intersected_tets{0};   // tetrahedra with count > 0
  std::size_t partial_tets{0};       // tetrahedra with 0 < count < 4
  std::size_t bvh_bytes{0};          // memory of the hierarchy over B's triangles (fast only)
};

struct NewBoundary {
  std::vector<mesh::Tri> triangles;  // S' on A's vertex ids
  std::vector<int> source_tet;       // per triangle: the tetrahedron of A that contributed it
  InclusionStats stats;

  // Vertices of A used by S', sorted ascending.
  std::vector<int> vertices() const;
};

struct InclusionOptions {
  // Check B (closed, finite, in range, no degenerate triangle) before use; throws
  // std::invalid_argument naming open edges / bad triangles.
  bool validate_embedded{true};
  // One hierarchy descent per tetrahedron collects B's triangles overlapping its box; its
  // faces are tested against those only (false: one descent per face, for comparison).
  // Either way a tetrahedron whose box overlaps no triangle box of B is skipped.
  bool candidates_per_tetrahedron{true};
};

// Reference: Algorithm 1 as written — every face of every tetrahedron against every triangle of
// B, inside/outside against every triangle. Only the whole-mesh box test of step 2 culls.
NewBoundary find_new_boundary_bruteforce(const mesh::TetMesh& host,
                                         const TriangleSurface& embedded);

// Same result, fast: box culling of tetrahedra, an AABB tree over B's triangles, one exact
// test per distinct face (shared faces are cached) and one parity test per vertex.
NewBoundary find_new_boundary(const mesh::TetMesh& host, const TriangleSurface& embedded,
                              const InclusionOptions& options = {});

// Exact: is point p strictly outside the closed surface? p must not lie on the surface
// (throws std::invalid_argument if it does). Uses every triangle (no hierarchy).
bool outside_closed_surface(const Vec3& p_m, const TriangleSurface& surface);

// The same test for many points through one hierarchy over the surface's triangles (validated
// closed first): per point 1 when strictly outside, 0 when inside. Throws
// std::invalid_argument if a point lies on the surface.
std::vector<char> outside_closed_surface(const std::vector<Vec3>& points_m,
                                         const TriangleSurface& surface);

}  // namespace neurosim::fusion
