// Carving: the host tetrahedra enclosed by S' around an embedded box are the ones inside it, no
// tetrahedron on the host's surface is among them, and an empty cut carves nothing; for enclosed
// embedded meshes the flood from S' carves exactly what a flood from the host's surface leaves;
// an embedded box that crosses the host's surface is carved too (no host tetrahedron left inside
// it), where the flood from the surface carves nothing.
#include "server/fusion/carve.hpp"

#include "server/fusion/inclusion.hpp"
#include "server/fusion/paper_models.hpp"
#include "server/fusion/triangle_surface.hpp"
#include "server/mesh/generate.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>

namespace neurosim::fusion {
namespace {

mesh::TetMesh box(const mesh::Vec3& lo, const mesh::Vec3& hi, double cell_m) {
  mesh::MeshingOptions o;
  o.cell_size_m = cell_m;
  o.seed = 3;
  return mesh::generate_box(lo, hi, o).mesh;
}

// The reference for an enclosed S': the tetrahedra a flood from the host's surface tetrahedra
// cannot reach without crossing a face of S'.
std::vector<char> not_reached_from_surface(const mesh::TetMesh& host, const NewBoundary& cut) {
  std::vector<std::array<int, 3>> faces;
  for (const auto& t : cut.triangles) {
    std::array<int, 3> f{t[0], t[1], t[2]};
    std::sort(f.begin(), f.end());
    faces.push_back(f);
  }
  std::sort(faces.begin(), faces.end());
  std::vector<char> reached(host.num_tets(), 0);
  std::vector<int> stack;
  for (int t : host.surface_tet())
    if (!reached[t]) reached[t] = 1, stack.push_back(t);
  while (!stack.empty()) {
    const int t = stack.back();
    stack.pop_back();
    for (int k = 0; k < 4; ++k) {
      const int nb = host.neighbours()[t][k];
      if (nb < 0 || reached[nb]) continue;
      std::array<int, 3> f{};
      for (int a = 0; a < 3; ++a) f[a] = host.tets()[t][mesh::kTetFaces[k][a]];
      std::sort(f.begin(), f.end());
      if (std::binary_search(faces.begin(), faces.end(), f)) continue;
      reached[nb] = 1;
      stack.push_back(nb);
    }
  }
  for (auto& r : reached) r = !r;
  return reached;
}

TEST(FusionCarve, TetrahedraEnclosedByTheNewBoundaryAreTheOnesAroundTheEmbeddedBox) {
  const mesh::TetMesh host = box({0, 0, 0}, {0.04, 0.04, 0.04}, 0.004);
  const mesh::TetMesh inner = box({0.012, 0.012, 0.012}, {0.028, 0.028, 0.028}, 0.004);
  const NewBoundary b = find_new_boundary(host, TriangleSurface::of(inner, "inner"));
  const std::vector<char> inside = tets_inside(host, b);
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
  EXPECT_EQ(inside, not_reached_from_surface(host, b));
  // No cut at all: nothing is enclosed.
  const std::vector<char> none = tets_inside(host, NewBoundary{});
  EXPECT_EQ(std::count(none.begin(), none.end(), 1), 0);
  // A cut whose source list does not match its triangles is refused.
  NewBoundary bad = b;
  bad.source_tet.pop_back();
  EXPECT_THROW(tets_inside(host, bad), std::invalid_argument);
}

TEST(FusionCarve, EnclosedMeshesCarveAsTheFloodFromTheHostSurface) {
  // The paper's cube and cylinder, and the brain-sized box with its long oblique artery.
  const MeshPair pairs[] = {make_cube_cylinder(1500), make_brain_like(3000, 800)};
  for (const auto& p : pairs) {
    const NewBoundary b = find_new_boundary(p.host, TriangleSurface::of(p.embedded, "embedded"));
    const std::vector<char> inside = tets_inside(p.host, b);
    EXPECT_GT(std::count(inside.begin(), inside.end(), 1), 0) << p.description;
    EXPECT_EQ(inside, not_reached_from_surface(p.host, b)) << p.description;
  }
}

TEST(FusionCarve, BoxCrossingTheHostSurfaceIsCarved) {
  // The host cube [0, 40 mm]^3; the embedded box from z = 12 mm to 60 mm leaves it by its top.
  const mesh::TetMesh host = box({0, 0, 0}, {0.04, 0.04, 0.04}, 0.004);
  const mesh::Vec3 lo(0.012, 0.012, 0.012), hi(0.028, 0.028, 0.06);
  const mesh::TetMesh inner = box(lo, hi, 0.004);
  const NewBoundary b = find_new_boundary(host, TriangleSurface::of(inner, "inner"));
  const std::vector<char> inside = tets_inside(host, b);
  // A flood from the host's surface reaches everything through the opening.
  const std::vector<char> old = not_reached_from_surface(host, b);
  EXPECT_EQ(std::count(old.begin(), old.end(), 1), 0);
  int carved = 0, surface_carved = 0;
  for (std::size_t t = 0; t < inside.size(); ++t) {
    mesh::Vec3 c = mesh::Vec3::Zero();
    for (int v : host.tets()[t]) c += 0.25 * host.vertices()[v];
    const bool centre_in_b = (c.array() > lo.array()).all() && (c.array() < hi.array()).all();
    if (inside[t]) {
      ++carved;
      // Meets B or lies in it: within a cell of B.
      EXPECT_TRUE((c.array() > lo.array() - 0.006).all() && (c.array() < hi.array() + 0.006).all())
          << "tet " << t;
    } else {
      // A kept tetrahedron neither meets B's surface nor lies inside B: host and B never
      // overlap.
      EXPECT_FALSE(centre_in_b) << "kept tet " << t << " has its centre inside B";
    }
  }
  for (int t : host.surface_tet()) surface_carved += inside[t];
  EXPECT_GT(carved, 0);
  EXPECT_GT(surface_carved, 0);  // the opening in the host's top
}

}  // namespace
}  // namespace neurosim::fusion
