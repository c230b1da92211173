#include "viewer_client/viewer/image_io.hpp"

#include "common/nifti.hpp"
#include "common/stats.hpp"

#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPNGWriter.h>
#include <vtkPointData.h>
#include <vtkUnsignedCharArray.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace neurosim::viewer {

ImageGrid load_nifti(const std::string& path, double unit_m) {
  if (!(std::isfinite(unit_m) && unit_m > 0))
    throw std::runtime_error(path + ": image unit " + std::to_string(unit_m) +
                             " m is not positive");
  const nifti::Volume v = nifti::read(path);
  ImageGrid g;
  for (std::size_t a = 0; a < 3; ++a) {
    g.dims[a] = v.dims[a];
    g.spacing_m[static_cast<Eigen::Index>(a)] = v.spacing[a] * unit_m;
    g.origin_m[static_cast<Eigen::Index>(a)] = v.origin[a] * unit_m;
  }
  g.values = v.float_values();
  try {
    g.validate();
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
  return g;
}

ImageGrid downsample(const ImageGrid& image, int step) {
  if (step <= 1) return image;
  ImageGrid g;
  for (std::size_t a = 0; a < 3; ++a) g.dims[a] = (image.dims[a] + step - 1) / step;
  g.origin_m = image.origin_m;
  g.spacing_m = image.spacing_m * step;
  g.values.resize(static_cast<std::size_t>(g.dims[0]) * g.dims[1] * g.dims[2]);
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i)
        g.values[g.index(i, j, k)] = image.values[image.index(i * step, j * step, k * step)];
  return g;
}

void write_png_rgb(const std::string& path, int width, int height,
                   const std::vector<std::uint8_t>& rgb) {
  if (width <= 0 || height <= 0 ||
      rgb.size() != 3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    throw std::runtime_error(path + ": RGB buffer does not match " + std::to_string(width) + "x" +
                             std::to_string(height));
  vtkNew<vtkImageData> im;
  im->SetDimensions(width, height, 1);
  vtkNew<vtkUnsignedCharArray> px;
  px->SetNumberOfComponents(3);
  px->SetNumberOfTuples(static_cast<vtkIdType>(width) * height);
  std::copy(rgb.begin(), rgb.end(), px->GetPointer(0));
  im->GetPointData()->SetScalars(px);
  vtkNew<vtkPNGWriter> writer;
  writer->SetFileName(path.c_str());
  writer->SetInputData(im);
  writer->Write();
  if (writer->GetErrorCode() != 0) throw std::runtime_error(path + ": cannot write PNG");
}

std::pair<float, float> display_range(const ImageGrid& image) {
  std::vector<float> v;
  v.reserve(image.values.size() / 4);
  for (std::size_t i = 0; i < image.values.size(); i += 7)  // a sparse sample is enough
    if (image.values[i] > 0 && std::isfinite(image.values[i])) v.push_back(image.values[i]);
  if (v.empty()) return {0.0F, 1.0F};
  const float hi = common::percentile_in_place(v.begin(), v.end(), 0.995);
  return {0.0F, hi > 0 ? hi : 1.0F};
}

}  // namespace neurosim::viewer
