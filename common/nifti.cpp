#include "common/nifti.hpp"

#include <vtkDataArray.h>
#include <vtkMatrix4x4.h>
#include <vtkNIFTIImageReader.h>
#include <vtkPointData.h>

#include <filesystem>
#include <stdexcept>

namespace neurosim::nifti {

Volume read(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw std::runtime_error(path + ": no such NIfTI file");
  auto reader = vtkSmartPointer<vtkNIFTIImageReader>::New();
  if (!reader->CanReadFile(path.c_str()))
    throw std::runtime_error(path + ": not a NIfTI file vtkNIFTIImageReader can read");
  reader->SetFileName(path.c_str());
  reader->Update();
  vtkImageData* im = reader->GetOutput();
  if (reader->GetErrorCode() != 0 || im == nullptr || im->GetNumberOfPoints() == 0 ||
      im->GetNumberOfScalarComponents() != 1 || im->GetPointData()->GetScalars() == nullptr)
    throw std::runtime_error(path + ": cannot read a scalar volume");

  Volume v;
  v.image = im;  // keeps the reader's output alive on its own
  im->GetDimensions(v.dims.data());
  im->GetSpacing(v.spacing.data());
  im->GetOrigin(v.origin.data());
  vtkMatrix4x4* world = reader->GetSFormMatrix();
  if (world == nullptr) world = reader->GetQFormMatrix();
  if (world != nullptr) {
    v.has_world = true;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        v.image_to_world[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)] =
            world->GetElement(r, c);
  }
  return v;
}

std::vector<float> Volume::float_values() const {
  std::vector<float> out;
  vtkDataArray* s = image != nullptr ? image->GetPointData()->GetScalars() : nullptr;
  if (s == nullptr) return out;
  const vtkIdType n = s->GetNumberOfTuples();
  out.resize(static_cast<std::size_t>(n));
  for (vtkIdType i = 0; i < n; ++i)
    out[static_cast<std::size_t>(i)] = static_cast<float>(s->GetComponent(i, 0));
  return out;
}

}  // namespace neurosim::nifti
