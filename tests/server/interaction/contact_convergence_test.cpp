// Mesh convergence of the contact force (contact_step.cpp): the same press (the 2 mm tip, 1, 2
// and 3 mm deep, at one point of a block's top face) on meshes whose cells under the tip are 4,
// 2, 1 and 0.5 mm (a graded grid over the same domain): the force converges as the cells shrink.
// The brain meshes of 7 / 5 / 4 / 3 mm cells are measured by bench/contact_convergence_bench.
#include "server/interaction/simulation.hpp"

#include "graded_block_fixtures.hpp"
#include "server/mesh/io.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

namespace neurosim::interaction {
namespace {

struct Press {
  const char* element{"linear-tet"};
  double poisson{0.45};
  double youngs_pa{3000.0};
  double tip_radius_m{0.002};
  double shaft_radius_m{0.0015};
  double fine_half_m{0.004};  // half-width and depth of the region of fine cells
  double growth{1.5};
  double half_m{0.024};  // block [-half, half]^2 x [-half, 0]
};

scene::Model block_scene(const Press& p, const mesh::TetMesh& block) {
  const auto dir = neurosim::testing::temp_dir("contact_convergence");
  const auto file = dir / "block.mesh";
  mesh::write_medit(file.string(), mesh::to_mesh_data(block), 1.0);
  std::ostringstream s;
  s.precision(17);
  s << "name: \"convergence\"\n"
    << "meshes { id: \"block\" file: \"" << file.string() << "\"\n"
    << "  material { name: \"block\" youngs_modulus_pa: " << p.youngs_pa
    << " poisson_ratio: " << p.poisson << " element: \"" << p.element << "\" }\n"
    << "  fixed { half_space { point_m { z: " << -p.half_m + 1e-9 << " } normal { z: 1 } } }\n"
    << "  priority: 0 }\n"
    << "tools { id: \"probe\" tip_radius_m: " << p.tip_radius_m
    << " shaft_radius_m: " << p.shaft_radius_m << " shaft_length_m: 0.05 max_speed_m_per_s: 2 }\n"
    << "effects { tier: LINEAR coupling: false tool_contact: true deformation_output: true }\n";
  const std::string source = (dir / "convergence.scene").string();
  scene::Model model = scene::compile(scene::parse_scene(s.str(), source), source);
  std::filesystem::remove_all(dir);
  return model;
}

// The press: the 2 mm tip (1.5 mm shaft) along -z at a point of the top face, 1, 2 and 3 mm past
// it, on meshes of 4, 2, 1 and 0.5 mm cells under the tip (fine out to 4 mm from the axis and
// 4 mm deep, graded by 1.5 beyond, the same 48 x 48 x 24 mm block), the brain's E = 3 kPa on
// linear tetrahedra at nu = 0.45 (an element that converges from above; smoothed-tet, the
// bundled brain's, does not settle on these meshes at 2 mm: bench/RESULTS.md). The point
// (8/3, 4/3) mm is the centroid of a top triangle of the 4 mm mesh, 1.89 mm from its nearest
// vertex: the tip 1 mm deep cuts the rest surface in a circle of 1.73 mm, so no node lies under
// it and node rows gave 0 N there (asserted below). Measured (mN, 4 / 2 / 1 / 0.5 mm):
//   1 mm: 51.7 / 19.9 / 14.2 / 13.8   differences 31.8, 5.7, 0.41 (order 2.5, 3.8)
//   2 mm: 102.9 / 39.9 / 39.6 / 39.1  differences 63.0, 0.33, 0.46 (settled to 1.2 %)
//   3 mm: 150.8 / 60.5 / 59.3 / 58.8  differences 90.2, 1.2, 0.57 (order 6.2, 1.1)
// From 4 to 2 mm the force halves with the cells (F ~ h: the contact radius, 1.3-2 mm, is under
// one cell, the press is a point load on one triangle, as a node row's on one node); below, the
// patch spans 1-4 cells and the force settles. Asserted: a force on every mesh at every depth,
// growing with depth, and each successive difference smaller than the one before it or under
// 2 % of the finest force (the level at which the row set changes between meshes). Not run
// here (60025 vertices, 100 s): at 0.25 mm the force is 15.15 / 37.73 / 56.65 mN, the 1 mm
// force rises again by 9.7 % (2 and 3 mm fall by 3.5 %): settled to about 10 %, not converged
// monotonically (bench/RESULTS.md, "the press on a graded block"). 1 mm is R / 2, where the
// rim rows of a flat press turn from the sphere's radial normal to the half-space depth along
// the mean normal (RESULTS: "Why the settled force is twice Sneddon's"); with the radial normal
// there the 1 mm forces are 51.71 / 16.88 / 9.86 / 7.58 mN and this test still holds.
TEST(interaction_contact_convergence, SamePressOnEverFinerCellsConverges) {
  const std::vector<double> cells_m{0.004, 0.002, 0.001, 0.0005};
  const std::vector<double> depths_m{0.001, 0.002, 0.003};
  const Press p;
  const Vec3 at(0.008 / 3.0, 0.004 / 3.0, 0.0);
  std::vector<std::vector<double>> force_n(cells_m.size());
  for (std::size_t ci = 0; ci < cells_m.size(); ++ci) {
    const double h = cells_m[ci];
    const auto xs = testing::graded_axis_to(h, p.fine_half_m, p.growth, p.half_m, true);
    const auto zs = testing::graded_axis_to(h, p.fine_half_m, p.growth, p.half_m, false);
    const mesh::TetMesh block = testing::graded_block(xs, zs);
    if (ci == 0) {
      // No surface node within the tip's section of the rest surface at 1 mm: node rows, which
      // exist only where a node's normal line meets the tip, gave no force here.
      const double d = depths_m[0], section = std::sqrt(2.0 * p.tip_radius_m * d - d * d);
      for (int v : block.surface_vertices()) {
        const Vec3 x = block.vertices()[v];
        if (std::abs(x.z()) < 1e-12) {
          EXPECT_GT((x - at).norm(), section) << "vertex " << v;
        }
      }
    }
    SimulationOptions o;
    o.max_contact_nodes_per_tool = 1200;  // the whole patch of the finest mesh
    o.lcp_max_iterations = 4000;
    auto sim = Simulation::build(block_scene(p, block), o);
    std::printf("cells %.1f mm (%zu vertices):", h * 1e3, block.num_vertices());
    for (double d : depths_m) {
      ToolPose pose;
      pose.tip_m = at + Vec3(0.0, 0.0, p.tip_radius_m - d);
      pose.axis = Vec3::UnitZ();
      std::vector<ToolContact> c;
      StepStats st;
      sim->step({pose}, c, st);
      ASSERT_TRUE(st.converged) << "cells " << h << " depth " << d;
      force_n[ci].push_back(c.at(0).force_n.z());
      std::printf("  %.0f mm %.3f mN (%d rows)", d * 1e3, 1e3 * force_n[ci].back(),
                  st.contact_rows);
      EXPECT_GT(force_n[ci].back(), 0.0) << "cells " << h << " depth " << d;
      if (force_n[ci].size() > 1) {
        EXPECT_GT(force_n[ci].back(), force_n[ci][force_n[ci].size() - 2])
            << "cells " << h << " depth " << d;
      }
    }
    std::printf("\n");
  }
  for (std::size_t di = 0; di < depths_m.size(); ++di) {
    const double finest = force_n.back()[di];
    std::printf("%.0f mm: differences", depths_m[di] * 1e3);
    for (std::size_t ci = 0; ci + 1 < cells_m.size(); ++ci) {
      const double diff = force_n[ci][di] - force_n[ci + 1][di];
      std::printf(" %.3f mN", 1e3 * diff);
      if (ci == 0) continue;
      const double before = force_n[ci - 1][di] - force_n[ci][di];
      std::printf(" (order %.2f)", std::log2(std::abs(before / diff)));
      EXPECT_TRUE(std::abs(diff) < std::abs(before) || std::abs(diff) < 0.02 * finest)
          << "depth " << depths_m[di] << ": difference " << diff << " N after " << before
          << " N (cells " << cells_m[ci] << " to " << cells_m[ci + 1] << " m)";
    }
    std::printf("\n");
  }
}

}  // namespace
}  // namespace neurosim::interaction
