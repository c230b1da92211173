// The patient model: brain mesh from the Colin27 MRI, a generated artery tube inside
// it, fixed nodes at the skull base, materials, and the scene file that ties them together.
#pragma once

#include "server/mesh/quality.hpp"
#include "server/mesh/tet_mesh.hpp"
#include "tools/model/mesh3.hpp"
#include "tools/model/regions.hpp"
#include "tools/model/skull.hpp"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace neurosim::model {

using mesh::Vec3;

enum class MaterialSet {
  Literature,  // brain E = 3 kPa, nu = 0.49, smoothed-tet; artery E = 1 MPa, nu = 0.45
  Paper,       // the mesh fusion paper's E = 1 MPa, nu = 0.4 for both
};

struct ModelOptions {
  std::string mri_path{"/usr/share/mricron/templates/ch2bet.nii.gz"};
  std::filesystem::path out_dir{"scenes"};
  std::string name{"brain_artery"};  // <out_dir>/<name>.scene and <out_dir>/<name>/*.mesh
  double mask_threshold{20.0};       // T1 intensity (ch2bet is 0..133); voxels >= it are brain
  double brain_cell_size_mm{5.0};    // Mesh_3 cell/facet size, unit mm (~13.3k vertices)
  // Finer brain cells around one point (image mm; off by default): a press's neighbourhood
  // resolved without refining the whole brain (contact_convergence_bench --refine-cell).
  LocalRefinement brain_refinement{};
  double artery_cell_size_mm{0.9};   // unit mm (~1.5k vertices, ~4.4k tetrahedra)
  double artery_radius_mm{1.5};      // MCA M1 diameter ~3 mm
  // Artery centreline control points in the image's world space (NIfTI sform: MNI mm).
  // Empty: default_mca_course_mni_mm().
  std::vector<Vec3> artery_course_world_mm;
  double fixed_margin_mm{10.0};  // fixed layer above the fitted skull-base plane, unit mm
  std::uint32_t seed{1};
  MaterialSet material{MaterialSet::Literature};
  // --skull: the approach scene (default name brain_skull): the brain's tetrahedra labelled by
  // AAL region (tissues cerebrum / cerebellum / other), and the skull as a rigid surface with a
  // craniotomy. Off: the brain/artery scene exactly as before.
  bool skull{false};
  SkullOptions skull_options{};  // its openings are replaced by `opening` below
  AtlasOptions atlas{};
  // The craniotomy in NIfTI world (MNI) mm; default_suboccipital_opening() unless set.
  bool opening_given{false};
  Vec3 opening_center_mni_mm{Vec3::Zero()};
  Vec3 opening_axis_mni{Vec3::UnitZ()};
  double opening_radius_mm{15.0};
  double opening_half_length_mm{25.0};
};

// The default craniotomy: suboccipital, over the right cerebellar hemisphere (the paper's
// Figure 16 shows the cerebellum through a hole in the skull). Centre and axis in MNI mm.
struct OpeningMni {
  Vec3 center_mm;
  Vec3 axis;  // unit, out of the head
  double radius_mm;
  double half_length_mm;
  const char* source;
};
OpeningMni default_suboccipital_opening();

// Right middle cerebral artery, MNI mm: M1 from the carotid terminus laterally to the genu at
// the limen insulae, then M2 posterosuperiorly over the insula in the Sylvian fissure.
std::vector<Vec3> default_mca_course_mni_mm();

struct MeshSummary {
  std::filesystem::path file;
  int vertices{0};       // used by a tetrahedron
  int file_vertices{0};  // written (CGAL's Medit output holds some unused ones)
  int tets{0};
  mesh::QualityReport quality;
  double seconds{0.0};  // meshing wall time, unit s
};

struct SkullSummary {
  std::filesystem::path file;
  int vertices{0};
  int triangles{0};
  double enclosed_volume_ml{0.0};  // of the closed surface (bone volume), unit ml
  SkullResult build;               // voxel counts, timings (surface moved out)
  Vec3 opening_center_m{Vec3::Zero()};  // scene coordinates, unit m
  Vec3 opening_axis{Vec3::UnitZ()};
};

struct ModelResult {
  bool has_skull{false};
  SkullSummary skull;
  RegionStats regions;  // with has_skull
  MeshSummary brain;
  MeshSummary artery;
  double brain_volume_ml{0.0};      // mask volume, unit ml
  double artery_length_mm{0.0};     // centreline length, unit mm
  double artery_min_depth_mm{0.0};  // least distance from the centreline to outside the mask
  int artery_vertices_outside{0};   // artery vertices not strictly inside the brain surface
  int fixed_nodes{0};               // brain nodes fixed at the skull base
  int prescribed_nodes{0};          // brain nodes of the static load case (tool footprint)
  int carved_tets{0};    // brain tetrahedra the server removes inside the artery at load
  int island_parts{0};   // parts of the carved brain no fixed node held (pinned)
  int pinned_nodes{0};   // their nodes, fixed by id in the scene (included in fixed_nodes)
  double island_seconds{0.0};  // the load check (carving, parts), unit s
  Vec3 fixed_plane_point_m{Vec3::Zero()};
  Vec3 fixed_plane_normal{Vec3::UnitZ()};
  std::filesystem::path scene;
  double mask_seconds{0.0};   // reading and masking the MRI, unit s
  double total_seconds{0.0};  // unit s
};

// Builds everything and writes <out_dir>/<name>.scene and <out_dir>/<name>/{brain,artery}.mesh,
// then reads the scene back with the server's loader. Before the scene is written, the brain is
// carved around the artery as the server does at load and every part the fixed nodes leave free
// is pinned (islands.hpp): the scene written always loads. Throws std::invalid_argument on bad
// options and std::runtime_error when the MRI cannot be read or the artery course leaves the
// brain mask. An artery vertex outside the brain mesh is reported, not thrown.
ModelResult build_model(const ModelOptions& options);

// Human-readable summary, compared with the paper's Table 2 (5367/25103, 1644/4449).
std::string summary(const ModelResult& result);

// Paper, Table 2b (patient model).
inline constexpr int kPaperBrainVertices = 5367;
inline constexpr int kPaperBrainTets = 25103;
inline constexpr int kPaperArteryVertices = 1644;
inline constexpr int kPaperArteryTets = 4449;

}  // namespace neurosim::model
