// neurosim-model --skull: the skull is a closed surface outside the brain with a CSF gap, open
// where the scene's craniotomy is; AAL regions put the cerebellum posterior-inferior with a
// plausible volume. The scene's properties are checked on the tests' 7 mm brain under the skull
// (brain7_scene("brain_skull"): neurosim-model --skull --cell-size 7, built once at build time
// and rebuilt whenever neurosim-model changes, tests/CMakeLists.txt); the build's own report
// (ModelResult: region statistics, triangle count) on one in-process build_model with the same
// options, whose files must equal the build-time ones byte for byte.
#include "tools/model/skull.hpp"
#include "server/mesh/tri_surface.hpp"
#include "server/scene/compile.hpp"
#include "test_support.hpp"
#include "tools/model/model.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <random>

namespace {

namespace model = neurosim::model;
namespace scene = neurosim::scene;
using neurosim::mesh::Tri;
using neurosim::mesh::Vec3;

struct Built {
  std::filesystem::path dir;
  model::ModelOptions options;
  model::ModelResult result;
  std::unique_ptr<scene::Model> scene_model;
};

Built& built() {
  static Built* b = [] {
    auto* out = new Built;
    out->dir = neurosim::testing::temp_dir("skull_model");
    out->options.out_dir = out->dir;
    out->options.name = "brain_skull";
    out->options.skull = true;
    // The paper-size brain (7 mm cells), not the bundled 5 mm one: the skull and its opening do
    // not depend on the brain's cell size (skull.mesh is byte-identical at both), the regions
    // move by less than 1 % (cerebrum 1355 / 1358 ml at 7 / 5 mm), and every test of this suite
    // builds the model in its own process (about 7 s at 7 mm, 17 s at 5 mm, idle machine).
    out->options.brain_cell_size_mm = 7.0;
    out->result = model::build_model(out->options);
    out->scene_model = std::make_unique<scene::Model>(scene::load_model(out->result.scene));
    return out;
  }();
  return *b;
}

// The same model as built() (the same options: neurosim-model's defaults with --skull
// --cell-size 7), written at build time: the tests of the scene's geometry load it instead of
// building the model again in their own process (gtest_discover_tests runs each test alone).
const scene::Model& scene_model() {
  static const scene::Model* m =
      new scene::Model(scene::load_model(neurosim::testing::brain7_scene("brain_skull")));
  return *m;
}

// Closest distance from p to triangle abc (Ericson, Real-Time Collision Detection, 5.1.5).
double point_triangle_distance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return (p - a).norm();
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return (p - b).norm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (p - (a + d1 / (d1 - d3) * ab)).norm();
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return (p - c).norm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (p - (a + d2 / (d2 - d6) * ac)).norm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return (p - (b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b))).norm();
  const double denom = 1.0 / (va + vb + vc);
  return (p - (a + ab * vb * denom + ac * vc * denom)).norm();
}

// Parity of the crossings of a ray from p (a fixed, generic direction) with the surface: odd
// means inside the skull's solid bone.
bool inside_solid(const Vec3& p, const scene::RigidSurface& s) {
  const Vec3 dir = Vec3(0.5773, 0.6123, 0.5401).normalized();
  int crossings = 0;
  for (const Tri& t : s.triangles) {
    const Vec3 &a = s.vertices_m[t[0]], &b = s.vertices_m[t[1]], &c = s.vertices_m[t[2]];
    // Moller-Trumbore.
    const Vec3 e1 = b - a, e2 = c - a, h = dir.cross(e2);
    const double det = e1.dot(h);
    if (std::abs(det) < 1e-18) continue;
    const Vec3 q = p - a;
    const double u = q.dot(h) / det;
    if (u < 0 || u > 1) continue;
    const Vec3 w = q.cross(e1);
    const double v = dir.dot(w) / det;
    if (v < 0 || u + v > 1) continue;
    if (e2.dot(w) / det > 0) ++crossings;
  }
  return crossings % 2 == 1;
}

TEST(SkullModel, SkullIsAClosedOutwardSurfaceOfServerSize) {
  const auto& m = scene_model();
  ASSERT_EQ(m.rigid.size(), 1u);
  const auto& s = m.rigid[0];
  EXPECT_EQ(s.id, "skull");
  const auto r = neurosim::mesh::check_closed(s.vertices_m, s.triangles);
  EXPECT_TRUE(r.closed()) << r.first_problem;
  EXPECT_EQ(r.boundary_edges + r.nonmanifold_edges + r.misoriented_edges, 0);
  EXPECT_EQ(2 * r.edges, 3 * r.triangles);  // every edge shared by exactly two triangles
  // Bone volume: the shell of ~6.5 mm over a brain of ~1.7 l is a few hundred ml (an adult
  // cranial vault: some 500-700 ml).
  EXPECT_GT(r.volume_m3, 150e-6);
  EXPECT_LT(r.volume_m3, 800e-6);
  EXPECT_GE(r.triangles, 5000);
  EXPECT_LE(r.triangles, 20000);
  EXPECT_FALSE(s.provenance.empty());
}

TEST(SkullModel, BrainOutsideTheBoneWithACsfGap) {
  const auto& m = scene_model();
  const auto& brain = m.meshes[static_cast<std::size_t>(m.find_mesh("brain"))].mesh;
  const auto& s = m.rigid[0];
  double min_m = std::numeric_limits<double>::infinity();
  int inside = 0;
  for (int v : brain.surface_vertices()) {
    const Vec3& p = brain.vertices()[v];
    inside += inside_solid(p, s) ? 1 : 0;
    for (const Tri& t : s.triangles) {
      min_m = std::min(min_m, point_triangle_distance(p, s.vertices_m[t[0]], s.vertices_m[t[1]],
                                                      s.vertices_m[t[2]]));
    }
  }
  EXPECT_EQ(inside, 0);
  // Gap 3 mm between the brain mask and the inner table; both surfaces approximate their
  // level sets (brain facet distance 1.75 mm at the 7 mm cell, skull smoothing), hence 2 mm.
  const double gap_mm = model::SkullOptions{}.csf_gap_mm;
  std::cout << "brain surface -> skull: min distance " << min_m * 1e3 << " mm (gap " << gap_mm
            << " mm)\n";
  EXPECT_GE(min_m * 1e3, gap_mm - 2.0);
}

TEST(SkullModel, OpeningWhereTheSceneSaysOverTheCerebellum) {
  const auto& m = scene_model();
  const auto& s = m.rigid[0];
  ASSERT_EQ(s.openings.size(), 1u);
  const auto& o = s.openings[0];
  EXPECT_NEAR(o.radius_m, 0.015, 1e-12);
  EXPECT_FALSE(o.provenance.empty());
  // No bone inside the cut (less the smoothing's reach), bone just outside its radius.
  const double tol = 2e-3;
  int inside = 0, rim = 0;
  for (const Tri& t : s.triangles) {
    const Vec3 c = (s.vertices_m[t[0]] + s.vertices_m[t[1]] + s.vertices_m[t[2]]) / 3.0;
    if (std::abs(o.axial_m(c)) > o.half_length_m) continue;
    const double r = o.radial_m(c);
    if (r < o.radius_m - tol) ++inside;
    if (r > o.radius_m && r < o.radius_m + 8e-3) ++rim;
  }
  EXPECT_EQ(inside, 0);
  EXPECT_GT(rim, 20);
  // Through the hole the tool reaches the cerebellum: brain surface in the cylinder is mostly
  // cerebellum-labelled.
  const auto& lm = m.meshes[static_cast<std::size_t>(m.find_mesh("brain"))];
  int cerebellum = 0, other = 0;
  for (std::size_t k = 0; k < lm.mesh.surface().size(); ++k) {
    const auto& f = lm.mesh.surface()[k];
    const Vec3 c =
        (lm.mesh.vertices()[f[0]] + lm.mesh.vertices()[f[1]] + lm.mesh.vertices()[f[2]]) / 3.0;
    if (!o.contains(c)) continue;
    (lm.mesh.tet_labels()[lm.mesh.surface_tet()[k]] == model::kCerebellum ? cerebellum : other)++;
  }
  EXPECT_GT(cerebellum, 3);
  EXPECT_GT(cerebellum, 4 * other);
}

// The bone closes all round the craniotomy: on every line parallel to its axis at 5 and 15 mm
// outside its rim (16 directions), from 15 mm inside the head to 25 mm out, some point is bone.
// (The head's dark occipital bone once left the head mask open towards the neck, and with it
// the shell over the cerebellum: a hole several times the opening's size.)
TEST(SkullModel, BoneAllRoundTheOpening) {
  const auto& s = scene_model().rigid[0];
  ASSERT_EQ(s.openings.size(), 1u);
  const auto& o = s.openings[0];
  const Vec3 u = o.axis.unitOrthogonal(), v = o.axis.cross(u);
  constexpr double kPi = 3.14159265358979323846;
  for (double r : {o.radius_m + 5e-3, o.radius_m + 15e-3}) {
    for (int k = 0; k < 16; ++k) {
      const double a = 2 * kPi * k / 16;
      const Vec3 foot = o.center_m + r * (std::cos(a) * u + std::sin(a) * v);
      bool bone = false;
      for (double h = -15e-3; h <= 25e-3 && !bone; h += 0.5e-3)
        bone = inside_solid(foot + h * o.axis, s);
      EXPECT_TRUE(bone) << "no bone " << r * 1e3 << " mm from the opening's axis at angle "
                        << 360.0 * k / 16 << " deg";
    }
  }
}

TEST(SkullModel, AalRegionsPosteriorInferiorCerebellumOfPlausibleVolume) {
  const auto& m = *built().scene_model;
  const auto& lm = m.meshes[static_cast<std::size_t>(m.find_mesh("brain"))];
  ASSERT_EQ(lm.tissues.size(), 3u);
  EXPECT_EQ(lm.tissues[1].name, "cerebellum");
  EXPECT_TRUE(lm.tissues[1].own_material);
  EXPECT_FALSE(lm.tissues[1].material_source.empty());
  ASSERT_EQ(lm.materials.tet_material.size(), lm.mesh.num_tets());
  for (int l : lm.mesh.tet_labels()) ASSERT_TRUE(l >= 1 && l <= 3) << l;
  const auto& st = built().result.regions;
  const Vec3 cerebrum = st.centroid_world_mm[model::kCerebrum];
  const Vec3 cerebellum = st.centroid_world_mm[model::kCerebellum];
  EXPECT_LT(cerebellum.y(), cerebrum.y() - 20.0);  // posterior (MNI y)
  EXPECT_LT(cerebellum.z(), cerebrum.z() - 20.0);  // inferior (MNI z)
  // Adult cerebellum ~120-160 ml, about 10-12 % of the brain; Colin27 in MNI space is enlarged
  // (this mask is ~1.7 l, AAL's cerebellum labels alone are 195 ml), so judge the fraction and
  // a range scaled with it.
  const double total = st.volume_ml[1] + st.volume_ml[2] + st.volume_ml[3];
  const double fraction = st.volume_ml[model::kCerebellum] / total;
  std::cout << "cerebellum " << st.volume_ml[model::kCerebellum] << " ml of " << total << " ml ("
            << 100 * fraction << " %)\n";
  EXPECT_GT(fraction, 0.08);
  EXPECT_LT(fraction, 0.15);
  EXPECT_GT(st.volume_ml[model::kCerebellum], 120.0);
  EXPECT_LT(st.volume_ml[model::kCerebellum], 230.0);

  // The build's report counts the skull it wrote, and the files it wrote are the build-time
  // model's that the tests above check (the scene and its meshes, byte for byte: the mesher is
  // seeded), so those tests judge what build_model makes now. Here, not in a test of
  // its own: each test runs in its own process, and this one builds the model anyway.
  const auto& s = built().scene_model->rigid.at(0);
  EXPECT_EQ(built().result.skull.triangles,
            neurosim::mesh::check_closed(s.vertices_m, s.triangles).triangles);
  const auto tested = neurosim::testing::brain7_scene("brain_skull").parent_path();
  for (const char* file : {"brain_skull.scene", "brain_skull/brain.mesh", "brain_skull/skull.mesh",
                           "brain_skull/artery.mesh"}) {
    const std::string here = neurosim::testing::slurp(built().dir / file);
    EXPECT_FALSE(here.empty()) << file;
    EXPECT_TRUE(here == neurosim::testing::slurp(tested / file))
        << file << " differs from the build-time model's " << tested / file;
  }
}

TEST(SkullModel, DistanceTransformMatchesBruteForce) {
  const std::array<int, 3> d{9, 7, 6};
  const std::array<double, 3> h{1.0, 1.5, 0.5};
  std::mt19937 rng(3);
  std::vector<unsigned char> mask(9 * 7 * 6, 0);
  for (auto& v : mask) v = (rng() % 17 == 0) ? 1 : 0;
  mask[20] = 1;
  const auto dist = model::distance_from_mask_mm(mask.data(), d, h);
  for (int i = 0; i < 9 * 7 * 6; ++i) {
    double best = std::numeric_limits<double>::infinity();
    for (int j = 0; j < 9 * 7 * 6; ++j) {
      if (!mask[j]) continue;
      const double dx = (i % 9 - j % 9) * h[0], dy = ((i / 9) % 7 - (j / 9) % 7) * h[1],
                   dz = (i / 63 - j / 63) * h[2];
      best = std::min(best, std::sqrt(dx * dx + dy * dy + dz * dz));
    }
    ASSERT_NEAR(dist[i], best, 1e-5) << "voxel " << i;
  }
}

}  // namespace
