// The contact step (contact_step.cpp) against outside references: a rigid sphere pressed into an
// elastic block meshed finely under it (a structured grid graded away from the contact, Kuhn
// tetrahedra), LINEAR tier, against Hertz's force-depth law
//   F = 4/3 E / (1 - nu^2) sqrt(R) d^(3/2)   (contact radius a = sqrt(R d)),
// at depths whose contact radius spans at least five elements.
#include "server/interaction/simulation.hpp"

#include "server/mesh/io.hpp"
#include "server/mesh/tet_mesh.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

namespace neurosim::interaction {
namespace {

// Node coordinates of one axis, symmetric about 0: cells of `fine_m` out to `fine_half_m`, then
// each cell `growth` times the last until `half_m` is passed (the last node at the total).
std::vector<double> graded_axis(double fine_m, double fine_half_m, double growth, double half_m,
                                bool symmetric) {
  std::vector<double> side{0.0};
  double h = fine_m;
  while (side.back() < fine_half_m - 1e-12) side.push_back(side.back() + fine_m);
  while (side.back() < half_m - 1e-12) {
    h *= growth;
    side.push_back(side.back() + h);
  }
  std::vector<double> out;
  if (symmetric)
    for (std::size_t k = side.size() - 1; k > 0; --k) out.push_back(-side[k]);
  out.insert(out.end(), side.begin(), side.end());
  return out;
}

// Block [-X, X]^2 x [-Z, 0] (top face z = 0), graded grid, six Kuhn tetrahedra per cell.
mesh::TetMesh graded_block(const std::vector<double>& xs, const std::vector<double>& zs) {
  const int n = static_cast<int>(xs.size()), nz = static_cast<int>(zs.size());
  auto node = [&](int i, int j, int k) { return i + n * (j + n * k); };
  std::vector<mesh::Vec3> x;
  x.reserve(static_cast<std::size_t>(n) * n * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) x.emplace_back(xs[i], xs[j], -zs[nz - 1 - k]);
  static constexpr int kPerm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2},
                                      {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  std::vector<mesh::Tet> tets;
  for (int k = 0; k + 1 < nz; ++k)
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i)
        for (const auto& p : kPerm) {
          std::array<int, 3> c{i, j, k};
          mesh::Tet t;
          t[0] = node(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            t[s + 1] = node(c[0], c[1], c[2]);
          }
          if (mesh::signed_volume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]) < 0.0) std::swap(t[2], t[3]);
          tets.push_back(t);
        }
  mesh::BuildOptions opt;
  opt.source = "graded block";
  return mesh::TetMesh::build(std::move(x), std::move(tets), opt);
}

struct HertzCase {
  double youngs_pa{3000.0};
  double poisson{0.3};  // linear tetrahedra: no volumetric locking at 0.3
  double tip_radius_m{0.010};
  double fine_m{0.00044};       // element size under the contact
  double fine_half_m{0.0036};   // half-width (and depth) of the fine region
  double growth{1.5};           // size ratio of neighbouring cells outside it
  double half_m{0.15};          // block half-width and depth
};

scene::Model hertz_scene(const HertzCase& h, int& vertices) {
  const auto dir = neurosim::testing::temp_dir("contact_reference");
  const auto xs = graded_axis(h.fine_m, h.fine_half_m, h.growth, h.half_m, true);
  const auto zs = graded_axis(h.fine_m, h.fine_half_m, h.growth, h.half_m, false);
  const mesh::TetMesh block = graded_block(xs, zs);
  vertices = static_cast<int>(block.num_vertices());
  const auto file = dir / "block.mesh";
  mesh::write_medit(file.string(), mesh::to_mesh_data(block), 1.0);
  std::ostringstream s;
  s.precision(17);
  s << "name: \"hertz\"\n"
    << "meshes { id: \"block\" file: \"" << file.string() << "\"\n"
    << "  material { name: \"block\" youngs_modulus_pa: " << h.youngs_pa
    << " poisson_ratio: " << h.poisson << " }\n"
    << "  fixed { half_space { point_m { z: " << -zs.back() + 1e-9
    << " } normal { z: 1 } } }\n"
    << "  priority: 0 }\n"
    << "tools { id: \"sphere\" tip_radius_m: " << h.tip_radius_m
    << " shaft_radius_m: 0.001 shaft_length_m: 0.05 max_speed_m_per_s: 2 }\n"
    << "effects { tier: LINEAR coupling: false tool_contact: true deformation_output: true }\n";
  const std::string source = (dir / "hertz.scene").string();
  scene::Model model = scene::compile(scene::parse_scene(s.str(), source), source);
  std::filesystem::remove_all(dir);
  return model;
}

// Hertz: F = 4/3 E* sqrt(R) d^(3/2). The 10 mm sphere pressed along -z at the block's centre
// (a node); three depths with a = sqrt(R d) from 5 to 7 elements (0.5, 0.75, 1 mm; d / R <= 0.1).
// Measured F / Hertz 1.080, 1.081, 1.085 (40.7k vertices). What is left: the block is a layer of
// finite depth on a fixed base (150 mm, a / depth <= 0.021: about +2 % for a bonded layer), and
// the graded far field is stiffer than the continuum (cell growth 1.4 / 1.5 / 1.6 / 2.0 gave 1.079
// / 1.085 / 1.095 / 1.126 at 1 mm); refining under the contact (0.45 to 0.30 mm) changed < 0.3 %.
TEST(interaction_contact_reference, SpherePressedIntoAGradedBlockFollowsHertz) {
  const HertzCase h;
  int vertices = 0;
  const scene::Model model = hertz_scene(h, vertices);
  SimulationOptions o;
  o.max_contact_nodes_per_tool = 1200;  // the whole patch (nodes, edges and faces under the tip)
  o.lcp_max_iterations = 4000;          // an active-set pivot per row at least
  auto sim = Simulation::build(model, o);
  const double e_star = h.youngs_pa / (1.0 - h.poisson * h.poisson);
  std::vector<ToolContact> c;
  StepStats st;
  std::printf("graded block: %d vertices, %.2f mm under the contact\n", vertices, h.fine_m * 1e3);
  for (double d : {0.0005, 0.00075, 0.001}) {
    ToolPose pose;
    pose.tip_m = Vec3(0.0, 0.0, h.tip_radius_m - d);
    pose.axis = Vec3::UnitZ();
    sim->step({pose}, c, st);
    ASSERT_TRUE(st.converged) << "depth " << d << ", rows " << st.contact_rows;
    const double hertz = 4.0 / 3.0 * e_star * std::sqrt(h.tip_radius_m) * std::pow(d, 1.5);
    const double a = std::sqrt(h.tip_radius_m * d);
    std::printf("d %.2f mm: a %.2f mm (%.1f elements), rows %d, F %.4f N, Hertz %.4f N, ratio %.4f\n",
                d * 1e3, a * 1e3, a / h.fine_m, st.contact_rows, c[0].force_n.z(), hertz,
                c[0].force_n.z() / hertz);
    EXPECT_GE(a / h.fine_m, 5.0);
    EXPECT_NEAR(c[0].force_n.z() / hertz, 1.0, 0.10) << "depth " << d;
    EXPECT_LT(std::abs(c[0].force_n.x()) + std::abs(c[0].force_n.y()), 1e-3 * c[0].force_n.z());
  }
}

}  // namespace
}  // namespace neurosim::interaction
