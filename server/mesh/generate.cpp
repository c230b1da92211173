// Cube and cylinder meshes by CGAL Mesh_3 (polyhedral domain, sharp edges protected).
#include "server/mesh/generate.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Polyhedral_mesh_domain_with_features_3.h>
#include <CGAL/Random.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/make_mesh_3.h>

#include <cmath>
#include <iostream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

namespace neurosim::mesh {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Polyhedron = CGAL::Surface_mesh<K::Point_3>;
using Domain = CGAL::Polyhedral_mesh_domain_with_features_3<K, Polyhedron>;
using Tr = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr, Domain::Corner_index, Domain::Curve_index>;
using Criteria = CGAL::Mesh_criteria_3<Tr>;
namespace params = CGAL::parameters;

constexpr double kTetsPerCell = 10.0;   // per s^3 grid cell over the bounding box

void check_finite(const Vec3& v, const char* what) {
  if (!v.allFinite()) {
    std::ostringstream msg;
    msg << "mesh generator: " << what << " is not finite";
    throw std::invalid_argument(msg.str());
  }
}

Polyhedron box_surface(const Vec3& lo, const Vec3& hi) {
  Polyhedron p;
  Polyhedron::Vertex_index v[8];
  for (int i = 0; i < 8; ++i) {
    v[i] = p.add_vertex(K::Point_3((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                                   (i & 4) ? hi.z() : lo.z()));
  }
  // Each face as two triangles, counter-clockwise seen from outside.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    p.add_face(v[q[0]], v[q[1]], v[q[2]]);
    p.add_face(v[q[0]], v[q[2]], v[q[3]]);
  }
  return p;
}

Polyhedron cylinder_surface(const Vec3& base, const Vec3& axis, double radius, int segments) {
  const Vec3 n = axis.normalized();
  // Orthonormal frame (e1, e2, n) so that the rim runs counter-clockwise around n.
  Vec3 helper = std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  const Vec3 e1 = n.cross(helper).normalized();
  const Vec3 e2 = n.cross(e1);
  Polyhedron p;
  auto add = [&p](const Vec3& x) { return p.add_vertex(K::Point_3(x.x(), x.y(), x.z())); };
  std::vector<Polyhedron::Vertex_index> bottom(segments), top(segments);
  for (int i = 0; i < segments; ++i) {
    const double a = 2.0 * M_PI * i / segments;
    const Vec3 r = radius * (std::cos(a) * e1 + std::sin(a) * e2);
    bottom[i] = add(base + r);
    top[i] = add(base + axis + r);
  }
  const auto cb = add(base);
  const auto ct = add(base + axis);
  for (int i = 0; i < segments; ++i) {
    const int j = (i + 1) % segments;
    p.add_face(cb, bottom[j], bottom[i]);  // bottom cap faces -n
    p.add_face(ct, top[i], top[j]);        // top cap faces +n
    p.add_face(bottom[i], bottom[j], top[j]);
    p.add_face(bottom[i], top[j], top[i]);
  }
  return p;
}

// One Mesh_3 run at cell size s (m): tetrahedra of the complex and the vertices they use.
// optimize: the sliver steps the options ask for (perturbation, exudation), and the TetMesh
// built; without them only the vertex count, which is the same, faster (what the cell-size
// search needs; unoptimized meshes may hold flat tetrahedra that TetMesh refuses).
struct Mesh3Run {
  TetMesh mesh;
  int vertices{0};
  bool time_limited{false};  // a sliver step stopped at optimization_time_limit_s
};
Mesh3Run run_mesh3(const Polyhedron& surface, double s, const MeshingOptions& options,
                   const std::string& what, bool optimize) {
  if (!(options.optimization_time_limit_s >= 0.0) ||
      !std::isfinite(options.optimization_time_limit_s))
    throw std::invalid_argument(what + ": optimization_time_limit_s must be finite and >= 0 s");
  // Mesh_3 draws from CGAL's default random generator: seed it for reproducible meshes.
  CGAL::get_default_random() = CGAL::Random(options.seed);
  Domain domain(surface);
  domain.detect_features();  // 60 degree default: box edges, cylinder rims
  Criteria criteria(params::edge_size = s, params::facet_angle = 25.0, params::facet_size = s,
                    params::facet_distance = 0.05 * s,
                    params::cell_radius_edge_ratio = options.cell_radius_edge_ratio,
                    params::cell_size = s);
  C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(domain, criteria, params::no_perturb(), params::no_exude());
  // Both stop when no sliver can be improved; the time limit is a safety bound far above what
  // the bundled sizes need, so for them the mesh does not depend on how loaded the machine is (a
  // tight wall-clock limit made it vary).
  const double limit_s = options.optimization_time_limit_s;
  bool time_limited = false;
  if (optimize && options.perturb_slivers) {
    if (!(options.perturb_sliver_bound_deg > 0.0 && options.perturb_sliver_bound_deg < 60.0)) {
      throw std::invalid_argument(what + ": perturb_sliver_bound_deg must be in (0, 60) degrees");
    }
    time_limited |= CGAL::perturb_mesh_3(c3t3, domain, params::time_limit = limit_s,
                                         params::sliver_bound = options.perturb_sliver_bound_deg) ==
                    CGAL::TIME_LIMIT_REACHED;
  }
  if (optimize && options.exude_slivers) {
    time_limited |=
        CGAL::exude_mesh_3(c3t3, params::time_limit = limit_s) == CGAL::TIME_LIMIT_REACHED;
  }
  if (!optimize) {
    std::unordered_map<Tr::Vertex_handle, int> seen;
    for (auto c = c3t3.cells_in_complex_begin(); c != c3t3.cells_in_complex_end(); ++c)
      for (int k = 0; k < 4; ++k) seen.emplace(c->vertex(k), 0);
    return {TetMesh{}, static_cast<int>(seen.size()), false};
  }
  std::unordered_map<Tr::Vertex_handle, int> index;
  std::vector<Vec3> vertices;
  std::vector<Tet> tets;
  tets.reserve(c3t3.number_of_cells_in_complex());
  for (auto c = c3t3.cells_in_complex_begin(); c != c3t3.cells_in_complex_end(); ++c) {
    Tet t{};
    for (int k = 0; k < 4; ++k) {
      const auto vh = c->vertex(k);
      auto [it, inserted] = index.emplace(vh, static_cast<int>(vertices.size()));
      if (inserted) {
        const auto& p = vh->point();
        vertices.emplace_back(CGAL::to_double(p.x()), CGAL::to_double(p.y()),
                              CGAL::to_double(p.z()));
      }
      t[k] = it->second;
    }
    tets.push_back(t);
  }
  BuildOptions build;
  build.source = what;
  Mesh3Run out;
  out.mesh = TetMesh::build(std::move(vertices), std::move(tets), build);
  out.vertices = static_cast<int>(out.mesh.num_vertices());
  out.time_limited = time_limited;
  if (time_limited) {
    std::cerr << "warning: " << what << ": sliver optimization stopped at its time limit of "
              << limit_s << " s (optimization_time_limit_s); the mesh may vary from run to run\n";
  }
  return out;
}

// Refuses a request whose expected size is above options.max_tetrahedra, naming the option.
void check_expected_size(const Vec3& extent_m, const MeshingOptions& options,
                         const std::string& what) {
  const double expected = expected_tetrahedra(extent_m, options);
  if (expected <= options.max_tetrahedra) return;
  std::ostringstream msg;
  msg.precision(3);
  if (options.target_vertices > 0) {
    msg << "target_vertices: " << options.target_vertices << " gives about " << expected;
  } else {
    msg << "cell_size_m: " << options.cell_size_m << " m in a " << extent_m.x() << " x "
        << extent_m.y() << " x " << extent_m.z() << " m " << what << " gives about " << expected;
  }
  msg << " tetrahedra, above the limit of " << options.max_tetrahedra
      << " (max_tetrahedra); give fewer vertices or a larger cell size";
  throw std::invalid_argument(msg.str());
}

// Search the cell size whose mesh has the vertex count closest to target.
GeneratedMesh mesh_to_target(const Polyhedron& surface, double volume_m3, const Vec3& extent_m,
                             const MeshingOptions& options, const std::string& what) {
  if (options.target_vertices < 0) {
    throw std::invalid_argument(what + ": target_vertices must be >= 0");
  }
  if (options.target_vertices == 0 &&
      (!(options.cell_size_m > 0.0) || !std::isfinite(options.cell_size_m))) {
    throw std::invalid_argument(what + ": give target_vertices > 0 or a cell size > 0 m");
  }
  check_expected_size(extent_m, options, what);
  if (options.target_vertices == 0) {
    Mesh3Run run = run_mesh3(surface, options.cell_size_m, options, what, true);
    return {std::move(run.mesh), options.cell_size_m, 1, run.time_limited};
  }
  if (options.target_vertices < 8) {
    throw std::invalid_argument(what + ": target_vertices must be at least 8");
  }
  const double target = options.target_vertices;
  // The search counts vertices only (no sliver steps, no TetMesh); the chosen size is meshed
  // again at the end. Start from about (volume / tets)^(1/3) with ~5 tets per vertex, then secant
  // steps on log(vertices) against log(size) (slope about -3 for volume meshes, less when small).
  double s = std::cbrt(volume_m3 / (0.6 * target));
  double best_err = std::numeric_limits<double>::infinity();
  GeneratedMesh best{TetMesh{}, 0.0, 0, false};
  // The search never tries a size whose grid estimate is above the limit either.
  MeshingOptions at_size = options;
  at_size.target_vertices = 0;
  double prev_log_s = 0.0, prev_log_n = 0.0;
  bool have_prev = false;
  constexpr int kMaxAttempts = 12;
  int attempts = 0;
  for (; attempts < kMaxAttempts; ++attempts) {
    at_size.cell_size_m = s;
    check_expected_size(extent_m, at_size, what);
    const double n = run_mesh3(surface, s, options, what, false).vertices;
    const double err = std::abs(n - target) / target;
    if (err < best_err) {
      best_err = err;
      best.cell_size_m = s;
    }
    if (err < 0.01) break;
    double slope = -3.0;
    const double log_s = std::log(s), log_n = std::log(n);
    if (have_prev && std::abs(log_s - prev_log_s) > 1e-9) {
      slope = (log_n - prev_log_n) / (log_s - prev_log_s);
      // Vertex counts are noisy step functions of size: keep the slope plausible.
      if (!(slope < -0.5) || slope < -6.0) slope = -3.0;
    }
    prev_log_s = log_s;
    prev_log_n = log_n;
    have_prev = true;
    double step = (std::log(target) - log_n) / slope;
    step = std::clamp(step, -0.7, 0.7);
    s *= std::exp(step);
  }
  best.attempts = attempts;
  // The chosen size again, with the sliver steps and the mesh built (same seed and size: same
  // vertices).
  Mesh3Run run = run_mesh3(surface, best.cell_size_m, options, what, true);
  best.mesh = std::move(run.mesh);
  best.optimization_time_limited = run.time_limited;
  return best;
}

}  // namespace

double expected_tetrahedra(const Vec3& extent_m, const MeshingOptions& options) {
  if (options.target_vertices > 0) return kTetsPerVertex * options.target_vertices;
  const double s = options.cell_size_m;
  double cells = kTetsPerCell;
  for (int a = 0; a < 3; ++a) cells *= extent_m[a] / s + 1.0;
  return cells;  // inf or NaN for a zero or non-finite size: never below a limit
}

GeneratedMesh generate_box(const Vec3& lo_m, const Vec3& hi_m, const MeshingOptions& options) {
  check_finite(lo_m, "box lower corner");
  check_finite(hi_m, "box upper corner");
  const Vec3 size = hi_m - lo_m;
  if (!(size.minCoeff() > 0.0)) {
    throw std::invalid_argument("mesh generator: box must have hi > lo on every axis (m)");
  }
  return mesh_to_target(box_surface(lo_m, hi_m), size.prod(), size, options, "generated box");
}

GeneratedMesh generate_cylinder(const Vec3& base_center_m, const Vec3& axis_m, double radius_m,
                                const MeshingOptions& options) {
  check_finite(base_center_m, "cylinder base centre");
  check_finite(axis_m, "cylinder axis");
  if (!(radius_m > 0.0) || !std::isfinite(radius_m)) {
    throw std::invalid_argument("mesh generator: cylinder radius must be > 0 m");
  }
  const double height = axis_m.norm();
  if (!(height > 0.0)) {
    throw std::invalid_argument("mesh generator: cylinder axis must have non-zero length (m)");
  }
  int segments = options.circle_segments;
  if (segments == 0) {
    // About one rim segment per expected cell size, at least 12 (the rim is a protected
    // feature, so its polygon is what the mesh follows).
    const double volume = M_PI * radius_m * radius_m * height;
    const double s = options.target_vertices > 0
                         ? std::cbrt(volume / (0.6 * options.target_vertices))
                         : options.cell_size_m;
    // Clamped as a double: a tiny or zero size gives a count no int holds (or NaN).
    const double wanted = std::ceil(2.0 * M_PI * radius_m / (0.5 * s));
    segments = wanted >= 12.0 ? static_cast<int>(std::min(wanted, 96.0)) : 12;
  }
  if (segments < 3 || segments > 4096)
    throw std::invalid_argument("mesh generator: circle_segments must be in [3, 4096]");
  return mesh_to_target(cylinder_surface(base_center_m, axis_m, radius_m, segments),
                        M_PI * radius_m * radius_m * height,
                        Vec3(2.0 * radius_m, 2.0 * radius_m, height), options,
                        "generated cylinder");
}

}  // namespace neurosim::mesh
