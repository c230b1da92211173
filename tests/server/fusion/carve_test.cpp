// Carving: the host tetrahedra enclosed by S' around an embedded box are the ones inside it, no
// tetrahedron on the host's surface is among them, and an open cut carves nothing.
#include "server/fusion/carve.hpp"

#include "server/fusion/inclusion.hpp"
#include "server/fusion/triangle_surface.hpp"
#include "server/mesh/generate.hpp"

#include <gtest/gtest.h>

#include <algorithm>

namespace neurosim::fusion {
namespace {

mesh::TetMesh box(const mesh::Vec3& lo, const mesh::Vec3& hi, double cell_m) {
  mesh::MeshingOptions o;
  o.cell_size_m = cell_m;
  o.seed = 3;
  return mesh::generate_box(lo, hi, o).mesh;
}

TEST(FusionCarve, TetrahedraEnclosedByTheNewBoundaryAreTheOnesAroundTheEmbeddedBox) {
  const mesh::TetMesh host = box({0, 0, 0}, {0.04, 0.04, 0.04}, 0.004);
  const mesh::TetMesh inner = box({0.012, 0.012, 0.012}, {0.028, 0.028, 0.028}, 0.004);
  const NewBoundary b = find_new_boundary(host, TriangleSurface::of(inner, "inner"));
  const std::vector<char> inside = tets_inside(host, b.triangles);
  ASSERT_EQ(inside.size(), host.num_tets());
  int carved = 0;
  for (std::size_t t = 0; t < inside.size(); ++t) {
    if (!inside[t]) continue;
    ++carved;
    mesh::Vec3 c = mesh::Vec3::Zero();
    for (int v : host.tets()[t]) c += 0.25 * host.vertices()[v];
    // Within a cell of the embedded box.
    EXPECT_TRUE((c.array() > 0.012 - 0.006).all() && (c.array() < 0.028 + 0.006).all())
        << "tet " << t;
  }
  EXPECT_GT(carved, 0);
  for (int t : host.surface_tet()) EXPECT_FALSE(inside[t]) << "surface tet " << t;
  // No cut at all: nothing is enclosed.
  const std::vector<char> none = tets_inside(host, {});
  EXPECT_EQ(std::count(none.begin(), none.end(), 1), 0);
}

}  // namespace
}  // namespace neurosim::fusion
