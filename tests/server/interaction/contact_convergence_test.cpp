// Mesh convergence of the contact force (contact_step.cpp): the same press (the 2 mm tip, 1, 2
// and 3 mm deep, at one point of a block's top face) on meshes whose cells under the tip are 4,
// 2, 1 and 0.5 mm (a graded grid over the same domain): the force converges as the cells shrink
// (the rows on the touched triangle in ever smaller steps; with the contact options toward
// Sneddon's answer, the coarse cells already near it).
// The brain meshes of 7 / 5 / 4 / 3 mm cells are measured by bench/contact_convergence_bench
// (at 24 fixed points, and on brains split 1 -> 8 with the surface fixed: with the default rows no
// positive order at cells of 3.5 mm and more, the steps grow; bench/RESULTS.md, "The press at 24
// points"; nor on sub-models of the 7 mm brain split to 0.44 mm, "The press below 3.5 mm cells"),
// not here: no measured order to bound a brain's convergence by.
// Also the tilted probe whose shaft carries force, with and without the shaft's near field.
#include "server/interaction/simulation.hpp"

#include "bench/sub_model.hpp"
#include "bench/tet_split.hpp"
#include "graded_block_fixtures.hpp"
#include "server/mesh/io.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
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
// it and node rows gave 0 N there (asserted below). Measured with the rows on the touched
// triangle (mN, 4 / 2 / 1 / 0.5 mm; 2026-11-28):
//   1 mm: 50.75 / 17.34 / 8.65 / 7.20    differences 33.4, 8.7, 1.45 (order 1.9, 2.6)
//   2 mm: 101.49 / 34.68 / 23.05 / 21.05 differences 66.8, 11.6, 2.0 (order 2.5, 2.5)
//   3 mm: 152.24 / 52.90 / 40.89 / 36.68 differences 99.3, 12.0, 4.2 (order 3.1, 1.5)
// (an earlier row search gave 51.7 / 19.9 / 14.2 / 13.8, 102.9 / 39.9 / 39.6 / 39.1, 150.8 /
// 60.5 / 59.3 / 58.8; the notes below on 0.25 mm cells are of that one, not measured since.)
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
constexpr double kCells[] = {0.004, 0.002, 0.001, 0.0005};  // under the tip, unit m
constexpr double kDepths[] = {0.001, 0.002, 0.003};           // unit m

// The press on the four graded blocks with `o` (the rows' options): force_n[cells][depth], N.
std::vector<std::vector<double>> press_on_graded_blocks(SimulationOptions o) {
  const Press p;
  const Vec3 at(0.008 / 3.0, 0.004 / 3.0, 0.0);
  std::vector<std::vector<double>> force_n;
  for (double h : kCells) {
    const auto xs = testing::graded_axis_to(h, p.fine_half_m, p.growth, p.half_m, true);
    const auto zs = testing::graded_axis_to(h, p.fine_half_m, p.growth, p.half_m, false);
    const mesh::TetMesh block = testing::graded_block(xs, zs);
    if (h == kCells[0]) {
      // No surface node within the tip's section of the rest surface at 1 mm: node rows, which
      // exist only where a node's normal line meets the tip, gave no force here.
      const double d = kDepths[0], section = std::sqrt(2.0 * p.tip_radius_m * d - d * d);
      for (int v : block.surface_vertices()) {
        const Vec3 x = block.vertices()[v];
        if (std::abs(x.z()) < 1e-12) {
          EXPECT_GT((x - at).norm(), section) << "vertex " << v;
        }
      }
    }
    o.max_contact_nodes_per_tool = 1200;  // the whole patch of the finest mesh
    o.lcp_max_iterations = 4000;
    auto sim = Simulation::build(block_scene(p, block), o);
    std::printf("cells %.1f mm (%zu vertices):", h * 1e3, block.num_vertices());
    force_n.emplace_back();
    for (double d : kDepths) {
      ToolPose pose;
      pose.tip_m = at + Vec3(0.0, 0.0, p.tip_radius_m - d);
      pose.axis = Vec3::UnitZ();
      std::vector<ToolContact> c;
      StepStats st;
      sim->step({pose}, c, st);
      EXPECT_TRUE(st.converged) << "cells " << h << " depth " << d;
      force_n.back().push_back(c.at(0).force_n.z());
      std::printf("  %.0f mm %.3f mN (%d rows)", d * 1e3, 1e3 * force_n.back().back(),
                  st.contact_rows);
      EXPECT_GT(force_n.back().back(), 0.0) << "cells " << h << " depth " << d;
      if (force_n.back().size() > 1) {
        EXPECT_GT(force_n.back().back(), force_n.back()[force_n.back().size() - 2])
            << "cells " << h << " depth " << d;
      }
    }
    std::printf("\n");
  }
  return force_n;
}

// Sneddon's rigid sphere on an elastic half-space (radius R, depth d): the contact radius a from
// d = (a / 2) ln((R + a) / (R - a)), then F = (E* / 2) ((a^2 + R^2) ln((R + a) / (R - a)) - 2 a R).
double sneddon_n(const Press& p, double depth_m) {
  const double r = p.tip_radius_m;
  auto depth_of = [&](double a) { return 0.5 * a * std::log((r + a) / (r - a)); };
  double lo = 0.0, hi = r * (1.0 - 1e-12);
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    (depth_of(mid) < depth_m ? lo : hi) = mid;
  }
  const double a = 0.5 * (lo + hi);
  const double e_star = p.youngs_pa / (1.0 - p.poisson * p.poisson);
  return 0.5 * e_star * ((a * a + r * r) * std::log((r + a) / (r - a)) - 2.0 * a * r);
}

// The rows on the touched triangle (the contact options off, SimulationOptions::contact_spread,
// contact_smooth_normals, contact_near_field): the force converges from above as the cells
// shrink, each successive difference smaller than the one before it.
TEST(interaction_contact_convergence, SamePressOnEverFinerCellsConverges) {
  SimulationOptions o;
  o.contact_spread = 0.0;
  o.contact_smooth_normals = false;
  o.contact_near_field = false;
  const auto force_n = press_on_graded_blocks(o);
  const std::size_t nc = std::size(kCells);
  for (std::size_t di = 0; di < std::size(kDepths); ++di) {
    const double finest = force_n.back()[di];
    std::printf("%.0f mm: differences", kDepths[di] * 1e3);
    for (std::size_t ci = 0; ci + 1 < nc; ++ci) {
      const double diff = force_n[ci][di] - force_n[ci + 1][di];
      std::printf(" %.3f mN", 1e3 * diff);
      if (ci == 0) continue;
      const double before = force_n[ci - 1][di] - force_n[ci][di];
      std::printf(" (order %.2f)", std::log2(std::abs(before / diff)));
      EXPECT_TRUE(std::abs(diff) < std::abs(before) || std::abs(diff) < 0.02 * finest)
          << "depth " << kDepths[di] << ": difference " << diff << " N after " << before
          << " N (cells " << kCells[ci] << " to " << kCells[ci + 1] << " m)";
    }
    std::printf("\n");
  }
}

// With the contact options (spread 1, smooth normals, the near field: the rows for a tip whose
// patch is smaller than the cells) the coarse cells are already near the continuum's answer,
// so the force does not fall in ever smaller steps: measured (mN, 4 / 2 / 1 / 0.5 mm cells;
// Sneddon 6.74 / 18.05 / 31.36; 2026-11-29, the tip's node rows along the sphere's normal where
// the point leaves it, contact_step.cpp merge_features)
//   1 mm: 8.29 / 8.83 / 8.52 / 7.24   2 mm: 24.89 / 24.83 / 20.61 / 18.09
//   3 mm: 47.63 / 43.83 / 33.91 / 29.47
// (with the tip's spread floor, contact_step.cpp tip_spread_floor_m, 2026-11-30: the 2 and 1 mm
// cells 8.19 / 7.66, 23.58 / 21.20, 43.01 / 36.63, the 4 and 0.5 mm cells unchanged: nearer
// Sneddon on the 2 mm cells and at 1 mm deep, farther at 2 and 3 mm deep on the 1 mm cells)
// (with radial rows up to 90 degrees and the mean normal past it: 8.29 / 8.83 / 8.37 / 7.39,
// 24.89 / 24.83 / 21.87 / 21.08, 47.63 / 43.83 / 40.10 / 37.51: the mean normal's rows past
// d = r pushed every node along the surface normal, as if it stuck to the sphere, 17-20 % above
// the frictionless sphere on the finest cells; with the near field's former max(0, 3 / (4 E* a)
// - 0.766 / (E* rho)), the term gone once the patch a passed the spread rho: 8.36 / 10.00 /
// 11.45 / 8.06, 25.5 / 34.1 / 26.8 / 22.2, 50.0 / 64.2 / 46.5 / 38.8: the 1 and 0.5 mm cells
// too stiff, the spread's smear uncorrected; contact_step.cpp near_field_of_tool). Asserted:
// the finest cells are the closest to Sneddon's (exact for the frictionless sphere at any depth
// of the linear theory), within 25 %, and at most half as far from it as the coarsest; the force
// above Sneddon's where the centre is in front of the rest surface (d < r: linear tetrahedra at
// nu = 0.45 and a finite block are stiffer than the half-space; at d >= r the finest cells
// measured +0.2 % and -6.0 %).
TEST(interaction_contact_convergence, ContactOptionsConvergeTowardSneddon) {
  SimulationOptions o;
  o.contact_spread = 1.0;
  o.contact_smooth_normals = true;
  o.contact_near_field = true;
  const auto force_n = press_on_graded_blocks(o);
  const Press p;
  for (std::size_t di = 0; di < std::size(kDepths); ++di) {
    const double sneddon = sneddon_n(p, kDepths[di]);
    std::printf("%.0f mm: Sneddon %.3f mN, relative error", kDepths[di] * 1e3, 1e3 * sneddon);
    std::vector<double> error;
    for (const auto& row : force_n) {
      error.push_back(row[di] / sneddon - 1.0);
      std::printf(" %.3f", error.back());
      if (kDepths[di] < p.tip_radius_m) {
        EXPECT_GT(error.back(), 0.0) << "depth " << kDepths[di];
      }
    }
    std::printf("\n");
    for (std::size_t ci = 0; ci + 1 < error.size(); ++ci)
      EXPECT_LT(std::abs(error.back()), std::abs(error[ci]))
          << "depth " << kDepths[di] << " cells " << kCells[ci];
    EXPECT_LT(std::abs(error.back()), 0.25) << "depth " << kDepths[di];
    EXPECT_LT(std::abs(error.back()), 0.5 * std::abs(error.front())) << "depth " << kDepths[di];
  }
}

// The shaft's near field (SimulationOptions::contact_shaft_near_field, contact_step.cpp
// near_field_of_shaft) under refinement: the probe tilted 10 degrees off the top face, the tip
// centre d below it at (-3, 4/3) mm, so that the 1.5 mm shaft leaving the tip stays in the
// tissue for 3-6 mm beyond it (the fine region), on the 4 / 2 / 1 / 0.5 mm blocks; the default
// rows with and without the shaft's term. On the 0.5 mm cells there is no spread (its fade,
// edge < r_s / 2) and so no near field: both are the rows' own answer, the reference (the rows
// on fine cells follow CalculiX's contact: contact_reference_test). Measured |F| (mN, 4 / 2 /
// 1 / 0.5 mm cells; 2026-11-29, the tip's node rows along the sphere's normal where the point
// leaves it, contact_step.cpp merge_features):
//   without, 1.5 mm: 29.78 / 16.43 / 15.25 / 13.36   2 mm: 59.93 / 32.01 / 26.11 / 22.62
//   with,    1.5 mm: 16.61 / 16.43 / 15.24 / 13.36   2 mm: 28.72 / 27.80 / 25.49 / 22.62
// (radial rows up to 90 degrees and the mean normal past it: 16.93 / 14.60 / 12.16 and 28.29 /
// 24.96 in place of the changed numbers), so the 4 mm cells went from 2.23-2.65x the finest to
// 1.24-1.27x (the tip's
// own press on these blocks: 1.12x at 1 mm). Asserted: the term never stiffens (with <=
// without), the finest is the same both ways, and with it every mesh lies within 1.45x of the
// finest.
TEST(interaction_contact_convergence, ShaftNearFieldUnderRefinement) {
  const Press p;
  const double tilt = 10.0 * M_PI / 180.0;
  const Vec3 axis(std::cos(tilt), 0.0, std::sin(tilt));
  const Vec3 at(-0.003, 0.004 / 3.0, 0.0);
  constexpr double kShaftDepths[] = {0.0015, 0.002};
  // force[on][cells][depth]: |F|, N
  std::vector<std::vector<double>> force[2];
  for (double h : kCells) {
    const auto xs = testing::graded_axis_to(h, p.fine_half_m, p.growth, p.half_m, true);
    const auto zs = testing::graded_axis_to(h, p.fine_half_m, p.growth, p.half_m, false);
    const mesh::TetMesh block = testing::graded_block(xs, zs);
    const scene::Model model = block_scene(p, block);
    for (int on = 0; on < 2; ++on) {
      SimulationOptions o;
      o.contact_shaft_near_field = on == 1;
      o.max_contact_nodes_per_tool = 1200;
      o.lcp_max_iterations = 4000;
      auto sim = Simulation::build(model, o);
      force[on].emplace_back();
      std::printf("cells %.1f mm, shaft near field %d:", h * 1e3, on);
      for (double d : kShaftDepths) {
        ToolPose pose;
        pose.tip_m = at + Vec3(0.0, 0.0, p.tip_radius_m - d);
        pose.axis = axis;
        std::vector<ToolContact> c;
        StepStats st;
        sim->step({pose}, c, st);
        EXPECT_TRUE(st.converged) << "cells " << h << " depth " << d;
        force[on].back().push_back(c.at(0).force_n.norm());
        std::printf("  %.1f mm %.3f mN (%.3f, %.3f; %d rows)", d * 1e3,
                    1e3 * force[on].back().back(), 1e3 * c[0].force_n.x(), 1e3 * c[0].force_n.z(),
                    st.contact_rows);
      }
      std::printf("\n");
    }
  }
  const std::size_t finest = std::size(kCells) - 1;
  for (std::size_t ci = 0; ci < std::size(kCells); ++ci)
    for (std::size_t di = 0; di < std::size(kShaftDepths); ++di) {
      EXPECT_LE(force[1][ci][di], force[0][ci][di] * (1.0 + 1e-12))
          << "cells " << kCells[ci] << " depth " << kShaftDepths[di];
      EXPECT_LE(force[1][ci][di], 1.45 * force[1][finest][di])
          << "cells " << kCells[ci] << " depth " << kShaftDepths[di];
      EXPECT_GE(force[1][ci][di], force[1][finest][di])
          << "cells " << kCells[ci] << " depth " << kShaftDepths[di];
      if (ci == finest) {
        EXPECT_NEAR(force[1][ci][di], force[0][ci][di], 1e-9 * force[0][ci][di]);
      }
    }
}

// bench/tet_split.hpp (contact_convergence_bench --split, the refinement of the discretization
// alone): a 1 -> 8 split keeps the volume and the boundary surface exactly (each surface triangle
// becomes four in its own plane: the new surface vertices are the midpoints of the surface
// edges), with eight times the tetrahedra, every one of positive volume.
TEST(interaction_contact_convergence, SplitKeepsTheSurface) {
  const auto xs = testing::graded_axis_to(0.004, 0.004, 1.5, 0.012, true);
  const auto zs = testing::graded_axis_to(0.004, 0.004, 1.5, 0.012, false);
  const mesh::TetMesh block = testing::graded_block(xs, zs);
  const bench::SplitMesh s = bench::split_tets(block);
  auto volume = [](const mesh::TetMesh& m, double& least) {
    double v = 0.0;
    least = 1.0;
    for (const auto& t : m.tets()) {
      const auto& x = m.vertices();
      const double vt = (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]).dot(x[t[3]] - x[t[0]]) / 6.0;
      v += vt;
      least = std::min(least, vt);
    }
    return v;
  };
  auto area = [](const mesh::TetMesh& m) {
    double a = 0.0;
    for (const auto& t : m.surface()) {
      const auto& x = m.vertices();
      a += 0.5 * (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]).norm();
    }
    return a;
  };
  double least_in = 0.0, least_out = 0.0;
  const double v_in = volume(block, least_in), v_out = volume(s.mesh, least_out);
  EXPECT_EQ(s.mesh.num_tets(), 8 * block.num_tets());
  EXPECT_EQ(s.parent_tet.size(), s.mesh.num_tets());
  EXPECT_NEAR(v_out, v_in, 1e-12 * v_in);
  EXPECT_GT(least_out, 0.0);
  EXPECT_EQ(s.mesh.surface().size(), 4 * block.surface().size());
  EXPECT_NEAR(area(s.mesh), area(block), 1e-12 * area(block));
  // Every surface vertex of the split mesh is an old surface vertex or the midpoint of an edge
  // whose ends are both on the old surface, and lies on the old surface (a face of the block).
  std::vector<char> on_surface(block.num_vertices(), 0);
  for (int v : block.surface_vertices()) on_surface[v] = 1;
  const int n = static_cast<int>(block.num_vertices());
  for (int v : s.mesh.surface_vertices()) {
    if (v < n) {
      EXPECT_TRUE(on_surface[v]) << "vertex " << v;
      continue;
    }
    const auto& e = s.edge_ends[v - n];
    EXPECT_TRUE(on_surface[e[0]] && on_surface[e[1]]) << "vertex " << v;
    const Vec3 x = s.mesh.vertices()[v];
    const double to_face = std::min({std::abs(x.x() - xs.front()), std::abs(x.x() - xs.back()),
                                      std::abs(x.y() - xs.front()), std::abs(x.y() - xs.back()),
                                      std::abs(x.z() + zs.back()), std::abs(x.z())});
    EXPECT_LT(to_face, 1e-15) << "vertex " << v;
  }
}


// bench/sub_model.hpp (contact_convergence_bench --region: a press's neighbourhood, then split):
// the cut keeps the tetrahedra with centroid within the radius that are face-connected to the
// one nearest the centre (here all but one, joined by an edge), its surface is the block's own
// faces plus the cut faces, and every node of a cut face is clamped and no other (the block's
// clamped base lies beyond the radius); after a 1 -> 8 split (split_region) the clamp is still
// exactly the cut faces' nodes (tet_split.hpp's split_loaded_mesh, which fixes every midpoint
// between two fixed nodes, clamped more here: the rim on the top face and edges through the
// inside). A region that holds the block's clamped base is refused.
TEST(interaction_contact_convergence, RegionCutClampsExactlyItsCutFaces) {
  const auto xs = testing::graded_axis_to(0.004, 0.004, 1.5, 0.012, true);
  const auto zs = testing::graded_axis_to(0.004, 0.004, 1.5, 0.012, false);
  scene::LoadedMesh m;
  m.mesh = testing::graded_block(xs, zs);
  for (std::size_t v = 0; v < m.mesh.num_vertices(); ++v)
    if (std::abs(m.mesh.vertices()[v].z() + zs.back()) < 1e-15) m.fixed_nodes.push_back(static_cast<int>(v));
  ASSERT_FALSE(m.fixed_nodes.empty());
  const Vec3 centre(0.001, 0.0005, 0.0);
  const double radius = 0.008;
  auto centroid = [](const mesh::TetMesh& mesh, const mesh::Tet& t) {
    const auto& x = mesh.vertices();
    return Vec3(0.25 * (x[t[0]] + x[t[1]] + x[t[2]] + x[t[3]]));
  };
  std::size_t inside = 0;
  double v_inside = 0.0;
  for (std::size_t t = 0; t < m.mesh.num_tets(); ++t)
    if ((centroid(m.mesh, m.mesh.tets()[t]) - centre).norm() <= radius) ++inside, v_inside += m.mesh.tet_volume(static_cast<int>(t));
  const std::size_t tets_before = m.mesh.num_tets();
  std::vector<mesh::Tri> cut_faces = bench::cut_region(m, centre, radius);
  ASSERT_FALSE(cut_faces.empty());
  // The face-connected piece: the ball's tetrahedra but those joined to it by an edge or a vertex.
  EXPECT_LE(m.mesh.num_tets(), inside);
  EXPECT_GE(m.mesh.num_tets() + 2, inside);
  EXPECT_LT(m.mesh.num_tets(), tets_before);
  double v_cut = 0.0;
  for (std::size_t t = 0; t < m.mesh.num_tets(); ++t) {
    EXPECT_LE((centroid(m.mesh, m.mesh.tets()[t]) - centre).norm(), radius);
    v_cut += m.mesh.tet_volume(static_cast<int>(t));
  }
  EXPECT_LE(v_cut, v_inside * (1.0 + 1e-12));
  EXPECT_GT(v_cut, 0.9 * v_inside);
  // A surface triangle lies in one face of the block or is a cut face.
  auto check = [&](const scene::LoadedMesh& mm, const char* what) {
    const auto& x = mm.mesh.vertices();
    auto on_face = [&](const Vec3& p, int axis, double at) { return std::abs(p[axis] - at) < 1e-15; };
    std::vector<char> fixed(x.size(), 0), cut(x.size(), 0);
    for (int v : mm.fixed_nodes) fixed[v] = 1;
    int own = 0, cut_seen = 0;
    for (const auto& t : mm.mesh.surface()) {
      bool block_face = false;
      for (int axis = 0; axis < 3; ++axis)
        for (double at : {axis == 2 ? -zs.back() : xs.front(), axis == 2 ? 0.0 : xs.back()})
          block_face = block_face || (on_face(x[t[0]], axis, at) && on_face(x[t[1]], axis, at) && on_face(x[t[2]], axis, at));
      if (block_face) {
        ++own;
        continue;
      }
      ++cut_seen;
      for (int v : t) {
        cut[v] = 1;
        EXPECT_TRUE(fixed[v]) << what << ": node " << v << " of a cut face is free";
      }
    }
    for (int v : mm.fixed_nodes) EXPECT_TRUE(cut[v]) << what << ": node " << v << " clamped off the cut";
    EXPECT_GT(own, 0) << what;
    EXPECT_GT(cut_seen, 0) << what;
  };
  check(m, "cut");
  const std::size_t cut_tets = m.mesh.num_tets(), cut_faces_before = cut_faces.size();
  bench::split_region(m, cut_faces);
  EXPECT_EQ(cut_faces.size(), 4 * cut_faces_before);
  EXPECT_EQ(m.mesh.num_tets(), 8 * cut_tets);
  check(m, "cut and split");
  bench::split_region(m, cut_faces);
  check(m, "cut and split twice");
  scene::LoadedMesh whole;
  whole.mesh = testing::graded_block(xs, zs);
  whole.fixed_nodes = {0};
  EXPECT_THROW(bench::cut_region(whole, whole.mesh.vertices()[0], radius), std::invalid_argument);
  // keep_pinned: the mesh's clamped node inside the region stays fixed, through the splits.
  const Vec3 pinned_x = whole.mesh.vertices()[0];
  std::vector<mesh::Tri> whole_cut = bench::cut_region(whole, pinned_x, radius, true);
  auto pinned_fixed = [&]() {
    for (int v : whole.fixed_nodes)
      if ((whole.mesh.vertices()[static_cast<std::size_t>(v)] - pinned_x).norm() < 1e-15) return true;
    return false;
  };
  EXPECT_TRUE(pinned_fixed());
  bench::split_region(whole, whole_cut);
  EXPECT_TRUE(pinned_fixed());
}

}  // namespace
}  // namespace neurosim::interaction
