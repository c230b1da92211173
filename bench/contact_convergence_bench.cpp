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
// --points N: instead of the one line, the press at N fixed points of the dorsal surface, the same
// world points on every mesh (seeded --seed, at least --spacing mm apart, taken on the first mesh
// where its highest surface point faces up, normal z >= 0.8, in the brain's upper 40 %): on each
// mesh the closest surface point q to the world point, the press axis the surface's normal over
// a --patch mm ball around q (patch_normal: each triangle weighted by its area inside the ball,
// the same on any mesh of the same surface), the tip centre at q + (r - d) n for d = 1, 2, 3 mm.
// Per depth and mesh: |F| mean / sd / min / max over the points, the successive differences
// (mean, sd, how many share the mean's sign), |F - F_ref| / F_ref (the last mesh the reference),
// |q - q_ref| and the normal's angle to the reference's (how far the surfaces differ there); the
// order of the mean force (Richardson on the three-mesh means, negative when the differences
// grow, with its 2.5 / 50 / 97.5 % over --bootstrap draws of the points), fit A (log |F_h -
// F_ref| / F_ref = c_k + p log h, least squares over the points), fit B (F_h / F_ref = a_k + b_k h^p,
// one p), the order per point from the last three meshes, and how |F - F_ref| correlates with
// the surface's change. --split K (repeat): each --cell-size mesh also split 1 -> 8 K times
// (tet_split.hpp: the same surface, the cells halved; the brain alone, as --brain-only), so the
// order of the discretization shows without the mesher's change of surface. --points-csv: every
// press. --cache-dir: SimulationOptions::compliance_cache_dir (a second run of a mesh reads its
// factor). --region R: each point pressed on its own sub-model (sub_model.hpp: the tetrahedra
// with centroid within R of the point, the cut faces clamped), cut on the unsplit mesh, then
// split: cells down to 0.44 mm under the tip (the 7 mm brain split 4 times) within 8 GB.
// --refine-cell H (repeat, fine to finer; the line's press only): the series is one brain (the
// one --cell-size, default 7 mm) meshed again by neurosim-model with cells of H within
// --refine-radius of the press point (its top on the line on the unrefined mesh), growing by
// --refine-grading mm per mm beyond: the mesher's surface and cells refined under the tip alone,
// down to 0.1 mm cells at a few ten thousand vertices. The table's "cells" are then H.
#include "patient_models.hpp"
#include "sub_model.hpp"
#include "tet_split.hpp"
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
#include <memory>
#include <numeric>
#include <random>
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

// The closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5).
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + d1 / (d1 - d3) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

// The surface's normal over a patch: the mean outward normal of the surface within radius_m of
// q, each triangle weighted by its area inside that ball (each triangle near q cut into
// sub-triangles of about 0.1 mm, those whose centroid lies within radius_m counted): the same
// integral on any mesh of the same surface (a split mesh's patch normal is its parent's), and
// across an edge or a vertex the mean of the faces around it, not one triangle's.
Vec3 patch_normal(const neurosim::mesh::TetMesh& mesh, const Vec3& q, double radius_m) {
  Vec3 sum = Vec3::Zero();
  const auto& x = mesh.vertices();
  for (const auto& t : mesh.surface()) {
    const Vec3 &a = x[t[0]], &b = x[t[1]], &c = x[t[2]];
    if ((closest_on_triangle(q, a, b, c) - q).norm() > radius_m) continue;
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int m = std::max(1, static_cast<int>(std::ceil(longest / 1e-4)));
    const Vec3 e1 = (b - a) / m, e2 = (c - a) / m;
    int inside = 0;
    for (int i = 0; i < m; ++i)
      for (int j = 0; i + j < m; ++j) {
        inside += (a + (i + 1.0 / 3.0) * e1 + (j + 1.0 / 3.0) * e2 - q).norm() <= radius_m;
        if (i + j + 2 <= m) inside += (a + (i + 2.0 / 3.0) * e1 + (j + 2.0 / 3.0) * e2 - q).norm() <= radius_m;
      }
    sum += 0.5 * (b - a).cross(c - a) * (static_cast<double>(inside) / (static_cast<double>(m) * m));
  }
  return sum.normalized();
}

// --points: the press at many fixed points, the same world points on every mesh.
struct MeshEntry {
  double cell_mm{0.0};
  int split{0};
  double h_mm() const { return cell_mm / std::pow(2.0, split); }
  std::string label() const {
    char s[64];
    if (split == 0)
      std::snprintf(s, sizeof s, "%g mm", cell_mm);
    else
      std::snprintf(s, sizeof s, "%g mm / %d", cell_mm, 1 << (3 * split));
    return s;
  }
};

struct MeshRun {
  MeshEntry entry;
  std::size_t vertices{0}, tets{0};
  double build_s{0.0}, press_s{0.0};
  std::vector<Vec3> q, n;                // per point: the closest surface point (m) and its normal
  std::vector<std::vector<double>> f;    // [point][depth] |F|, mN (nan: the LCP did not converge)
  std::vector<std::vector<int>> rows;    // [point][depth]
};

double mean_of(const std::vector<double>& v) {
  return v.empty() ? std::nan("") : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}
double sd_of(const std::vector<double>& v) {
  if (v.size() < 2) return std::nan("");
  const double m = mean_of(v);
  double s = 0.0;
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / static_cast<double>(v.size() - 1));
}
double quantile_of(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const double at = q * static_cast<double>(v.size() - 1);
  const std::size_t i = static_cast<std::size_t>(std::floor(at));
  const double w = at - static_cast<double>(i);
  return i + 1 < v.size() ? (1.0 - w) * v[i] + w * v[i + 1] : v[i];
}

// Fit A: log(|F_h - F_ref| / F_ref) = c_k + p log h over the points k (an intercept per point,
// one slope), the meshes before the reference (the last): the slope and its standard error.
struct Slope {
  double p{std::nan("")}, se{std::nan("")};
};
Slope fit_log_error(const std::vector<double>& h, const std::vector<std::vector<double>>& f,
                    const std::vector<std::size_t>& points) {
  const std::size_t ref = h.size() - 1;
  double sxy = 0.0, sxx = 0.0, syy = 0.0;
  std::size_t n_obs = 0, n_pts = 0;
  for (std::size_t k : points) {
    std::vector<double> x, y;
    for (std::size_t m = 0; m < ref; ++m) {
      const double e = std::abs(f[m][k] - f[ref][k]) / f[ref][k];
      if (!(e > 0.0) || !std::isfinite(e)) continue;
      x.push_back(std::log(h[m]));
      y.push_back(std::log(e));
    }
    if (x.size() < 2) continue;
    const double mx = mean_of(x), my = mean_of(y);
    for (std::size_t i = 0; i < x.size(); ++i) {
      sxy += (x[i] - mx) * (y[i] - my);
      sxx += (x[i] - mx) * (x[i] - mx);
      syy += (y[i] - my) * (y[i] - my);
    }
    n_obs += x.size();
    ++n_pts;
  }
  Slope s;
  if (sxx <= 0.0) return s;
  s.p = sxy / sxx;
  const double ss_res = syy - s.p * sxy;
  if (n_obs > n_pts + 1) s.se = std::sqrt(std::max(0.0, ss_res) / static_cast<double>(n_obs - n_pts - 1) / sxx);
  return s;
}

// Fit B: F_h / F_ref = a_k + b_k h^p per point (the limit a_k and the constant b_k of each point,
// one order p for all), p on a grid of 0.01 in [0.05, 6] minimizing the summed squared
// residual; also that residual's RMS (relative to F_ref). p at an end of the grid: no order.
struct CommonOrder {
  double p{std::nan("")}, rms{std::nan("")};
};
CommonOrder fit_common_order(const std::vector<double>& h, const std::vector<std::vector<double>>& f,
                             const std::vector<std::size_t>& points) {
  const std::size_t nm = h.size(), ref = nm - 1;
  CommonOrder best;
  double best_ss = std::numeric_limits<double>::infinity();
  std::size_t n_obs = 0;
  for (int i = 0; i <= 595; ++i) {
    const double p = 0.05 + 0.01 * i;
    double ss = 0.0;
    n_obs = 0;
    for (std::size_t k : points) {
      double sx = 0.0, sy = 0.0, sxx = 0.0, sxy = 0.0, syy = 0.0;
      for (std::size_t m = 0; m < nm; ++m) {
        const double x = std::pow(h[m], p), y = f[m][k] / f[ref][k];
        sx += x, sy += y, sxx += x * x, sxy += x * y, syy += y * y;
      }
      const double n = static_cast<double>(nm);
      const double vxx = sxx - sx * sx / n, vxy = sxy - sx * sy / n, vyy = syy - sy * sy / n;
      ss += vyy - (vxx > 0.0 ? vxy * vxy / vxx : 0.0);
      n_obs += nm;
    }
    if (ss < best_ss) {
      best_ss = ss;
      best.p = p;
    }
  }
  best.rms = std::sqrt(best_ss / static_cast<double>(std::max<std::size_t>(n_obs, 1)));
  return best;
}

// The points: seeded (x, y) over the first mesh's bounding box (15 mm in from its sides), kept
// where the highest surface point on the vertical line faces up (normal z >= 0.8) in the upper
// 40 % of the brain's height and lies at least spacing_mm from every point kept before.
std::vector<Vec3> dorsal_points(const neurosim::mesh::TetMesh& mesh, int count, unsigned seed, double spacing_mm) {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int v : mesh.surface_vertices()) {
    lo = lo.cwiseMin(mesh.vertices()[v]);
    hi = hi.cwiseMax(mesh.vertices()[v]);
  }
  std::mt19937 rng(seed);
  auto u = [&] { return (static_cast<double>(rng()) + 0.5) / 4294967296.0; };
  std::vector<Vec3> out;
  for (int tries = 0; tries < 20000 && static_cast<int>(out.size()) < count; ++tries) {
    const double x = lo.x() + 0.015 + u() * (hi.x() - lo.x() - 0.03);
    const double y = lo.y() + 0.015 + u() * (hi.y() - lo.y() - 0.03);
    const auto top = ni::top_of_surface(mesh, x, y);
    if (!top || top->normal.z() < 0.8 || top->point_m.z() < lo.z() + 0.6 * (hi.z() - lo.z())) continue;
    bool near = false;
    for (const Vec3& q : out) near = near || (q - top->point_m).norm() < 1e-3 * spacing_mm;
    if (!near) out.push_back(top->point_m);
  }
  return out;
}


// As observed_order, but p in [-6, 6]: a negative p says the differences grow as the cells shrink
// (|F(h2) - F(h3)| > |F(h1) - F(h2)| scaled by the sizes); at p = 0 the ratio's limit
// ln(h1 / h2) / ln(h2 / h3). nan if the differences change sign or the ratio is out of reach.
double signed_order(double h1, double h2, double h3, double d12, double d23) {
  if (!(d12 * d23 > 0.0)) return std::nan("");
  const double ratio = d12 / d23;
  auto g = [&](double p) {
    if (std::abs(p) < 1e-9) return std::log(h1 / h2) / std::log(h2 / h3) - ratio;
    return (std::pow(h1, p) - std::pow(h2, p)) / (std::pow(h2, p) - std::pow(h3, p)) - ratio;
  };
  double lo = -6.0, hi = 6.0;
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
  int points = 0;
  unsigned seed = 1;
  double spacing_mm = 10.0, patch_mm = 3.0;
  std::vector<int> splits;
  bool brain_only = false;
  int bootstrap = 2000;
  std::string points_csv, cache_dir;
  double region_mm = 0.0;
  int max_rows = 0;
  int lcp_iterations = 0;
  std::vector<double> refine_cells;
  double refine_radius_mm = 3.0, refine_grading = 0.25;
  neurosim::cli::Parser p("contact_convergence_bench",
                          "The same press on the brain at several cell sizes: force convergence.");
  p.add_option("--cell-size", cells, "brain cell size, unit mm (repeat; coarse to fine)");
  p.add_option("--models", dir, "folder of the built scenes (as scale_bench)")->capture_default_str();
  p.add_option("--x", x_mm, "press line x, unit mm")->capture_default_str();
  std::vector<double> line_depths_mm;
  p.add_option("--depth", line_depths_mm, "the line's press depths, unit mm (repeat; default 0.5 to 3 by 0.5)")
      ->check(neurosim::cli::finite());
  p.add_option("--y", y_mm, "press line y, unit mm")->capture_default_str();
  p.add_option("--element", element, "every mesh's element (default: the scene's)");
  p.add_flag("--slide", slide, "also the 40 mm slide at 1 and 2 mm (|F| / depth spread)");
  p.add_flag("--csv", csv, "CSV instead of the table");
  p.add_option("--geometry-iterations", geometry_iterations,
               "SimulationOptions::contact_geometry_iterations (default: the library's)");
  p.add_option("--slide-trace", trace_path, "CSV of every slide step (cell, depth, y, |F|, rows, ...)");
  p.add_option("--smooth-normals", smooth_normals,
               "SimulationOptions::contact_smooth_normals, 0 or 1 (default: the library's)");
  p.add_option("--near-field", near_field,
               "SimulationOptions::contact_near_field, 0 or 1 (default: the library's)");
  p.add_option("--shaft-near-field", shaft_near_field,
               "SimulationOptions::contact_shaft_near_field, 0 or 1 (default: the library's)");
  p.add_flag("--cube", cube,
             "with --slide: also the cube's slide (scenes/cube_cylinder.scene, its tier and probe, "
             "40 mm along x across the top face from (30, 50) mm)");
  p.add_option("--slide-path", slide_path_kind,
               "normal: the tip d along the highest triangle's normal, the axis along it (the former "
               "ctest's slide); closest: the axis fixed, the tip where its distance to the closest surface point "
               "is r - d (the gap depth d at every sample)")
      ->check(neurosim::cli::one_of({"normal", "closest"}))
      ->capture_default_str();
  p.add_option("--slide-axis", slide_axis_kind,
               "with --slide-path closest: the fixed axis, start-normal (the outward normal of the "
               "highest triangle at the slide's start) or vertical (+z)")
      ->check(neurosim::cli::one_of({"start-normal", "vertical"}))
      ->capture_default_str();
  p.add_flag("--no-shaft", no_shaft, "the probe without its shaft (shaft length 0): the tip's own contact");
  p.add_option("--contact-spread", contact_spread,
               "SimulationOptions::contact_spread (default: the library's)");
  p.add_option("--points", points,
               "the press at this many fixed points of the dorsal surface instead of the one line (1, 2, 3 mm "
               "along each mesh's normal at its closest point to the same world point): per mesh the mean and "
               "spread of |F| and of the differences, the fitted order")
      ->capture_default_str();
  p.add_option("--seed", seed, "with --points: the points' seed")->capture_default_str();
  p.add_option("--spacing", spacing_mm, "with --points: the least distance between two points, unit mm")
      ->capture_default_str();
  p.add_option("--split", splits,
               "with --points: every mesh also split 1 -> 8 this many times (repeat: 0, 1, 2; the brain alone): "
               "the same surface, finer cells")
      ->check(neurosim::cli::range(0, 4));
  p.add_option("--max-rows", max_rows,
               "SimulationOptions::max_contact_nodes_per_tool (default: the library's; the 1 mm cells' patch "
               "of a 3 mm press holds more rows than its 32)");
  p.add_option("--region", region_mm,
               "with --points: each point pressed on its own sub-model, the brain's tetrahedra with centroid "
               "within this distance of the point (sub_model.hpp: the face-connected piece, every cut face's "
               "node clamped), cut on the unsplit mesh and then split: the refinement below the whole brain's "
               "reach, unit mm (0: the whole brain)")
      ->capture_default_str();
  p.add_option("--patch", patch_mm,
               "with --points: the press axis is the area-weighted normal of the surface triangles within this "
               "distance of the closest point, unit mm")
      ->capture_default_str();
  p.add_flag("--brain-only", brain_only, "the brain without the artery (as --split runs it)");
  p.add_option("--bootstrap", bootstrap, "with --points: bootstrap draws of the points for the order's spread")
      ->capture_default_str();
  p.add_option("--points-csv", points_csv, "with --points: every press as CSV (mesh, point, surface point, normal, depth, |F|, rows)");
  p.add_option("--lcp-iterations", lcp_iterations,
               "SimulationOptions::lcp_max_iterations (default: the library's; a patch of 1000 rows needs more pivots)");
  p.add_option("--refine-cell", refine_cells,
               "the line's press on one brain (--cell-size, default 7) refined to this cell size around the press "
               "point, unit mm (repeat; coarse to fine)")
      ->check(neurosim::cli::finite());
  p.add_option("--refine-radius", refine_radius_mm, "with --refine-cell: radius of the finest cells, unit mm")
      ->check(neurosim::cli::finite())
      ->capture_default_str();
  p.add_option("--refine-grading", refine_grading,
               "with --refine-cell: growth of the cells beyond --refine-radius, mm per mm")
      ->check(neurosim::cli::finite())
      ->capture_default_str();
  p.add_option("--cache-dir", cache_dir,
               "SimulationOptions::compliance_cache_dir (the host's factor and boundary operator on disk: a second "
               "run of a mesh skips its factorization)");
  if (auto rc = p.parse(argc, argv)) return *rc;
  double far_cell_mm = 0.0;      // with --refine-cell: the brain's cell size away from the press
  double refine_centre_mm[3]{};  // the press point on the unrefined brain, image mm
  if (!refine_cells.empty()) {
    if (cells.size() > 1 || points > 0 || slide || region_mm > 0.0 || !splits.empty()) {
      std::fprintf(stderr, "contact_convergence_bench: --refine-cell takes one --cell-size and the line's press "
                           "(not --points, --slide, --region or --split)\n");
      return 2;
    }
    far_cell_mm = cells.empty() ? 7.0 : cells.front();
    try {
      const fs::path scene = neurosim::bench::scene_at(far_cell_mm, dir, "contact_convergence_bench");
      const neurosim::scene::Model model = neurosim::scene::load_model(scene);
      const auto top = ni::top_of_surface(model.meshes.front().mesh, 1e-3 * x_mm, 1e-3 * y_mm);
      if (!top) throw std::runtime_error(scene.string() + ": the press line misses the brain's surface");
      for (int k = 0; k < 3; ++k) refine_centre_mm[k] = std::round(1e5 * top->point_m[k]) / 1e2;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "contact_convergence_bench: %s\n", e.what());
      return 1;
    }
    cells = refine_cells;
  }
  if (cells.empty()) cells = {7.0, 5.0, 4.0, 3.0};
  // The scene of the line's press at cells[ci] (the refined brain's with --refine-cell).
  auto line_scene = [&](std::size_t ci) {
    if (refine_cells.empty()) return neurosim::bench::scene_at(cells[ci], dir, "contact_convergence_bench");
    return neurosim::bench::refined_scene_at(far_cell_mm, cells[ci], refine_centre_mm, refine_radius_mm,
                                             refine_grading, dir, "contact_convergence_bench");
  };
  auto prepare = [&](neurosim::scene::Model& model) {
    model.effects.tier = neurosim::scene::Tier::kLinear;
    if (no_shaft) model.tools.at(0).shaft_length_m = 0.0;
    if (!element.empty()) {
      const auto e = neurosim::fem::parse_element(element);
      if (!e) throw std::runtime_error("--element " + element + ": expected " + neurosim::fem::element_names());
      model.set_element(*e);
    }
  };
  auto make_options = [&] {
    ni::SimulationOptions options;
    if (geometry_iterations > 0) options.contact_geometry_iterations = geometry_iterations;
    if (contact_spread >= 0.0) options.contact_spread = contact_spread;
    if (smooth_normals >= 0) options.contact_smooth_normals = smooth_normals != 0;
    if (near_field >= 0) options.contact_near_field = near_field != 0;
    if (shaft_near_field >= 0) options.contact_shaft_near_field = shaft_near_field != 0;
    if (max_rows > 0) options.max_contact_nodes_per_tool = max_rows;
    if (lcp_iterations > 0) options.lcp_max_iterations = lcp_iterations;
    options.compliance_cache_dir = cache_dir;
    return options;
  };
  if (points > 0) {
    // The meshes: every --cell-size, each split --split times (all of them: ascending).
    if (splits.empty()) splits = {0};
    std::sort(splits.begin(), splits.end());
    std::vector<MeshEntry> entries;
    for (double c : cells)
      for (int s : splits) entries.push_back({c, s});
    if (entries.size() < 2) {
      std::fprintf(stderr, "contact_convergence_bench: --points needs at least 2 meshes\n");
      return 2;
    }
    const std::vector<double> pdepths_mm{1.0, 2.0, 3.0};
    std::vector<MeshRun> runs;
    std::vector<Vec3> world;  // the press points, from the first mesh
    FILE* pcsv = points_csv.empty() ? nullptr : std::fopen(points_csv.c_str(), "w");
    if (pcsv)
      std::fprintf(pcsv, "mesh,h_mm,point,px_mm,py_mm,pz_mm,qx_mm,qy_mm,qz_mm,nx,ny,nz,depth_mm,force_mn,rows\n");
    try {
      // The model of an entry (the brain alone when split or cut), cut around centre when given.
      auto entry_model = [&](const MeshEntry& e, const Vec3* centre) {
        const fs::path scene = neurosim::bench::scene_at(e.cell_mm, dir, "contact_convergence_bench");
        neurosim::scene::Model model = neurosim::scene::load_model(scene);
        prepare(model);
        if (brain_only || e.split > 0 || centre) {
          // The brain alone (a split host would be carved anew around the artery).
          model.meshes.resize(1);
          model.couplings.clear();
          model.effects.coupling = false;
          model.loads.clear();
          model.prescribed.clear();
        }
        if (centre) {
          std::vector<neurosim::mesh::Tri> cut =
              neurosim::bench::cut_region(model.meshes.front(), *centre, 1e-3 * region_mm);
          for (int s = 0; s < e.split; ++s) neurosim::bench::split_region(model.meshes.front(), cut);
        } else {
          for (int s = 0; s < e.split; ++s) neurosim::bench::split_loaded_mesh(model.meshes.front());
        }
        return model;
      };
      for (const MeshEntry& e : entries) {
        if (world.empty()) {
          // The points on the first mesh (uncut, unsplit: the same points with and without --region).
          const neurosim::scene::Model first = entry_model(MeshEntry{e.cell_mm, 0}, nullptr);
          world = dorsal_points(first.meshes.front().mesh, points, seed, spacing_mm);
          if (static_cast<int>(world.size()) < points)
            std::fprintf(stderr, "contact_convergence_bench: only %zu points at %g mm spacing\n", world.size(),
                         spacing_mm);
        }
        MeshRun run;
        run.entry = e;
        std::unique_ptr<ni::Simulation> sim;
        double r = 0.0;
        auto build = [&](const Vec3* centre) {
          sim.reset();
          const neurosim::scene::Model model = entry_model(e, centre);
          r = model.tools.at(0).tip_radius_m;
          const auto t0 = neurosim::common::Clock::now();
          sim = ni::Simulation::build(model, make_options());
          run.build_s += neurosim::common::seconds_since(t0);
          // With --region: the largest sub-model's size.
          run.vertices = std::max(run.vertices, sim->mesh(0).num_vertices());
          run.tets = std::max(run.tets, sim->mesh(0).num_tets());
        };
        if (region_mm <= 0.0) build(nullptr);
        std::vector<ni::ToolPose> poses(1);
        std::vector<ni::ToolContact> contacts;
        ni::StepStats stats;
        double press_s = 0.0;
        for (std::size_t k = 0; k < world.size(); ++k) {
          if (region_mm > 0.0) build(&world[k]);
          const auto t1 = neurosim::common::Clock::now();
          const auto& mesh = sim->mesh(0);
          ni::SurfacePoint at = ni::closest_on_surface(mesh, world[k]);
          at.normal = patch_normal(mesh, at.point_m, 1e-3 * patch_mm);
          run.q.push_back(at.point_m);
          run.n.push_back(at.normal);
          run.f.emplace_back();
          run.rows.emplace_back();
          for (double d : pdepths_mm) {
            poses[0].tip_m = at.point_m + (r - 1e-3 * d) * at.normal;
            poses[0].axis = at.normal;
            sim->step(poses, contacts, stats);
            const double f = stats.converged ? 1e3 * contacts[0].force_n.norm() : std::nan("");
            run.f.back().push_back(f);
            run.rows.back().push_back(stats.contact_rows);
            if (pcsv)
              std::fprintf(pcsv, "%s,%g,%zu,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.5f,%.5f,%.5f,%g,%.4f,%d\n",
                           e.label().c_str(), e.h_mm(), k, 1e3 * world[k].x(), 1e3 * world[k].y(),
                           1e3 * world[k].z(), 1e3 * at.point_m.x(), 1e3 * at.point_m.y(), 1e3 * at.point_m.z(),
                           at.normal.x(), at.normal.y(), at.normal.z(), d, f, stats.contact_rows);
          }
          press_s += neurosim::common::seconds_since(t1);
        }
        sim.reset();
        run.press_s = press_s;
        std::fprintf(stderr, "contact_convergence_bench: %s: %zu vertices, %zu tets, build %.1f s, %zu x %zu presses %.1f s\n",
                     e.label().c_str(), run.vertices, run.tets, run.build_s, world.size(), pdepths_mm.size(),
                     run.press_s);
        if (pcsv) std::fflush(pcsv);
        runs.push_back(std::move(run));
      }
    } catch (const std::exception& ex) {
      std::fprintf(stderr, "contact_convergence_bench: %s\n", ex.what());
      return 1;
    }
    if (pcsv) std::fclose(pcsv);
    const std::size_t nm = runs.size(), ref = nm - 1, np = world.size();
    std::vector<double> h;
    for (const auto& r : runs) h.push_back(r.entry.h_mm());
    std::printf("points: %zu (seed %u, spacing %g mm, from the %s mesh); reference: %s\n\n", np, seed, spacing_mm,
                runs.front().entry.label().c_str(), runs.back().entry.label().c_str());
    std::printf("| mesh | h mm | vertices / tets | build s | |q - q_ref| mm mean / max | normal to ref deg mean / max |\n"
                "|---|---|---|---|---|---|\n");
    for (const auto& r : runs) {
      std::vector<double> dq, ang;
      for (std::size_t k = 0; k < np; ++k) {
        dq.push_back(1e3 * (r.q[k] - runs[ref].q[k]).norm());
        ang.push_back(180.0 / M_PI * std::acos(std::clamp(r.n[k].dot(runs[ref].n[k]), -1.0, 1.0)));
      }
      std::printf("| %s | %g | %zu / %zu | %.1f | %.3f / %.3f | %.2f / %.2f |\n", r.entry.label().c_str(),
                  r.entry.h_mm(), r.vertices, r.tets, r.build_s, mean_of(dq),
                  *std::max_element(dq.begin(), dq.end()), mean_of(ang), *std::max_element(ang.begin(), ang.end()));
    }
    for (std::size_t di = 0; di < pdepths_mm.size(); ++di) {
      // f[m][k] at this depth; the points where every mesh converged.
      std::vector<std::vector<double>> f(nm, std::vector<double>(np));
      std::vector<std::size_t> ok;
      for (std::size_t k = 0; k < np; ++k) {
        bool good = true;
        for (std::size_t m = 0; m < nm; ++m) {
          f[m][k] = runs[m].f[k][di];
          good = good && std::isfinite(f[m][k]) && f[m][k] > 0.0;
        }
        if (good) ok.push_back(k);
      }
      std::printf("\n### %g mm deep: %zu of %zu points (force > 0 and converged on every mesh)\n\n", pdepths_mm[di],
                  ok.size(), np);
      std::printf("| mesh | |F| mN mean / sd / min / max | F - F_next mN mean / sd | |F - F_next| mN mean | same sign as the mean | |F - F_ref| / F_ref mean / median / max |\n"
                  "|---|---|---|---|---|---|\n");
      for (std::size_t m = 0; m < nm; ++m) {
        std::vector<double> fm, dm, adm, rel;
        for (std::size_t k : ok) {
          fm.push_back(f[m][k]);
          if (m + 1 < nm) {
            dm.push_back(f[m][k] - f[m + 1][k]);
            adm.push_back(std::abs(dm.back()));
          }
          if (m < ref) rel.push_back(std::abs(f[m][k] - f[ref][k]) / f[ref][k]);
        }
        const double md = mean_of(dm);
        int same = 0;
        for (double d : dm) same += (d > 0.0) == (md > 0.0);
        std::printf("| %s | %.2f / %.2f / %.2f / %.2f |", runs[m].entry.label().c_str(), mean_of(fm), sd_of(fm),
                    *std::min_element(fm.begin(), fm.end()), *std::max_element(fm.begin(), fm.end()));
        if (m + 1 < nm)
          std::printf(" %+.3f / %.3f | %.3f | %d of %zu |", md, sd_of(dm), mean_of(adm), same, dm.size());
        else
          std::printf(" | | |");
        if (m < ref)
          std::printf(" %.4f / %.4f / %.4f |\n", mean_of(rel), quantile_of(rel, 0.5),
                      *std::max_element(rel.begin(), rel.end()));
        else
          std::printf(" (reference) |\n");
      }
      if (nm < 3) continue;  // an order needs three meshes
      // The fits and their spread over the points (bootstrap: the points drawn with replacement).
      const Slope a = fit_log_error(h, f, ok);
      const CommonOrder b = fit_common_order(h, f, ok);
      std::mt19937 brng(7);
      std::vector<double> pa, pb;
      for (int it = 0; it < bootstrap; ++it) {
        std::vector<std::size_t> draw;
        for (std::size_t i = 0; i < ok.size(); ++i) draw.push_back(ok[brng() % ok.size()]);
        pa.push_back(fit_log_error(h, f, draw).p);
        pb.push_back(fit_common_order(h, f, draw).p);
      }
      // Per point: the order that the last three meshes' two differences imply (nan: they
      // change sign or imply none).
      std::vector<double> p3;
      int undefined = 0;
      for (std::size_t k : ok) {
        const double o = observed_order(h[nm - 3], h[nm - 2], h[nm - 1], f[nm - 3][k] - f[nm - 2][k],
                                        f[nm - 2][k] - f[nm - 1][k]);
        if (std::isfinite(o))
          p3.push_back(o);
        else
          ++undefined;
      }
      // How much of |F - F_ref| the surface's change explains: Pearson r over (point, mesh).
      std::vector<double> xs_dq, xs_ang, ys;
      for (std::size_t m = 0; m < ref; ++m)
        for (std::size_t k : ok) {
          xs_dq.push_back((runs[m].q[k] - runs[ref].q[k]).norm());
          xs_ang.push_back(std::acos(std::clamp(runs[m].n[k].dot(runs[ref].n[k]), -1.0, 1.0)));
          ys.push_back(std::abs(f[m][k] - f[ref][k]) / f[ref][k]);
        }
      auto pearson = [](const std::vector<double>& x, const std::vector<double>& y) {
        const double mx = mean_of(x), my = mean_of(y);
        double sxy = 0.0, sxx = 0.0, syy = 0.0;
        for (std::size_t i = 0; i < x.size(); ++i) {
          sxy += (x[i] - mx) * (y[i] - my);
          sxx += (x[i] - mx) * (x[i] - mx);
          syy += (y[i] - my) * (y[i] - my);
        }
        return sxx > 0.0 && syy > 0.0 ? sxy / std::sqrt(sxx * syy) : std::nan("");
      };
      std::printf("\nOrder, fit A (log |F_h - F_ref| / F_ref = c_k + p log h, reference %s): p = %.2f (standard error %.2f; "
                  "bootstrap over points 2.5 / 50 / 97.5 %%: %.2f / %.2f / %.2f)\n",
                  runs[ref].entry.label().c_str(), a.p, a.se, quantile_of(pa, 0.025), quantile_of(pa, 0.5),
                  quantile_of(pa, 0.975));
      std::printf("Order, fit B (F_h / F_ref = a_k + b_k h^p, every mesh, one p; grid 0.05..6): p = %.2f (residual RMS "
                  "%.4f of F_ref; bootstrap 2.5 / 50 / 97.5 %%: %.2f / %.2f / %.2f)\n",
                  b.p, b.rms, quantile_of(pb, 0.025), quantile_of(pb, 0.5), quantile_of(pb, 0.975));
      std::printf("Order per point from the last three meshes (%g / %g / %g): defined at %zu of %zu points "
                  "(median %.2f, quartiles %.2f / %.2f); %d with differences of opposite sign or no order\n",
                  h[nm - 3], h[nm - 2], h[nm - 1], p3.size(), ok.size(), quantile_of(p3, 0.5),
                  quantile_of(p3, 0.25), quantile_of(p3, 0.75), undefined);
      {
        // The order of the mean force over the points (Richardson on the means), and its spread
        // over bootstrap draws of the points.
        auto mean_force = [&](const std::vector<std::size_t>& pts) {
          std::vector<double> mf(nm, 0.0);
          for (std::size_t m = 0; m < nm; ++m) {
            for (std::size_t k : pts) mf[m] += f[m][k];
            mf[m] /= static_cast<double>(std::max<std::size_t>(pts.size(), 1));
          }
          return mf;
        };
        const std::vector<double> mf = mean_force(ok);
        std::printf("Order of the mean force (Richardson on the means; negative: the differences grow; successive "
                    "differences");
        for (std::size_t m = 0; m + 1 < nm; ++m) std::printf(" %+.3f", mf[m] - mf[m + 1]);
        std::printf(" mN):");
        std::mt19937 mrng(11);
        for (std::size_t m = 0; m + 2 < nm; ++m) {
          auto order_of = [&](const std::vector<double>& v) {
            return signed_order(h[m], h[m + 1], h[m + 2], v[m] - v[m + 1], v[m + 1] - v[m + 2]);
          };
          std::vector<double> draws;
          int no_order = 0;
          for (int it = 0; it < bootstrap; ++it) {
            std::vector<std::size_t> draw;
            for (std::size_t i = 0; i < ok.size(); ++i) draw.push_back(ok[mrng() % ok.size()]);
            const double o = order_of(mean_force(draw));
            if (std::isfinite(o))
              draws.push_back(o);
            else
              ++no_order;
          }
          std::printf(" %g/%g/%g p = %.2f (bootstrap 2.5 / 50 / 97.5 %%: %.2f / %.2f / %.2f; %d of %d draws "
                      "without one);",
                      h[m], h[m + 1], h[m + 2], order_of(mf), quantile_of(draws, 0.025), quantile_of(draws, 0.5),
                      quantile_of(draws, 0.975), no_order, bootstrap);
        }
        std::printf("\n");
      }
      std::printf("|F_h - F_ref| / F_ref against the surface's change (Pearson r over points and meshes): "
                  "|q_h - q_ref| %.2f, normal angle %.2f\n",
                  pearson(xs_dq, ys), pearson(xs_ang, ys));
    }
    return 0;
  }
  if (line_depths_mm.empty()) line_depths_mm = {0.5, 1.0, 1.5, 2.0, 2.5, 3.0};
  const std::vector<double> depths_mm = line_depths_mm;
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
      const fs::path scene = line_scene(ci);
      neurosim::scene::Model model = neurosim::scene::load_model(scene);
      prepare(model);
      if (brain_only) {
        model.meshes.resize(1);
        model.couplings.clear();
        model.effects.coupling = false;
        model.loads.clear();
        model.prescribed.clear();
      }
      const auto t0 = neurosim::common::Clock::now();
      const ni::SimulationOptions options = make_options();
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
