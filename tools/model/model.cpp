// The brain/artery patient model: MRI mask -> meshes -> checks -> scene file.
#include "tools/model/model.hpp"

#include "common/clock.hpp"
#include "scene.pb.h"
#include "server/fusion/inclusion.hpp"
#include "server/fusion/triangle_surface.hpp"
#include "server/mesh/io.hpp"
#include "server/mesh/tri_surface.hpp"
#include "server/scene/compile.hpp"
#include "tools/model/islands.hpp"
#include "tools/model/mesh3.hpp"
#include "tools/model/mri_mask.hpp"

#include <google/protobuf/text_format.h>

#include <Eigen/Dense>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

namespace neurosim::model {
namespace {

using common::Clock;
using common::seconds_since;

constexpr double kMmToM = 1e-3;

void check_positive(double v, const std::string& what) {
  if (!(v > 0.0) || !std::isfinite(v)) {
    throw std::invalid_argument("neurosim-model: " + what + " must be finite and > 0");
  }
}

// Uniform Catmull-Rom spline through the control points, sampled every <= step_mm.
std::vector<Vec3> sample_spline(const std::vector<Vec3>& p, double step_mm) {
  const int n = static_cast<int>(p.size());
  std::vector<Vec3> out{p.front()};
  for (int i = 0; i + 1 < n; ++i) {
    const Vec3& p0 = p[std::max(i - 1, 0)];
    const Vec3& p1 = p[i];
    const Vec3& p2 = p[i + 1];
    const Vec3& p3 = p[std::min(i + 2, n - 1)];
    const int steps = std::max(1, static_cast<int>(std::ceil((p2 - p1).norm() / step_mm)));
    for (int s = 1; s <= steps; ++s) {
      const double t = static_cast<double>(s) / steps, t2 = t * t, t3 = t2 * t;
      out.push_back(0.5 *
                    ((2.0 * p1) + (-p0 + p2) * t + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2 +
                     (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t3));
    }
  }
  return out;
}

std::string fmt(const Vec3& v, int precision = 1) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(precision) << "(" << v.x() << ", " << v.y() << ", " << v.z()
     << ")";
  return os.str();
}

// Writes the Medit text, reads it back as the server will (mm -> m), checks it.
mesh::TetMesh write_and_load(const std::filesystem::path& file, const Mesh3Output& meshed,
                             MeshSummary& summary) {
  {
    std::ofstream out(file);
    out << meshed.medit;
    if (!out) throw std::runtime_error(file.string() + ": cannot write");
  }
  mesh::MeshData data = mesh::read_medit(file.string(), kMmToM);
  summary.file = file;
  summary.file_vertices = static_cast<int>(data.vertices_m.size());
  // Judge the file as written, before TetMesh::build could reorient anything.
  summary.quality = mesh::quality(data.vertices_m, data.tets);
  mesh::BuildOptions build;
  build.source = file.string();
  mesh::TetMesh m = mesh::TetMesh::build(std::move(data.vertices_m), std::move(data.tets), build);
  summary.vertices = static_cast<int>(m.num_vertices());
  summary.tets = static_cast<int>(m.num_tets());
  if (summary.quality.inverted > 0 || summary.quality.zero_volume > 0) {
    throw std::runtime_error(file.string() + ": mesher produced " +
                             std::to_string(summary.quality.inverted) + " inverted and " +
                             std::to_string(summary.quality.zero_volume) + " flat tetrahedra");
  }
  return m;
}

// Skull base: a plane z = a + b*y fitted (least squares) to the lowest brain vertex of each
// 10 mm slab along y (anterior fossa high, posterior fossa low), raised by the margin.
void skull_base_plane(const mesh::TetMesh& brain, double margin_m, Vec3& point_m, Vec3& normal) {
  constexpr double kSlabM = 0.010;
  std::map<long, double> lowest;
  for (int v : brain.surface_vertices()) {
    const Vec3& x = brain.vertices()[v];
    const long slab = static_cast<long>(std::floor(x.y() / kSlabM));
    auto [it, inserted] = lowest.emplace(slab, x.z());
    if (!inserted) it->second = std::min(it->second, x.z());
  }
  if (lowest.size() < 2) throw std::runtime_error("brain mesh too small to fit a skull base");
  Eigen::MatrixXd A(lowest.size(), 2);
  Eigen::VectorXd z(lowest.size());
  int row = 0;
  for (const auto& [slab, zmin] : lowest) {
    A(row, 0) = 1.0;
    A(row, 1) = (slab + 0.5) * kSlabM;
    z(row) = zmin;
    ++row;
  }
  const Eigen::Vector2d ab = A.colPivHouseholderQr().solve(z);
  Vec3 lo, hi;
  brain.bounds(lo, hi);
  const double yc = 0.5 * (lo.y() + hi.y());
  point_m = Vec3(0.5 * (lo.x() + hi.x()), yc, ab(0) + ab(1) * yc + margin_m);
  normal = Vec3(0.0, -ab(1), 1.0).normalized();  // fixed side: dot(x - point, normal) <= 0
}

// Rounded to `quantum` so that the scene file stays readable (1e-6 m: a micrometre).
// The tool's footprint for the static load case: surface nodes of the brain within a box
// around the most lateral surface point near `target_m` (y, z within +-half_m).
void footprint_box(const mesh::TetMesh& brain, const Vec3& target_m, double half_m, double depth_m,
                   Vec3& lo, Vec3& hi) {
  double xmax = -std::numeric_limits<double>::infinity();
  for (int v : brain.surface_vertices()) {
    const Vec3& x = brain.vertices()[v];
    if (std::abs(x.y() - target_m.y()) <= half_m && std::abs(x.z() - target_m.z()) <= half_m) {
      xmax = std::max(xmax, x.x());
    }
  }
  if (!std::isfinite(xmax)) throw std::runtime_error("no brain surface near the load point");
  lo = Vec3(xmax - depth_m, target_m.y() - half_m, target_m.z() - half_m);
  hi = Vec3(xmax + 0.05, target_m.y() + half_m, target_m.z() + half_m);
}

void set_vec(scene::Vec3* out, const Vec3& v, double quantum) {
  auto q = [quantum](double x) { return std::round(x / quantum) * quantum; };
  out->set_x(q(v.x()));
  out->set_y(q(v.y()));
  out->set_z(q(v.z()));
}

void set_material(scene::Material* m, MaterialSet set, bool artery) {
  if (set == MaterialSet::Paper) {
    m->set_name("paper");
    m->set_youngs_modulus_pa(1.0e6);
    m->set_poisson_ratio(0.4);
    m->set_source("Mesh fusion paper, section 3: E = 1.0 MPa, nu = 0.4 applied to the model");
  } else if (!artery) {
    m->set_name("brain_literature");
    m->set_youngs_modulus_pa(3.0e3);
    m->set_poisson_ratio(0.49);
    m->set_element("smoothed-tet");
    m->set_source(
        "Brain tissue, literature: E of order 1-3 kPa (Miller et al. 2000, J Biomech 33:1369, "
        "in vivo indentation; Budday et al. 2015, J Mech Behav Biomed Mater 46:318, ~1 kPa); "
        "nu = 0.49, nearly incompressible (the value of the patient-specific brain models of "
        "Wittek et al. 2007, J Biomech 40:919, as quoted, not re-read here), on smoothed-tet, "
        "which does not lock there (linear tetrahedra do)");
  } else {
    m->set_name("artery_literature");
    m->set_youngs_modulus_pa(1.0e6);
    m->set_poisson_ratio(0.45);
    m->set_source(
        "Cerebral artery wall: E of order 1 MPa at small strain (e.g. Monson et al. 2003, "
        "J Biomech Eng 125:288; stiffer at large strain); nu = 0.45");
  }
}

// The cerebellum's own material. Values: the cerebrum's (unsure of a cerebellum-specific value,
// so the same one is used and the source says so).
void set_cerebellum_material(scene::Material* m, MaterialSet set) {
  set_material(m, set, false);
  m->set_name(set == MaterialSet::Paper ? "paper_cerebellum" : "cerebellum_literature");
  m->set_source(
      m->source() +
      ". Cerebellum: the cerebrum's values, not a cerebellum-specific measurement: in vivo "
      "elastography reports regional differences of the cerebellum (e.g. Zhang et al. 2011, J "
      "Biomech 44:1909) but no value of it was checked for this model, so none is invented");
}

// Skull summary: the surface written, read back as the server will (mm -> m), checked closed.
void write_skull(const std::filesystem::path& file, const SurfaceOutput& surface,
                 SkullSummary& summary) {
  mesh::MeshData data;
  data.vertices_m = surface.vertices;  // written in mm: unit 1
  data.triangles = surface.triangles;
  data.triangle_labels.assign(surface.triangles.size(), 1);
  mesh::write_medit(file.string(), data, 1.0);
  const mesh::MeshData back = mesh::read_medit_surface(file.string(), kMmToM);
  mesh::require_closed_outward(back.vertices_m, back.triangles, file.string());
  summary.file = file;
  summary.vertices = static_cast<int>(back.vertices_m.size());
  summary.triangles = static_cast<int>(back.triangles.size());
  summary.enclosed_volume_ml = mesh::check_closed(back.vertices_m, back.triangles).volume_m3 * 1e6;
}

// The refinement as neurosim-model's flags and in words (empty when off), for the scene's text.
std::string refinement_flags(const LocalRefinement& r) {
  if (!r.on()) return "";
  std::ostringstream s;
  s << " --refine-at " << r.centre_mm.x() << " " << r.centre_mm.y() << " " << r.centre_mm.z()
    << " --refine-cell-size " << r.cell_size_mm << " --refine-radius " << r.radius_mm
    << " --refine-grading " << r.grading;
  return s.str();
}
std::string refinement_words(const LocalRefinement& r) {
  if (!r.on()) return "";
  std::ostringstream s;
  s << " (" << r.cell_size_mm << " mm within " << r.radius_mm << " mm of image point "
    << fmt(r.centre_mm) << " mm, growing " << r.grading << " mm per mm beyond)";
  return s.str();
}

}  // namespace

OpeningMni default_suboccipital_opening() {
  return {Vec3(28.0, -89.0, -36.0), Vec3(0.25, -0.95, -0.2).normalized(), 15.0, 25.0,
          "suboccipital craniotomy over the right cerebellar hemisphere (the paper's Figure 16: "
          "cerebellum seen through a hole in the skull). Centre: the posterior surface of the "
          "right cerebellar hemisphere in the AAL atlas on Colin27 (mricron-data aal.nii.gz, "
          "labels 92-108 Cerebelum_*_R: centroid x = 28, z = -36 MNI mm; the most posterior "
          "labelled voxel at x 25-30, z -40..-30 is at y = -89); axis: the surface's outward "
          "normal estimated from the same voxels (posterior, slightly lateral and inferior); "
          "radius 15 mm, a typical small retrosigmoid/suboccipital keyhole"};
}

std::vector<Vec3> default_mca_course_mni_mm() {
  // Checked against ch2bet (T1 >= 20): every point >= 9 mm inside the mask.
  return {{18, 2, -16},  // M1 origin near the carotid terminus
          {28, 3, -13},  // M1, lateral along the sphenoid ridge
          {37, 4, -8},   // genu at the limen insulae
          {40, 0, -1},   // M2 over the insula (Sylvian fissure), posterosuperior
          {41, -9, 6},  {42, -19, 12}, {45, -28, 19},  // towards the posterior end of the fissure
          {51, -36, 26}};
}

ModelResult build_model(const ModelOptions& o) {
  const auto t_start = Clock::now();
  check_positive(o.brain_cell_size_mm, "--cell-size (mm)");
  o.brain_refinement.check(o.brain_cell_size_mm);
  check_positive(o.artery_cell_size_mm, "artery cell size (mm)");
  check_positive(o.artery_radius_mm, "artery radius (mm)");
  check_positive(o.fixed_margin_mm, "fixed margin (mm)");
  if (o.name.empty() || o.name.find('/') != std::string::npos) {
    throw std::invalid_argument("neurosim-model: model name must be a plain file name");
  }
  ModelResult r;

  // 1. MRI -> brain mask.
  auto t0 = Clock::now();
  const BrainMask mask = load_brain_mask(o.mri_path, o.mask_threshold);
  r.mask_seconds = seconds_since(t0);
  r.brain_volume_ml =
      mask.voxels_inside * mask.spacing_mm[0] * mask.spacing_mm[1] * mask.spacing_mm[2] * 1e-3;

  // 2. Artery centreline in image coordinates, checked against the mask.
  std::vector<Vec3> control =
      o.artery_course_world_mm.empty() ? default_mca_course_mni_mm() : o.artery_course_world_mm;
  if (control.size() < 2) throw std::invalid_argument("neurosim-model: artery needs >= 2 points");
  for (auto& p : control) {
    if (!p.allFinite()) throw std::invalid_argument("neurosim-model: artery point not finite");
    p = world_to_image(mask, p);
  }
  const std::vector<Vec3> centreline =
      sample_spline(control, 1.0);  // chord error ~ (1 mm)^2 / (8 x 10 mm radius of curvature)
  r.artery_min_depth_mm = std::numeric_limits<double>::infinity();
  const double needed = o.artery_radius_mm + 2.0;  // the tube plus the mesh's surface error
  for (std::size_t i = 0; i < centreline.size(); ++i) {
    if (i > 0) r.artery_length_mm += (centreline[i] - centreline[i - 1]).norm();
    const double depth = depth_in_mask_mm(mask, centreline[i], needed + 10.0);
    if (depth < needed) {
      const Eigen::Vector4d w = mask.image_to_world * centreline[i].homogeneous();
      throw std::runtime_error(o.mri_path + ": artery centreline at world " + fmt(w.head<3>()) +
                               " mm is only " + std::to_string(depth) +
                               " mm inside the brain mask (needs " + std::to_string(needed) +
                               " mm)");
    }
    r.artery_min_depth_mm = std::min(r.artery_min_depth_mm, depth);
  }

  // 3. Meshes (image mm in the files; the scene says file_unit_m 0.001).
  const std::filesystem::path mesh_dir = o.out_dir / o.name;
  std::filesystem::create_directories(mesh_dir);
  t0 = Clock::now();
  const Mesh3Output brain3 = mesh_labeled_image(mask.labels, o.brain_cell_size_mm, o.seed, o.brain_refinement);
  r.brain.seconds = seconds_since(t0);
  mesh::TetMesh brain = write_and_load(mesh_dir / "brain.mesh", brain3, r.brain);
  if (o.brain_refinement.on()) {
    // A point away from the brain refines nothing: refused rather than a mesh that looks refined.
    double nearest_mm = std::numeric_limits<double>::infinity();
    for (const Vec3& x : brain.vertices())
      nearest_mm = std::min(nearest_mm, (x / kMmToM - o.brain_refinement.centre_mm).norm());
    if (nearest_mm > o.brain_refinement.radius_mm + o.brain_cell_size_mm) {
      throw std::invalid_argument(
          "--refine-at " + fmt(o.brain_refinement.centre_mm) + " (image mm) lies " +
          std::to_string(nearest_mm) + " mm from the nearest brain vertex, beyond --refine-radius + " +
          "--cell-size: no cell there to refine (the mesh files' coordinates are image mm)");
    }
  }
  if (o.skull) {
    // AAL regions per tetrahedron, written as the Medit tetrahedron reference.
    std::vector<int> labels = label_regions(brain, mask, o.atlas);
    r.regions = region_stats(brain, labels, mask);
    mesh::MeshData data = mesh::read_medit((mesh_dir / "brain.mesh").string(), 1.0);
    data.tet_labels = labels;
    mesh::write_medit((mesh_dir / "brain.mesh").string(), data, 1.0);
    brain.set_tet_labels(std::move(labels));
  }
  t0 = Clock::now();
  const Mesh3Output artery3 =
      mesh_tube(centreline, o.artery_radius_mm, o.artery_cell_size_mm, o.seed);
  r.artery.seconds = seconds_since(t0);
  const mesh::TetMesh artery = write_and_load(mesh_dir / "artery.mesh", artery3, r.artery);

  // 4. Artery inside the brain surface (exact parity test of the fusion component).
  const auto surface = fusion::TriangleSurface::of(brain, "brain surface");
  for (const Vec3& x : artery.vertices()) {
    try {
      if (fusion::outside_closed_surface(x, surface)) ++r.artery_vertices_outside;
    } catch (const std::invalid_argument&) {  // on the surface: not strictly inside
      ++r.artery_vertices_outside;
    }
  }

  // 5. Skull base plane for the fixed nodes.
  skull_base_plane(brain, o.fixed_margin_mm * kMmToM, r.fixed_plane_point_m, r.fixed_plane_normal);

  // 5b. The skull, cut open at the craniotomy (image mm).
  const OpeningMni opening =
      o.opening_given ? OpeningMni{o.opening_center_mni_mm, o.opening_axis_mni.normalized(),
                                   o.opening_radius_mm, o.opening_half_length_mm,
                                   "given on the command line (--opening-*)"}
                      : default_suboccipital_opening();
  if (o.skull) {
    r.has_skull = true;
    SkullOptions so = o.skull_options;
    so.surface.seed = o.seed;
    CutCylinder cut;
    cut.center_mm = world_to_image(mask, opening.center_mm);
    cut.axis = (world_to_image(mask, opening.center_mm + opening.axis) - cut.center_mm).normalized();
    cut.radius_mm = opening.radius_mm;
    cut.half_length_mm = opening.half_length_mm;
    so.openings = {cut};
    SkullResult skull = build_skull(mask, so);
    write_skull(mesh_dir / "skull.mesh", skull.surface, r.skull);
    skull.surface = {};
    r.skull.build = skull;
    r.skull.opening_center_m = cut.center_mm * kMmToM;
    r.skull.opening_axis = cut.axis;
  }

  // 6. The scene.
  scene::Scene s;
  s.set_name(o.name);
  std::ostringstream desc;
  const Eigen::Vector3d world0 = (mask.image_to_world * Eigen::Vector4d(0, 0, 0, 1)).head<3>();
  desc << "Patient model: brain from the Colin27 MRI (" << o.mri_path
       << ") with a generated right middle cerebral artery; built by neurosim-model --seed "
       << o.seed << " --cell-size " << o.brain_cell_size_mm << refinement_flags(o.brain_refinement)
       << " --material "
       << (o.material == MaterialSet::Paper ? "paper" : "literature")
       << ". Mesh coordinates are the image's VTK coordinates (voxel index x spacing, mm); "
          "NIfTI world (MNI) = image + "
       << fmt(world0) << " mm.";
  if (o.skull) {
    desc << " Approach scene: brain tetrahedra labelled by AAL region (tissues), and the skull "
            "as a rigid closed surface with a craniotomy (meshes[].openings).";
  }
  s.set_description(desc.str());
  const std::string rel_dir = o.name + "/";
  {
    auto* m = s.add_meshes();
    m->set_id("brain");
    m->set_file(rel_dir + "brain.mesh");
    m->set_file_unit_m(kMmToM);
    set_material(m->mutable_material(), o.material, false);
    auto* hs = m->add_fixed()->mutable_half_space();
    set_vec(hs->mutable_point_m(), r.fixed_plane_point_m, 1e-6);
    set_vec(hs->mutable_normal(), r.fixed_plane_normal, 1e-6);
    m->set_priority(0);
    std::ostringstream prov;
    prov << "Colin27 ch2bet (mricron-data), T1 >= " << o.mask_threshold
         << " mask, largest component, cavities filled; CGAL Mesh_3 labeled image, cell size "
         << o.brain_cell_size_mm << " mm" << refinement_words(o.brain_refinement) << ", seed " << o.seed
         << ", sliver perturbation and exudation; fixed: brain resting on the skull base (nodes "
            "within "
         << o.fixed_margin_mm << " mm above a plane fitted to the lowest surface points)";
    m->set_provenance(prov.str());
    if (o.skull) {
      const std::string aal = "AAL atlas on Colin27 (" + o.atlas.path +
                              ", labels per aal.nii.txt) sampled at each tetrahedron's centroid, "
                              "nearest labelled voxel within " +
                              std::to_string(static_cast<int>(o.atlas.search_mm)) + " mm";
      auto* cerebrum = m->add_tissues();
      cerebrum->set_label(kCerebrum);
      cerebrum->set_name(region_name(kCerebrum));
      cerebrum->set_provenance(aal + ": AAL 1-90; the mesh's material");
      auto* cerebellum = m->add_tissues();
      cerebellum->set_label(kCerebellum);
      cerebellum->set_name(region_name(kCerebellum));
      cerebellum->set_provenance(aal + ": AAL 91-116 (Cerebelum_* and Vermis_*)");
      set_cerebellum_material(cerebellum->mutable_material(), o.material);
      auto* other = m->add_tissues();
      other->set_label(kOther);
      other->set_name(region_name(kOther));
      other->set_provenance(aal + ": no AAL label nearby (brainstem, which AAL lacks; CSF); the "
                                  "mesh's material");
    }
  }
  if (o.skull) {
    auto* m = s.add_meshes();
    m->set_id("skull");
    m->set_file(rel_dir + "skull.mesh");
    m->set_file_unit_m(kMmToM);
    m->set_rigid(true);
    const auto& so = o.skull_options;
    std::ostringstream prov;
    prov << "Colin27 head (" << so.head_path << ", T1 >= " << so.head_threshold
         << ", cavities filled in 3-D and in each axial slice) and brain mask (" << o.mri_path << "): bone shell from "
         << so.csf_gap_mm << " mm (CSF gap) to " << so.csf_gap_mm + so.thickness_mm
         << " mm outside the brain mask (exact distance transform), clipped to the head, cut "
            "by the opening, largest piece; indicator Gaussian-smoothed (sigma "
         << so.smoothing_sigma_mm << " mm) and its 0.5 level meshed by CGAL Mesh_3 (manifold, "
            "facet size "
         << so.surface.facet_size_mm << " mm, distance " << so.surface.facet_distance_mm
         << " mm, seed " << o.seed << "); not segmented bone: a shell of plausible thickness";
    m->set_provenance(prov.str());
    auto* op = m->add_openings();
    set_vec(op->mutable_center_m(), r.skull.opening_center_m, 1e-6);
    set_vec(op->mutable_axis(), r.skull.opening_axis, 1e-6);
    op->set_radius_m(opening.radius_mm * kMmToM);
    op->set_half_length_m(opening.half_length_mm * kMmToM);
    std::ostringstream oprov;
    oprov << opening.source << ". MNI centre " << fmt(opening.center_mm) << " mm, axis "
          << fmt(opening.axis, 3);
    op->set_provenance(oprov.str());
  }
  {
    auto* m = s.add_meshes();
    m->set_id("artery");
    m->set_file(rel_dir + "artery.mesh");
    m->set_file_unit_m(kMmToM);
    set_material(m->mutable_material(), o.material, true);
    m->set_priority(1);  // paper 2.4: the vessel wins over the brain
    std::ostringstream prov;
    prov << "generated (not segmented): tube r = " << o.artery_radius_mm << " mm, " << std::fixed
         << std::setprecision(1) << r.artery_length_mm
         << " mm along a plausible right MCA course (M1 -> genu at the limen insulae -> M2 over "
            "the insula in the Sylvian fissure); CGAL Mesh_3 implicit tube, cell size "
         << o.artery_cell_size_mm << " mm, seed " << o.seed;
    m->set_provenance(prov.str());
  }
  {
    auto* c = s.add_couplings();
    c->set_host("brain");
    c->set_embedded("artery");
    c->set_kind(scene::Coupling::TIE);
    c->set_method(scene::Coupling::EXACT);
  }
  {
    auto* t = s.add_tools();
    t->set_id("probe");
    t->set_tip_radius_m(0.002);
    t->set_shaft_radius_m(0.0015);
    t->set_shaft_length_m(0.15);
    t->set_max_speed_m_per_s(2.0);
  }
  auto* fx = s.mutable_effects();
  fx->set_tier(scene::Effects::LINEAR);
  fx->set_coupling(true);
  fx->set_tool_contact(true);
  fx->set_deformation_output(true);
  // The server warns once when the tier's expected tool-force error (measured table,
  // docs/accuracy.md) passes 10 % at the strain in the field.
  fx->set_max_expected_force_error(0.1);
  s.mutable_rates()->set_step_hz(1000);
  s.mutable_rates()->set_viewer_hz(30);
  s.mutable_rates()->set_status_hz(1);
  s.mutable_haptics()->set_force_scale(1);
  s.mutable_haptics()->set_workspace_scale(1);
  s.mutable_haptics()->set_max_force_n(3.3);
  s.mutable_image()->set_file(o.mri_path);
  s.mutable_image()->set_file_unit_m(kMmToM);
  s.set_max_stations(8);
  {
    // Static load case (neurosim-solve, the demo): the probe's footprint on the right lateral
    // surface over the Sylvian fissure, pushed 3 mm medially towards the artery.
    const Vec3 target_image =
        world_to_image(mask, Vec3(60.0, -10.0, 8.0));  // MNI mm, right superior temporal gyrus
    Vec3 lo, hi;
    footprint_box(brain, target_image * kMmToM, 0.010, 0.006, lo, hi);  // ~2 x 2 cm
    auto* pr = s.add_prescribed();
    pr->set_mesh("brain");
    set_vec(pr->mutable_region()->mutable_box()->mutable_min_m(), lo, 1e-6);
    set_vec(pr->mutable_region()->mutable_box()->mutable_max_m(), hi, 1e-6);
    set_vec(pr->mutable_displacement_m(), Vec3(-0.003, 0.0, 0.0), 1e-6);
    r.prescribed_nodes =
        static_cast<int>(scene::select_nodes(brain, pr->region(), "prescribed[0]").size());
  }

  // 6b. The scene must load: the brain carved around the artery as the server carves it, and
  // every connected part of what is left held by >= 3 non-collinear fixed nodes. A part cut off
  // (a few nodes of a fine brain between the artery and the surface) would make the stiffness
  // singular: it is pinned, its nodes fixed by id, and the count reported.
  r.scene = o.out_dir / (o.name + ".scene");
  {
    t0 = Clock::now();
    const std::string source = r.scene.string();
    auto find_entry = [&s](const std::string& id) -> scene::Mesh* {
      for (auto& m : *s.mutable_meshes())
        if (m.id() == id) return &m;
      return nullptr;
    };
    scene::Mesh* brain_entry = find_entry("brain");
    const scene::Mesh* artery_entry = find_entry("artery");
    const auto artery_loaded = scene::load_mesh(*artery_entry, o.out_dir, source);
    auto islands = [&] {
      const auto brain_loaded = scene::load_mesh(*brain_entry, o.out_dir, source);
      return find_islands(brain_loaded.mesh, brain_loaded.fixed_nodes, {&artery_loaded.mesh},
                          source + ": mesh brain");
    };
    const IslandReport found = islands();
    r.carved_tets = found.carved_tets;
    r.island_parts = static_cast<int>(found.part_nodes.size());
    r.pinned_nodes = static_cast<int>(found.pinned_nodes.size());
    if (!found.pinned_nodes.empty()) {
      auto* ids = brain_entry->add_fixed()->mutable_nodes();
      for (int v : found.pinned_nodes) ids->add_ids(v);
      std::ostringstream prov;
      prov << "; pinned: " << found.pinned_nodes.size() << " nodes of "
           << found.part_nodes.size()
           << " part(s) that carving around the artery cuts off from the fixed brain (they "
              "would be free rigid bodies), fixed by node id";
      brain_entry->set_provenance(brain_entry->provenance() + prov.str());
      const IslandReport again = islands();
      if (!again.pinned_nodes.empty()) {
        throw std::logic_error(source + ": " + std::to_string(again.pinned_nodes.size()) +
                               " brain nodes still unsupported after pinning");
      }
    }
    r.island_seconds = seconds_since(t0);
  }

  std::string text;
  if (!google::protobuf::TextFormat::PrintToString(s, &text)) {
    throw std::runtime_error("neurosim-model: cannot print the scene");
  }
  {
    std::ofstream out(r.scene);
    out << "# Generated by neurosim-model (tools/model); do not edit, rebuild instead.\n"
        << "# Brain: Colin27 MRI mesh. Artery: generated tube (see provenance). Units: m, Pa.\n"
        << text;
    if (!out) throw std::runtime_error(r.scene.string() + ": cannot write");
  }

  // 7. Read it back as the server does.
  const scene::Scene back = scene::read_scene(r.scene);
  for (const auto& entry : back.meshes()) {
    if (entry.rigid()) {
      scene::load_rigid(entry, r.scene.parent_path(), r.scene.string());
      continue;
    }
    const auto loaded = scene::load_mesh(entry, r.scene.parent_path(), r.scene.string());
    if (entry.id() == "brain") r.fixed_nodes = static_cast<int>(loaded.fixed_nodes.size());
  }
  r.total_seconds = seconds_since(t_start);
  return r;
}

std::string summary(const ModelResult& r) {
  std::ostringstream os;
  auto pct = [](int n, int paper) {
    std::ostringstream p;
    p << std::showpos << std::fixed << std::setprecision(1) << 100.0 * (n - paper) / paper << "%";
    return p.str();
  };
  auto line = [&](const char* what, const MeshSummary& m, int pv, int pt) {
    os << "  " << what << ": " << m.vertices << " vertices (paper " << pv << ", "
       << pct(m.vertices, pv) << "; " << m.file_vertices << " in the file), " << m.tets
       << " tetrahedra (paper " << pt << ", " << pct(m.tets, pt) << ")\n"
       << "    min dihedral " << std::fixed << std::setprecision(2) << m.quality.min_dihedral_deg
       << " deg, max " << m.quality.max_dihedral_deg << " deg, inverted " << m.quality.inverted
       << ", meshed in " << std::setprecision(2) << m.seconds << " s -> " << m.file.string()
       << "\n";
  };
  os << "neurosim-model: " << r.scene.string() << "\n";
  os << std::fixed << std::setprecision(2) << "  MRI mask: " << std::setprecision(0)
     << r.brain_volume_ml << " ml, read and masked in " << std::setprecision(2) << r.mask_seconds
     << " s\n";
  line("brain ", r.brain, kPaperBrainVertices, kPaperBrainTets);
  line("artery", r.artery, kPaperArteryVertices, kPaperArteryTets);
  const int inside = r.artery.vertices - r.artery_vertices_outside;
  os << std::setprecision(1) << "  artery inside brain: " << inside << "/" << r.artery.vertices
     << " vertices strictly inside the brain surface ("
     << (r.artery_vertices_outside == 0 ? "OK" : "FAILED") << "); centreline " << r.artery_length_mm
     << " mm, >= " << r.artery_min_depth_mm << " mm inside the mask\n";
  os << "  fixed: " << r.fixed_nodes << " brain nodes on the skull-base side of the plane through "
     << fmt(r.fixed_plane_point_m * 1e3) << " mm, normal " << fmt(r.fixed_plane_normal, 3) << "\n";
  os << "  load check: " << r.carved_tets << " brain tetrahedra carved around the artery; "
     << r.island_parts << " part(s) cut off, " << r.pinned_nodes << " nodes pinned ("
     << std::setprecision(2) << r.island_seconds << " s)\n";
  os << "  load case: " << r.prescribed_nodes
     << " brain nodes on the right lateral surface pushed 3 mm medially (prescribed)\n";
  if (r.has_skull) {
    const auto& k = r.skull;
    os << std::setprecision(1) << "  regions (AAL): cerebrum " << r.regions.volume_ml[kCerebrum]
       << " ml centroid MNI " << fmt(r.regions.centroid_world_mm[kCerebrum]) << ", cerebellum "
       << r.regions.volume_ml[kCerebellum] << " ml centroid MNI "
       << fmt(r.regions.centroid_world_mm[kCerebellum]) << ", other "
       << r.regions.volume_ml[kOther] << " ml\n";
    os << "  skull: " << k.vertices << " vertices, " << k.triangles
       << " triangles, closed, bone volume " << k.enclosed_volume_ml << " ml (shell voxels "
       << k.build.shell_volume_ml << " ml; head " << k.build.head_volume_ml << " ml, " << k.build.head_filled_in_slices
       << " voxels filled in axial slices; "
       << k.build.removed_by_openings << " voxels cut by the opening, " << k.build.clipped_by_head
       << " outside the head, " << k.build.dropped_fragments << " in fragments) masks "
       << std::setprecision(2) << k.build.seconds_mask << " s, meshed in " << k.build.seconds_mesh
       << " s -> " << k.file.string() << "\n";
  }
  os << std::setprecision(2) << "  total " << r.total_seconds << " s\n";
  return os.str();
}

}  // namespace neurosim::model
