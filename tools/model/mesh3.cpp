// CGAL Mesh_3 for the patient model: the brain from the labeled MRI mask, the artery from an
// implicit tube. Both use Labeled_mesh_domain_3, so make_mesh_3 is instantiated once.
#include "tools/model/mesh3.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/IO/read_vtk_image_data.h>
#include <CGAL/Image_3.h>
#include <CGAL/Labeled_mesh_domain_3.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Random.h>
#include <CGAL/make_mesh_3.h>

#include <vtkImageData.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <utility>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace neurosim::model {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Domain = CGAL::Labeled_mesh_domain_3<K>;
using Tr = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr>;
using Criteria = CGAL::Mesh_criteria_3<Tr>;
namespace params = CGAL::parameters;

void check_size(double s, const char* what) {
  if (!(s > 0.0) || !std::isfinite(s)) {
    throw std::invalid_argument(std::string("mesh3: ") + what + " must be finite and > 0 mm");
  }
}

Criteria make_criteria(double s, double facet_distance) {
  return Criteria(params::facet_angle = 30.0, params::facet_size = s,
                  params::facet_distance = facet_distance, params::cell_radius_edge_ratio = 3.0,
                  params::cell_size = s);
}

// The labeled image's criteria with a LocalRefinement: facet and cell size the refinement's field,
// the surface distance a quarter of it (as the uniform mesh's).
struct SizeField {
  LocalRefinement refine;
  double far_mm{0.0};
  double scale{1.0};
  double operator()(const K::Point_3& p, const int, const Domain::Index&) const {
    return scale * refine.size_at(Vec3(p.x(), p.y(), p.z()), far_mm);
  }
};

// Refinement, sliver perturbation, then sliver exudation. Without an explicit time limit
// make_mesh_3 bounds both by the refinement's wall time, which makes the mesh depend on machine
// load; time_limit = 0 means no limit (both stop when they cannot improve any more).
Mesh3Output run(const Domain& domain, const Criteria& criteria) {
  C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(
      domain, criteria, params::perturb(params::time_limit = 0, params::sliver_bound = 12),
      params::exude(params::time_limit = 0, params::sliver_bound = 0));
  Mesh3Output out;
  out.vertices_in_complex = c3t3.triangulation().number_of_vertices();
  out.cells = c3t3.number_of_cells_in_complex();
  std::ostringstream os;
  os.precision(10);
  c3t3.output_to_medit(os);
  out.medit = os.str();
  return out;
}

}  // namespace

double LocalRefinement::size_at(const Vec3& p_mm, double far_mm) const {
  if (!on()) return far_mm;
  const double beyond = std::max(0.0, (p_mm - centre_mm).norm() - radius_mm);
  return std::min(far_mm, cell_size_mm + grading * beyond);
}

void LocalRefinement::check(double far_mm) const {
  if (!on()) return;
  auto bad = [](const std::string& what) { throw std::invalid_argument("local refinement: " + what); };
  if (!centre_mm.allFinite()) bad("the centre (--refine-at) is not finite");
  if (!(cell_size_mm > 0.0 && cell_size_mm < far_mm) || !std::isfinite(cell_size_mm))
    bad("the cell size (--refine-cell-size) must be finite and below the mesh's cell size " +
        std::to_string(far_mm) + " mm");
  if (!(radius_mm >= 0.0) || !std::isfinite(radius_mm)) bad("the radius (--refine-radius) must be finite and >= 0 mm");
  if (!(grading > 0.0 && grading <= 1.0)) bad("the grading (--refine-grading) must be in (0, 1] mm per mm");
}

Mesh3Output mesh_labeled_image(vtkImageData* labels, double cell_size_mm, std::uint32_t seed,
                               const LocalRefinement& refine) {
  check_size(cell_size_mm, "brain cell size");
  refine.check(cell_size_mm);
  if (labels == nullptr || labels->GetScalarType() != VTK_UNSIGNED_CHAR) {
    throw std::invalid_argument("mesh3: label image must be unsigned char");
  }
  CGAL::get_default_random() = CGAL::Random(seed);
  CGAL::Random rng(seed);
  const CGAL::Image_3 image = CGAL::IO::read_vtk_image_data(labels);
  if (!image.is_valid()) throw std::runtime_error("mesh3: CGAL could not take the label image");
  const Domain domain = Domain::create_labeled_image_mesh_domain(
      image, params::relative_error_bound = 1e-6, params::p_rng = &rng);
  // Surface within a quarter cell of the mask boundary (a voxel is 1 mm).
  if (!refine.on()) return run(domain, make_criteria(cell_size_mm, 0.25 * cell_size_mm));
  const SizeField size{refine, cell_size_mm, 1.0}, distance{refine, cell_size_mm, 0.25};
  return run(domain, Criteria(params::facet_angle = 30.0, params::facet_size = size,
                              params::facet_distance = distance,
                              params::cell_radius_edge_ratio = 3.0, params::cell_size = size));
}

Mesh3Output mesh_tube(const std::vector<Vec3>& centreline_mm, double radius_mm, double cell_size_mm,
                      std::uint32_t seed) {
  check_size(cell_size_mm, "artery cell size");
  check_size(radius_mm, "artery radius");
  if (centreline_mm.size() < 2) throw std::invalid_argument("mesh3: tube needs >= 2 points");
  Vec3 lo = centreline_mm.front(), hi = lo;
  for (const auto& p : centreline_mm) {
    if (!p.allFinite()) throw std::invalid_argument("mesh3: tube centreline point not finite");
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  for (std::size_t i = 0; i + 1 < centreline_mm.size(); ++i) {
    if (!((centreline_mm[i + 1] - centreline_mm[i]).norm() > 0.0)) {
      throw std::invalid_argument("mesh3: tube centreline points " + std::to_string(i) + " and " +
                                  std::to_string(i + 1) + " coincide");
    }
  }
  CGAL::get_default_random() = CGAL::Random(seed);
  CGAL::Random rng(seed);
  const double r2 = radius_mm * radius_mm;
  const Vec3 box_lo = lo.array() - radius_mm, box_hi = hi.array() + radius_mm;
  // Segment midpoints and half lengths: |p - mid| - half bounds the distance from below.
  std::vector<Vec3> mid;
  std::vector<double> half;
  for (std::size_t i = 0; i + 1 < centreline_mm.size(); ++i) {
    mid.push_back(0.5 * (centreline_mm[i] + centreline_mm[i + 1]));
    half.push_back(0.5 * (centreline_mm[i + 1] - centreline_mm[i]).norm());
  }
  // Negative inside: the point is within radius of some segment of the centreline.
  std::function<double(const K::Point_3&)> inside = [&](const K::Point_3& q) {
    const Vec3 p(q.x(), q.y(), q.z());
    if ((p.array() < box_lo.array()).any() || (p.array() > box_hi.array()).any()) return 1.0;
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < mid.size(); ++i) {
      const double bound = (p - mid[i]).norm() - half[i];
      if (bound > 0.0 && bound * bound >= best) continue;
      const Vec3& a = centreline_mm[i];
      const Vec3 ab = centreline_mm[i + 1] - a;
      const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
      best = std::min(best, (a + t * ab - p).squaredNorm());
      if (best < r2) break;
    }
    return best - r2;
  };
  const Vec3 c = 0.5 * (lo + hi);
  const double radius = 0.5 * (hi - lo).norm() + radius_mm + 2.0 * cell_size_mm;
  const Domain domain = Domain::create_implicit_mesh_domain(
      inside, K::Sphere_3(K::Point_3(c.x(), c.y(), c.z()), radius * radius),
      params::relative_error_bound = 1e-6, params::p_rng = &rng);
  // A facet of size h on the tube deviates about h^2 / (8 r) from it: the size criterion leads.
  return run(domain, make_criteria(cell_size_mm, 0.1 * cell_size_mm));
}

SurfaceOutput mesh_gray_surface(vtkImageData* image, const GraySurfaceOptions& o) {
  check_size(o.facet_size_mm, "surface facet size");
  check_size(o.facet_distance_mm, "surface facet distance");
  if (image == nullptr || image->GetScalarType() != VTK_FLOAT) {
    throw std::invalid_argument("mesh3: gray image must be float");
  }
  CGAL::get_default_random() = CGAL::Random(o.seed);
  CGAL::Random rng(o.seed);
  const CGAL::Image_3 cgal_image = CGAL::IO::read_vtk_image_data(image);
  if (!cgal_image.is_valid()) throw std::runtime_error("mesh3: CGAL could not take the gray image");
  const Domain domain = Domain::create_gray_image_mesh_domain(
      cgal_image, params::iso_value = static_cast<float>(o.iso_value),
      params::value_outside = 0.0f, params::relative_error_bound = 1e-6, params::p_rng = &rng);
  // Surface criteria only: the volume is never used, so cells are not refined.
  const Criteria criteria(params::facet_angle = o.facet_angle_deg,
                          params::facet_size = o.facet_size_mm,
                          params::facet_distance = o.facet_distance_mm);
  const C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(domain, criteria, params::no_perturb(),
                                            params::no_exude(), params::manifold());
  // Boundary facets, each oriented out of the cell that lies in the subdomain.
  SurfaceOutput out;
  std::map<const void*, int> index;  // the order of first use, deterministic
  auto vertex = [&](Tr::Vertex_handle v) {
    auto [it, inserted] = index.emplace(&*v, static_cast<int>(out.vertices.size()));
    if (inserted) {
      const auto& p = v->point();
      out.vertices.emplace_back(CGAL::to_double(p.x()), CGAL::to_double(p.y()),
                                CGAL::to_double(p.z()));
    }
    return it->second;
  };
  for (auto f = c3t3.facets_in_complex_begin(); f != c3t3.facets_in_complex_end(); ++f) {
    auto cell = f->first;
    int i = f->second;
    if (!c3t3.is_in_complex(cell)) {  // use the side inside the subdomain
      const auto mirror = c3t3.triangulation().mirror_facet(*f);
      cell = mirror.first;
      i = mirror.second;
    }
    mesh::Tri t{vertex(cell->vertex((i + 1) & 3)), vertex(cell->vertex((i + 2) & 3)),
                vertex(cell->vertex((i + 3) & 3))};
    // Outward: the normal points away from the cell's fourth vertex (inside the subdomain).
    const Vec3 &a = out.vertices[t[0]], &b = out.vertices[t[1]], &c = out.vertices[t[2]];
    const auto& q = cell->vertex(i)->point();
    const Vec3 inner(CGAL::to_double(q.x()), CGAL::to_double(q.y()), CGAL::to_double(q.z()));
    if ((b - a).cross(c - a).dot(inner - a) > 0.0) std::swap(t[1], t[2]);
    out.triangles.push_back(t);
  }
  return out;
}

}  // namespace neurosim::model
