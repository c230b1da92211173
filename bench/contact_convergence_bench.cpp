// contact_convergence_bench: mesh convergence of the contact force. The brain/artery scene at
// several brain cell sizes (the scene built by `neurosim-model --cell-size C --out-dir DIR/cC`
// when DIR/cC/brain_artery.scene is missing), the same press on each: the 2 mm probe (the
// scene's tool), axis vertical, its centre on the vertical line through (x, y) (default 45 / 100 mm
// in image coordinates: the top of the left hemisphere, where the 5, 4 and 3 mm surfaces are the
// same plane, so only the mesh under it changes; at 60 / 100 mm it tilts from 21 to 36 degrees
// as the cells shrink, and the geometry's change hides the discretization's) at a
// depth d below that mesh's own rest surface on the line (d = 0.5, 1, 1.5, 2, 2.5, 3 mm), LINEAR
// tier (the scene's element, or --element for every mesh), each depth stepped straight from rest (the LINEAR answer is the pose's alone).
// Per cell size and depth: |F| (mN) and the contact rows. Then, per depth, the differences of
// successive sizes and the order p of F(h) = F* + C h^p that two successive differences imply
// ((F(h1) - F(h2)) / (F(h2) - F(h3)) = (h1^p - h2^p) / (h2^p - h3^p), solved for p).
// Prints a table (--csv: one line per mesh and depth, then the same differences and orders as
// CSV). --geometry-iterations sets SimulationOptions::contact_geometry_iterations (1: the rows of
// the rest surface only), to tell the contact geometry's share from the element's.
// With --slide, per cell size also a slide: the probe slid 40 mm (y 80 to
// 120 mm at x 60 mm, 0.1 mm steps) 1 mm and 2 mm below the rest surface (the highest surface point
// under the tip, along its triangle's normal), |F| / depth with the depth measured to the closest
// point of the surface triangles: its range and spread (max / min) along the path, and its
// jumps (the largest relative change of |F| between two steps whose tip moved < 0.25 mm, and
// how many exceed 10 %); with --cube also the cube's slide (40 mm along x across its top face).
// That is the default path, --slide-path normal (the former path of ctest
// interaction_contact_step.SlideOverTheSurfaceNeverLosesTheTissue, kept for comparisons).
// --contact-spread, --smooth-normals 0|1 and --near-field 0|1 set the SimulationOptions
// of the same names (the three options: --contact-spread 1 --smooth-normals 1 --near-field 1);
// --shaft-near-field 0|1 SimulationOptions::contact_shaft_near_field (0: the shaft's rows with
// the mesh's compliance alone, as before it).
// --no-shaft: the probe without its shaft (shaft length 0), the tip's own contact: the slide's
// axis is the touched triangle's normal, and where that turns far from the surface around it (a
// valley or a steep facet of a finer brain) the shaft leans into the tissue and carries part of
// |F| (bench/RESULTS.md, "The 4 mm brain's slide: the shaft, the depth and a steep facet").
// The trace (--slide-trace) also gives gap_depth_mm, r less the distance to the closest point
// (depth_mm is r less the height along that triangle's normal, which is larger where the closest
// point is an edge or a vertex).
// --slide-path closest: the contact issue's slide instead (the ctest's slide now, with the start
// normal's axis): the same 40 mm line, the tool axis fixed for the whole slide
// (--slide-axis start-normal, the default: the outward normal of the highest triangle at the
// slide's start; --slide-axis vertical: +z), and at each sample the tip centre on the line through
// the sample's highest surface point along that axis, where its distance to the closest point of
// the rest surface triangles is exactly r - d (surface_probe's at_distance_along: the first
// crossing, scanned outward from r - d in 0.1 mm steps, then false position (Illinois) to 1e-10 m,
// checked to 1e-9 m; at d = r the sample's surface point itself; an error if the line has no
// such point within 30 mm), so the gap depth is d at every sample; |F| / depth then uses that
// depth.
#include "patient_models.hpp"
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "server/fem/element.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/surface_probe.hpp"
#include "server/scene/compile.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

namespace fs = std::filesystem;
namespace ni = neurosim::interaction;
using Vec3 = Eigen::Vector3d;

namespace {

// Order p with (h1^p - h2^p) / (h2^p - h3^p) = ratio (bisection on p in (0.05, 6)); nan if the
// differences change sign (no monotone convergence) or the ratio is out of reach.
double observed_order(double h1, double h2, double h3, double d12, double d23) {
  if (!(d12 * d23 > 0.0)) return std::nan("");
  const double ratio = d12 / d23;
  auto g = [&](double p) {
    return (std::pow(h1, p) - std::pow(h2, p)) / (std::pow(h2, p) - std::pow(h3, p)) - ratio;
  };
  double lo = 0.05, hi = 6.0;
  if (g(lo) * g(hi) > 0.0) return std::nan("");
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (g(lo) * g(mid) <= 0.0 ? hi : lo) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> cells;
  std::string dir = "/tmp/neurosim_scale_bench";
  double x_mm = 45.0, y_mm = 100.0;
  bool slide = false, csv = false;
  int geometry_iterations = 0;
  double contact_spread = -1.0;
  int smooth_normals = -1, near_field = -1, shaft_near_field = -1;  // -1: the library's default
  bool cube = false;
  bool no_shaft = false;
  std::string trace_path;
  std::string element;
  std::string slide_path_kind = "normal", slide_axis_kind = "start-normal";
  neurosim::cli::Parser p("contact_convergence_bench",
                          "The same press on the brain at several cell sizes: force convergence.");
  p->add_option("--cell-size", cells, "brain cell size, unit mm (repeat; coarse to fine)");
  p->add_option("--models", dir, "folder of the built scenes (as scale_bench)")->capture_default_str();
  p->add_option("--x", x_mm, "press line x, unit mm")->capture_default_str();
  p->add_option("--y", y_mm, "press line y, unit mm")->capture_default_str();
  p->add_option("--element", element, "every mesh's element (default: the scene's)");
  p->add_flag("--slide", slide, "also the 40 mm slide at 1 and 2 mm (|F| / depth spread)");
  p->add_flag("--csv", csv, "CSV instead of the table");
  p->add_option("--geometry-iterations", geometry_iterations,
                "SimulationOptions::contact_geometry_iterations (default: the library's)");
  p->add_option("--slide-trace", trace_path, "CSV of every slide step (cell, depth, y, |F|, rows, ...)");
  p->add_option("--smooth-normals", smooth_normals,
                "SimulationOptions::contact_smooth_normals, 0 or 1 (default: the library's)");
  p->add_option("--near-field", near_field,
                "SimulationOptions::contact_near_field, 0 or 1 (default: the library's)");
  p->add_option("--shaft-near-field", shaft_near_field,
                "SimulationOptions::contact_shaft_near_field, 0 or 1 (default: the library's)");
  p->add_flag("--cube", cube,
              "with --slide: also the cube's slide (scenes/cube_cylinder.scene, its tier and probe, "
              "40 mm along x across the top face from (30, 50) mm)");
  p->add_option("--slide-path", slide_path_kind,
                "normal: the tip d along the highest triangle's normal, the axis along it (the former "
                "ctest's slide); closest: the axis fixed, the tip where its distance to the closest surface point "
                "is r - d (the gap depth d at every sample)")
      ->check(CLI::IsMember({"normal", "closest"}))
      ->capture_default_str();
  p->add_option("--slide-axis", slide_axis_kind,
                "with --slide-path closest: the fixed axis, start-normal (the outward normal of the "
                "highest triangle at the slide's start) or vertical (+z)")
      ->check(CLI::IsMember({"start-normal", "vertical"}))
      ->capture_default_str();
  p->add_flag("--no-shaft", no_shaft, "the probe without its shaft (shaft length 0): the tip's own contact");
  p->add_option("--contact-spread", contact_spread,
                "SimulationOptions::contact_spread (default: the library's)");
  if (auto rc = p.parse(argc, argv)) return *rc;
  if (cells.empty()) cells = {7.0, 5.0, 4.0, 3.0};
  const std::vector<double> depths_mm{0.5, 1.0, 1.5, 2.0, 2.5, 3.0};
  std::vector<std::vector<double>> force_mn(cells.size(), std::vector<double>(depths_mm.size(), 0.0));
  std::vector<std::vector<int>> rows(cells.size(), std::vector<int>(depths_mm.size(), 0));
  std::vector<std::string> mesh_rows;  // cell size, vertices / tets, surface point, build time
  std::vector<std::string> slide_rows;
  FILE* trace = trace_path.empty() ? nullptr : std::fopen(trace_path.c_str(), "w");
  if (trace) std::fprintf(trace, "cell_mm,slide_depth_mm,y_mm,tip_x_mm,tip_y_mm,tip_z_mm,depth_mm,force_mn,rows,gap_depth_mm\n");
  if (csv) std::printf("cell_mm,host_vertices,host_tets,surface_z_mm,normal_z,depth_mm,force_mn,rows,build_s\n");
  // The slide (1 and 2 mm deep) along `heading` from `start` (x, y; unit m), 400 steps of 0.1 mm:
  // a row of slide_rows per depth (cell 0: the cube), every step to the trace.
  auto slide_path = [&](ni::Simulation& sim, double r, const Vec3& start, const Vec3& heading,
                        double cell_mm, const std::string& where) {
    const auto& mesh = sim.mesh(0);
    std::vector<ni::ToolPose> poses(1);
    std::vector<ni::ToolContact> contacts;
    ni::StepStats stats;
    const double s0 = 1e3 * start.dot(heading);
    const bool closest = slide_path_kind == "closest";
    Vec3 axis = Vec3::UnitZ();  // the fixed axis of --slide-path closest
    if (closest && slide_axis_kind == "start-normal") {
      const auto on = ni::top_of_surface(mesh, start.x(), start.y());
      if (!on) throw std::runtime_error(where + ": the slide's start misses the surface");
      axis = on->normal;
    }
    if (closest)
      std::fprintf(stderr, "contact_convergence_bench: %s: slide axis (%.4f, %.4f, %.4f)\n", where.c_str(), axis.x(),
                   axis.y(), axis.z());
    // The tip centre on at + t axis (t >= 0) at the distance r - d from the surface: the first
    // crossing (surface_probe's at_distance_along: at d = r the surface point itself).
    auto place_at_gap = [&](const Vec3& at, double target, int k) -> Vec3 {
      const auto x = ni::at_distance_along(mesh, at, axis, target);
      if (!x)
        throw std::runtime_error(where + ": --slide-path closest: step " + std::to_string(k) +
                                 ": no point within 30 mm along the axis at distance r - d from the surface");
      return *x;
    };
    for (double depth_mm : {1.0, 2.0}) {
      double fpd_min = std::numeric_limits<double>::infinity(), fpd_max = 0.0, f_min = fpd_min;
      int steps = 0;
      double y_at_min = 0.0, depth_at_min = 0.0;  // where |F| / depth is least, unit mm / m
      // Jumps: the largest relative change of |F| between two steps whose tip moved less than
      // 0.25 mm (the path's own jumps, where the highest triangle under it changes, excluded),
      // and how many such changes exceed 10 %.
      double jump = 0.0, jump_y = 0.0, f_prev = -1.0;
      int jumps = 0;
      Vec3 tip_prev = Vec3::Zero();
      for (int k = 0; k <= 400; ++k) {
        const Vec3 xy = start + 1e-4 * k * heading;
        const double along_mm = s0 + 0.1 * k;
        const auto on = ni::top_of_surface(mesh, xy.x(), xy.y());
        if (!on) throw std::runtime_error(where + ": the slide leaves the surface at step " + std::to_string(k));
        const Vec3 at = on->point_m, up = on->normal;
        if (closest) {
          poses[0].tip_m = place_at_gap(at, r - 1e-3 * depth_mm, k);
          poses[0].axis = axis;
        } else {
          poses[0].tip_m = at + (r - 1e-3 * depth_mm) * up;
          poses[0].axis = up;
        }
        sim.step(poses, contacts, stats);
        const ni::SurfacePoint near = ni::closest_on_surface(mesh, poses[0].tip_m);
        const double depth = r - near.normal.dot(poses[0].tip_m - near.point_m);
        const double gap = (poses[0].tip_m - near.point_m).norm();
        const double gap_depth = r - (near.normal.dot(poses[0].tip_m - near.point_m) < 0.0 ? -gap : gap);
        const double per = closest ? gap_depth : depth;  // the depth of |F| / depth
        const double f = contacts[0].force_n.norm();
        if (f_prev >= 0.0 && (poses[0].tip_m - tip_prev).norm() < 2.5e-4 && std::max(f, f_prev) > 0.0) {
          const double rel = std::abs(f - f_prev) / std::max(f, f_prev);
          if (rel > 0.1) ++jumps;
          if (rel > jump) {
            jump = rel;
            jump_y = along_mm;
          }
        }
        f_prev = f;
        tip_prev = poses[0].tip_m;
        if (trace)
          std::fprintf(trace, "%g,%g,%.1f,%.5f,%.5f,%.5f,%.4f,%.4f,%d,%.4f\n", cell_mm, depth_mm, along_mm,
                       1e3 * poses[0].tip_m.x(), 1e3 * poses[0].tip_m.y(), 1e3 * poses[0].tip_m.z(),
                       1e3 * depth, 1e3 * f, stats.contact_rows, 1e3 * gap_depth);
        f_min = std::min(f_min, f);
        if (f / per < fpd_min) {
          y_at_min = along_mm;
          depth_at_min = per;
        }
        fpd_min = std::min(fpd_min, f / per);
        fpd_max = std::max(fpd_max, f / per);
        ++steps;
      }
      char row[256];
      std::snprintf(row, sizeof row, "%g,%g,%d,%.3f,%.1f,%.1f,%.2f,%.1f,%.3f,%.3f,%.1f,%d", cell_mm, depth_mm,
                    steps, 1e3 * f_min, fpd_min, fpd_max, fpd_max / fpd_min, y_at_min, 1e3 * depth_at_min,
                    jump, jump_y, jumps);
      slide_rows.emplace_back(row);
    }
  };
  try {
    for (std::size_t ci = 0; ci < cells.size(); ++ci) {
      const fs::path scene = neurosim::bench::scene_at(cells[ci], dir, "contact_convergence_bench");
      neurosim::scene::Model model = neurosim::scene::load_model(scene);
      model.effects.tier = neurosim::scene::Tier::kLinear;
      if (no_shaft) model.tools.at(0).shaft_length_m = 0.0;
      if (!element.empty()) {
        const auto e = neurosim::fem::parse_element(element);
        if (!e) throw std::runtime_error("--element " + element + ": expected " + neurosim::fem::element_names());
        model.set_element(*e);
      }
      const auto t0 = neurosim::common::Clock::now();
      ni::SimulationOptions options;
      if (geometry_iterations > 0) options.contact_geometry_iterations = geometry_iterations;
      if (contact_spread >= 0.0) options.contact_spread = contact_spread;
      if (smooth_normals >= 0) options.contact_smooth_normals = smooth_normals != 0;
      if (near_field >= 0) options.contact_near_field = near_field != 0;
      if (shaft_near_field >= 0) options.contact_shaft_near_field = shaft_near_field != 0;
      auto sim = ni::Simulation::build(model, options);
      const double build_s = neurosim::common::seconds_since(t0);
      const auto& mesh = sim->mesh(0);
      const auto press_at = ni::top_of_surface(mesh, 1e-3 * x_mm, 1e-3 * y_mm);
      if (!press_at) throw std::runtime_error(scene.string() + ": the press line misses the brain's surface");
      const Vec3 top = press_at->point_m, n = press_at->normal;
      const double r = model.tools.at(0).tip_radius_m;
      std::vector<ni::ToolPose> poses(1);
      std::vector<ni::ToolContact> contacts;
      ni::StepStats stats;
      for (std::size_t di = 0; di < depths_mm.size(); ++di) {
        poses[0].tip_m = top + Vec3(0, 0, r - 1e-3 * depths_mm[di]);
        poses[0].axis = Vec3::UnitZ();
        sim->step(poses, contacts, stats);
        if (!stats.converged) throw std::runtime_error(scene.string() + ": the contact LCP did not converge");
        force_mn[ci][di] = 1e3 * contacts[0].force_n.norm();
        rows[ci][di] = stats.contact_rows;
        if (csv)
          std::printf("%g,%zu,%zu,%.3f,%.4f,%g,%.4f,%d,%.1f\n", cells[ci], mesh.num_vertices(), mesh.num_tets(),
                      1e3 * top.z(), n.z(), depths_mm[di], force_mn[ci][di], stats.contact_rows, build_s);
        std::fflush(stdout);
      }
      char mesh_row[160];
      std::snprintf(mesh_row, sizeof mesh_row, "| %g mm | %zu / %zu | %.2f / %.4f | %.1f |", cells[ci],
                    mesh.num_vertices(), mesh.num_tets(), 1e3 * top.z(), n.z(), build_s);
      mesh_rows.emplace_back(mesh_row);
      if (slide) slide_path(*sim, r, Vec3(0.060, 0.080, 0.0), Vec3::UnitY(), cells[ci], scene.string());
    }
    if (slide && cube) {
      const fs::path scene = fs::path(NEUROSIM_SOURCE_DIR) / "scenes" / "cube_cylinder.scene";
      neurosim::scene::Model model = neurosim::scene::load_model(scene);
      if (no_shaft) model.tools.at(0).shaft_length_m = 0.0;
      ni::SimulationOptions options;
      if (contact_spread >= 0.0) options.contact_spread = contact_spread;
      if (smooth_normals >= 0) options.contact_smooth_normals = smooth_normals != 0;
      if (near_field >= 0) options.contact_near_field = near_field != 0;
      if (shaft_near_field >= 0) options.contact_shaft_near_field = shaft_near_field != 0;
      auto sim = ni::Simulation::build(model, options);
      slide_path(*sim, model.tools.at(0).tip_radius_m, Vec3(0.030, 0.050, 0.0), Vec3::UnitX(), 0.0,
                 scene.string());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contact_convergence_bench: %s\n", e.what());
    return 1;
  }
  // Successive differences and the order they imply.
  auto order = [&](std::size_t ci, std::size_t di) {
    return observed_order(cells[ci], cells[ci + 1], cells[ci + 2], force_mn[ci][di] - force_mn[ci + 1][di],
                          force_mn[ci + 1][di] - force_mn[ci + 2][di]);
  };
  if (csv) {
    std::printf("\ndepth_mm");
    for (std::size_t ci = 0; ci + 1 < cells.size(); ++ci) std::printf(",F%g-F%g_mn", cells[ci], cells[ci + 1]);
    for (std::size_t ci = 0; ci + 2 < cells.size(); ++ci)
      std::printf(",order_%g_%g_%g", cells[ci], cells[ci + 1], cells[ci + 2]);
    std::printf("\n");
    for (std::size_t di = 0; di < depths_mm.size(); ++di) {
      std::printf("%g", depths_mm[di]);
      for (std::size_t ci = 0; ci + 1 < cells.size(); ++ci)
        std::printf(",%.4f", force_mn[ci][di] - force_mn[ci + 1][di]);
      for (std::size_t ci = 0; ci + 2 < cells.size(); ++ci) std::printf(",%.2f", order(ci, di));
      std::printf("\n");
    }
  } else {
    std::printf("| cells | brain vertices / tets | surface z mm / normal z | build s |\n|---|---|---|---|\n");
    for (const auto& r : mesh_rows) std::printf("%s\n", r.c_str());
    std::printf("\n| cells |");
    for (double d : depths_mm) std::printf(" %g mm |", d);
    std::printf("\n|---|");
    for (std::size_t di = 0; di < depths_mm.size(); ++di) std::printf("---|");
    std::printf("\n");
    for (std::size_t ci = 0; ci < cells.size(); ++ci) {
      std::printf("| %g mm |", cells[ci]);
      for (std::size_t di = 0; di < depths_mm.size(); ++di)
        std::printf(" %.2f mN (%d) |", force_mn[ci][di], rows[ci][di]);
      std::printf("\n");
    }
    if (cells.size() >= 2) {
      std::printf("\n| depth |");
      for (std::size_t ci = 0; ci + 1 < cells.size(); ++ci) std::printf(" F%g - F%g mN |", cells[ci], cells[ci + 1]);
      for (std::size_t ci = 0; ci + 2 < cells.size(); ++ci)
        std::printf(" order %g/%g/%g |", cells[ci], cells[ci + 1], cells[ci + 2]);
      std::printf("\n|---|");
      for (std::size_t k = 0; k + 3 < 2 * cells.size(); ++k) std::printf("---|");
      std::printf("\n");
      for (std::size_t di = 0; di < depths_mm.size(); ++di) {
        std::printf("| %g mm |", depths_mm[di]);
        for (std::size_t ci = 0; ci + 1 < cells.size(); ++ci)
          std::printf(" %.2f |", force_mn[ci][di] - force_mn[ci + 1][di]);
        for (std::size_t ci = 0; ci + 2 < cells.size(); ++ci) std::printf(" %.2f |", order(ci, di));
        std::printf("\n");
      }
    }
  }
  if (trace) std::fclose(trace);
  if (slide) {
    std::printf("\ncell_mm,slide_depth_mm,steps,min_force_mn,force_per_depth_min_n_per_m,"
                "force_per_depth_max_n_per_m,spread,y_at_min_mm,depth_at_min_mm,max_jump,y_at_max_jump_mm,"
                "jumps_over_10pct\n");
    for (const auto& row : slide_rows) std::printf("%s\n", row.c_str());
  }
  return 0;
}
