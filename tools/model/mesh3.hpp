// CGAL Mesh_3 runs (the only CGAL translation unit of the tool): a labeled image and a tube.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

class vtkImageData;

namespace neurosim::model {

using mesh::Vec3;

struct Mesh3Output {
  std::string medit;  // c3t3.output_to_medit, coordinates in the input's unit (mm)
  std::size_t vertices_in_complex{0};
  std::size_t cells{0};
};

// Finer cells around one point (a press, a contact patch): the mesh's cell and facet size is
// cell_size_mm within radius_mm of centre_mm, growing by `grading` mm per mm beyond it up to the
// mesh's own size (a Lipschitz sizing field, as Mesh_3's refinement wants); the surface distance
// bound scales with it (a quarter of the local size). Off when cell_size_mm is 0. Units mm, in
// the image's coordinates (the mesh files' coordinates).
struct LocalRefinement {
  Vec3 centre_mm{Vec3::Zero()};
  double cell_size_mm{0.0};
  double radius_mm{2.5};
  double grading{0.25};
  bool on() const { return cell_size_mm != 0.0; }
  // The local size at p, unit mm, for a mesh whose size is far_mm elsewhere.
  double size_at(const Vec3& p_mm, double far_mm) const;
  // Throws std::invalid_argument naming the option when a value is not finite or out of range
  // (cell size in (0, far_mm), radius >= 0, grading in (0, 1]).
  void check(double far_mm) const;
};

// Mesh_3 on a labeled image (0 = outside), cell/facet size in mm, sliver exudation on.
// CGAL's random generator is seeded with `seed` first, so the result is reproducible.
Mesh3Output mesh_labeled_image(vtkImageData* labels, double cell_size_mm, std::uint32_t seed,
                               const LocalRefinement& refine = {});

// Solid tube of radius_mm around the polyline `centreline_mm` (rounded ends), implicit domain.
Mesh3Output mesh_tube(const std::vector<Vec3>& centreline_mm, double radius_mm, double cell_size_mm,
                      std::uint32_t seed);

// A closed triangle surface (the boundary of a meshed domain), outward oriented.
struct SurfaceOutput {
  std::vector<Vec3> vertices;  // in the input's unit (mm)
  std::vector<mesh::Tri> triangles;
};

struct GraySurfaceOptions {
  double iso_value{0.5};          // the surface is where the image equals it (inside: above)
  double facet_size_mm{10.0};     // Delaunay ball radius bound of a surface triangle, unit mm
  double facet_distance_mm{1.5};  // triangle centre to the iso-surface, unit mm
  double facet_angle_deg{30.0};   // lower bound of a triangle's smallest angle
  std::uint32_t seed{1};
};

// The iso-surface of a scalar (float) image by CGAL Mesh_3 (gray image domain, manifold facet
// topology, surface criteria only, no sliver steps): the facets of the complex between the
// subdomain and the outside, oriented out of the subdomain. Reproducible for a seed.
SurfaceOutput mesh_gray_surface(vtkImageData* image, const GraySurfaceOptions& options);

}  // namespace neurosim::model
