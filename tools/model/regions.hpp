// Brain regions from the AAL atlas (mricron-data aal.nii.gz on the Colin27 grid): a region label
// for every tetrahedron of the brain mesh.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <array>
#include <string>
#include <vector>

namespace neurosim::model {

using mesh::Vec3;
struct BrainMask;  // mri_mask.hpp (VTK)

// Region labels written in the brain mesh (Medit tetrahedron reference) and named in the scene.
enum RegionLabel : int {
  kCerebrum = 1,    // AAL 1-90 (cerebral cortex, deep grey matter)
  kCerebellum = 2,  // AAL 91-116 (Cerebelum_* hemispheres and Vermis_*)
  kOther = 3,       // no AAL label within the search radius: brainstem (AAL has none), CSF
};
const char* region_name(int label);

struct AtlasOptions {
  std::string path{"/usr/share/mricron/templates/aal.nii.gz"};
  // AAL's standard table (aal.nii.txt beside the volume): 91 Cerebelum_Crus1_L ... 108
  // Cerebelum_10_R, 109 Vermis_1_2 ... 116 Vermis_10; 1-90 the cerebrum.
  int cerebellum_first{91};
  int cerebellum_last{116};
  // A tetrahedron whose centroid voxel has no atlas label takes the nearest labelled voxel's
  // class within this distance (sulcal CSF, the mask's rim), else kOther. Unit mm.
  double search_mm{3.0};
};

struct RegionStats {
  std::array<double, 4> volume_ml{};        // by label (index 0 unused), from the tetrahedra
  std::array<Vec3, 4> centroid_world_mm{};  // volume-weighted, NIfTI world (MNI) mm
  std::array<int, 4> tets{};
};

// Labels per tetrahedron of `brain` (vertices in m, image coordinates). The atlas must share the
// brain image's grid and sform (std::runtime_error naming the file otherwise).
std::vector<int> label_regions(const mesh::TetMesh& brain, const BrainMask& grid,
                               const AtlasOptions& options);

RegionStats region_stats(const mesh::TetMesh& brain, const std::vector<int>& labels,
                         const BrainMask& grid);

}  // namespace neurosim::model
