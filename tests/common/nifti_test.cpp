// The NIfTI reader: a volume written by VTK reads back with its geometry and values; missing
// and non-NIfTI files are errors naming the file.
#include "common/nifti.hpp"
#include "test_support.hpp"

#include <vtkImageData.h>
#include <vtkNIFTIImageWriter.h>
#include <vtkNew.h>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;

TEST(common_nifti, WrittenVolumeReadsBack) {
  const fs::path dir = neurosim::testing::temp_dir("common_nifti");
  vtkNew<vtkImageData> im;
  im->SetDimensions(4, 3, 2);
  im->SetSpacing(1.0, 2.0, 0.5);
  im->AllocateScalars(VTK_SHORT, 1);
  auto* p = static_cast<short*>(im->GetScalarPointer());
  for (int i = 0; i < 24; ++i) p[i] = static_cast<short>(10 * i);
  vtkNew<vtkNIFTIImageWriter> w;
  const std::string file = (dir / "v.nii.gz").string();
  w->SetFileName(file.c_str());
  w->SetInputData(im);
  w->Write();
  ASSERT_EQ(w->GetErrorCode(), 0u);

  const neurosim::nifti::Volume v = neurosim::nifti::read(file);
  EXPECT_EQ(v.dims, (std::array<int, 3>{4, 3, 2}));
  EXPECT_DOUBLE_EQ(v.spacing[1], 2.0);
  EXPECT_DOUBLE_EQ(v.spacing[2], 0.5);
  const std::vector<float> f = v.float_values();
  ASSERT_EQ(f.size(), 24u);
  for (int i = 0; i < 24; ++i) EXPECT_EQ(f[static_cast<std::size_t>(i)], 10.0F * i);
  ASSERT_NE(v.image, nullptr);
  EXPECT_EQ(v.image->GetNumberOfPoints(), 24);

  try {
    neurosim::nifti::read((dir / "none.nii").string());
    FAIL() << "no error for a missing file";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("none.nii"), std::string::npos) << e.what();
  }
  std::ofstream((dir / "text.nii")) << "not an image\n";
  EXPECT_THROW(neurosim::nifti::read((dir / "text.nii").string()), std::runtime_error);
  fs::remove_all(dir);
}
