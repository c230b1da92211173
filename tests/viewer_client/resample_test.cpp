// Tests of the MRI resampling through deformed meshes (viewer_client/resample.hpp).
#include "viewer_client/resample.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using neurosim::viewer::DeformedVolumeSampler;
using neurosim::viewer::ImageGrid;
using neurosim::viewer::Location;
using neurosim::viewer::make_image_slice;
using neurosim::viewer::MeshGeometry;
using neurosim::viewer::ResampleStats;
using neurosim::viewer::sample_trilinear;
using neurosim::viewer::SamplerOptions;
using neurosim::viewer::Slice;

// A 26 x 22 x 20 image (default), anisotropic spacing around 1 mm, origin off zero.
ImageGrid make_image(std::array<int, 3> dims = {26, 22, 20}) {
  ImageGrid g;
  g.dims = dims;
  g.origin_m = Vector3d(0.002, -0.001, 0.003);
  g.spacing_m = Vector3d(1.0e-3, 1.2e-3, 0.9e-3);
  g.values.resize(static_cast<std::size_t>(dims[0]) * dims[1] * dims[2]);
  return g;
}

// Random voxel values (so any misplaced read shows).
ImageGrid random_image(unsigned seed = 7, std::array<int, 3> dims = {26, 22, 20}) {
  ImageGrid g = make_image(dims);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(0.0F, 255.0F);
  for (float& v : g.values) v = d(rng);
  return g;
}

// L(x) = c0 + g . x: trilinear interpolation reproduces it exactly.
const Vector3d kGradient(1.0e4, 2.0e4, -1.5e4);  // per m
constexpr double kC0 = 400.0;
double linear_value(const Vector3d& x) { return kC0 + kGradient.dot(x); }

ImageGrid linear_image() {
  ImageGrid g = make_image();
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Vector3d x = g.origin_m + g.spacing_m.cwiseProduct(Vector3d(i, j, k));
        g.values[g.index(i, j, k)] = static_cast<float>(linear_value(x));
      }
  return g;
}

double signed_volume(const Vector3d& a, const Vector3d& b, const Vector3d& c, const Vector3d& d) {
  return (b - a).dot((c - a).cross(d - a)) / 6.0;
}

// Box [lo, lo + n h] of n^3 cells, 6 Kuhn tetrahedra each (conforming, positive). Interior
// vertices are jittered by up to `jitter` x h (boundary vertices stay on the box faces).
MeshGeometry cube_mesh(const std::string& id, const Vector3d& lo, int n, double h,
                       double jitter = 0.15, unsigned seed = 3) {
  MeshGeometry m;
  m.id = id;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-jitter * h, jitter * h);
  const auto vid = [n](int i, int j, int k) { return i + (n + 1) * (j + (n + 1) * k); };
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        Vector3d p = lo + h * Vector3d(i, j, k);
        const bool interior = i > 0 && i < n && j > 0 && j < n && k > 0 && k < n;
        if (interior) p += Vector3d(d(rng), d(rng), d(rng));
        m.rest_m.push_back(p);
      }
  const int paths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (const auto& path : paths) {
          int c[3] = {i, j, k};
          std::array<int, 4> t{};
          t[0] = vid(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[path[s]];
            t[s + 1] = vid(c[0], c[1], c[2]);
          }
          const auto& v = m.rest_m;
          if (signed_volume(v[t[0]], v[t[1]], v[t[2]], v[t[3]]) < 0) std::swap(t[2], t[3]);
          m.tets.push_back(t);
        }
  return m;
}

// The default test mesh: 5^3 cells of 2.6 mm from (6, 5, 6) mm, inside the image.
MeshGeometry default_mesh() { return cube_mesh("brain", Vector3d(0.006, 0.005, 0.006), 5, 0.0026); }

// u(x) = A x + b at every vertex.
std::vector<Vector3d> affine_displacement(const MeshGeometry& m, const Matrix3d& a,
                                          const Vector3d& b) {
  std::vector<Vector3d> u;
  for (const Vector3d& x : m.rest_m) u.push_back(a * x + b);
  return u;
}

// Slices through the image grid on all three axes, at a few positions.
std::vector<Slice> some_slices(const ImageGrid& g) {
  std::vector<Slice> s;
  for (int axis = 0; axis < 3; ++axis)
    for (double f : {0.0, 0.3, 0.45, 0.62, 1.0}) {
      const double pos = g.origin_m[axis] + f * (g.dims[axis] - 1) * g.spacing_m[axis];
      s.push_back(make_image_slice(g, axis, pos));
    }
  return s;
}

// Point of pixel (a, b) of a slice.
Vector3d pixel_point(const Slice& s, int a, int b) {
  const int u = s.axis == 0 ? 1 : 0;
  const int v = s.axis == 2 ? 1 : 2;
  Vector3d p = s.origin_m;
  p[s.axis] = s.position_m;
  p[u] = s.origin_m[u] + a * s.spacing_m[0];
  p[v] = s.origin_m[v] + b * s.spacing_m[1];
  return p;
}

// Voxel index of a slice pixel on the image grid.
std::array<int, 3> pixel_voxel(const ImageGrid& g, const Slice& s, int a, int b) {
  const int u = s.axis == 0 ? 1 : 0;
  const int v = s.axis == 2 ? 1 : 2;
  std::array<int, 3> ijk{};
  ijk[s.axis] =
      static_cast<int>(std::lround((s.position_m - g.origin_m[s.axis]) / g.spacing_m[s.axis]));
  ijk[u] = a;
  ijk[v] = b;
  return ijk;
}

// ------------------------------------------------------------------------------------------------

TEST(resample_image_grid, ValidateRejectsInconsistentGrids) {
  ImageGrid g = random_image();
  EXPECT_NO_THROW(g.validate());
  ImageGrid bad = g;
  bad.dims[1] = 0;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad = g;
  bad.values.pop_back();
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad = g;
  bad.spacing_m[2] = 0.0;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad = g;
  bad.spacing_m[0] = std::numeric_limits<double>::infinity();
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad = g;
  bad.origin_m[1] = std::nan("");
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad = g;
  bad.values[bad.index(3, 4, 5)] = std::numeric_limits<float>::quiet_NaN();
  try {
    bad.validate();
    FAIL() << "NaN voxel accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("(3, 4, 5)"), std::string::npos) << e.what();
  }
}

TEST(resample_trilinear, GridPointsCornersOutsideAndNaN) {
  const ImageGrid g = random_image();
  const auto at = [&g](double i, double j, double k) {
    return Vector3d(g.origin_m + g.spacing_m.cwiseProduct(Vector3d(i, j, k)));
  };
  // Every voxel centre, including the eight corners of the grid: the voxel value, bit for bit.
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i)
        ASSERT_EQ(sample_trilinear(g, at(i, j, k)), g.values[g.index(i, j, k)]) << i << j << k;
  const int L[3] = {g.dims[0] - 1, g.dims[1] - 1, g.dims[2] - 1};
  for (int c = 0; c < 8; ++c) {
    const int i = (c & 1) ? L[0] : 0, j = (c & 2) ? L[1] : 0, k = (c & 4) ? L[2] : 0;
    EXPECT_EQ(sample_trilinear(g, at(i, j, k), -1.0F), g.values[g.index(i, j, k)]);
  }
  // Cell centre: the mean of its 8 voxels.
  double mean = 0.0;
  for (int c = 0; c < 8; ++c)
    mean += g.values[g.index(4 + (c & 1), 5 + ((c >> 1) & 1), 6 + ((c >> 2) & 1))] / 8.0;
  EXPECT_NEAR(sample_trilinear(g, at(4.5, 5.5, 6.5)), mean, 1e-4);
  // On the last face, between voxels: linear along the face.
  EXPECT_NEAR(sample_trilinear(g, at(L[0], 2.25, 0)),
              0.75 * g.values[g.index(L[0], 2, 0)] + 0.25 * g.values[g.index(L[0], 3, 0)], 1e-4);
  // Outside (beyond the outermost voxel centres), not finite: `outside`.
  EXPECT_EQ(sample_trilinear(g, at(-0.01, 3, 3), -7.0F), -7.0F);
  EXPECT_EQ(sample_trilinear(g, at(3, L[1] + 0.01, 3), -7.0F), -7.0F);
  EXPECT_EQ(sample_trilinear(g, at(3, 3, L[2] + 5), -7.0F), -7.0F);
  EXPECT_EQ(sample_trilinear(g, at(1e300, 3, 3), -7.0F), -7.0F);
  EXPECT_EQ(sample_trilinear(g, Vector3d(std::nan(""), 0.01, 0.01), -7.0F), -7.0F);
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(sample_trilinear(g, Vector3d(0.01, -inf, 0.01), 3.0F), 3.0F);
  EXPECT_EQ(sample_trilinear(g, Vector3d(0.01, 0.01, 0.01 * 0.0)), 0.0F);  // z below origin
  // A linear image is reproduced exactly anywhere inside.
  const ImageGrid lin = linear_image();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int n = 0; n < 1000; ++n) {
    const Vector3d f(u(rng) * L[0], u(rng) * L[1], u(rng) * L[2]);
    const Vector3d p = lin.origin_m + lin.spacing_m.cwiseProduct(f);
    ASSERT_NEAR(sample_trilinear(lin, p), linear_value(p), 1e-5 * linear_value(p));
  }
}

TEST(resample_trilinear, InconsistentImageIsRefused) {
  ImageGrid g = random_image();
  g.values.resize(10);
  EXPECT_THROW(sample_trilinear(g, Vector3d(0.01, 0.01, 0.01)), std::invalid_argument);
  g = ImageGrid();
  EXPECT_THROW(sample_trilinear(g, Vector3d::Zero()), std::invalid_argument);
}

TEST(resample_trilinear, SingleVoxelThickAxis) {
  ImageGrid g;
  g.dims = {3, 1, 2};
  g.values = {1, 2, 3, 4, 5, 6};
  EXPECT_EQ(sample_trilinear(g, Vector3d(2, 0, 1)), 6.0F);
  EXPECT_FLOAT_EQ(sample_trilinear(g, Vector3d(0.5, 0, 0.5)), 3.0F);
  EXPECT_EQ(sample_trilinear(g, Vector3d(0.5, 0.1, 0.5), -1.0F), -1.0F);
}

TEST(resample_slice, SnapsToTheNearestVoxelPlane) {
  const ImageGrid g = random_image();
  const Slice s = make_image_slice(g, 1, g.origin_m[1] + 4.4 * g.spacing_m[1]);
  EXPECT_EQ(s.axis, 1);
  EXPECT_DOUBLE_EQ(s.position_m, g.origin_m[1] + 4 * g.spacing_m[1]);
  EXPECT_EQ(s.width, g.dims[0]);
  EXPECT_EQ(s.height, g.dims[2]);
  EXPECT_EQ(s.spacing_m, Eigen::Vector2d(g.spacing_m[0], g.spacing_m[2]));
  EXPECT_EQ(s.values.size(), static_cast<std::size_t>(g.dims[0]) * g.dims[2]);
  const Slice beyond = make_image_slice(g, 0, 10.0);
  EXPECT_DOUBLE_EQ(beyond.position_m, g.origin_m[0] + (g.dims[0] - 1) * g.spacing_m[0]);
  EXPECT_EQ(beyond.width, g.dims[1]);
  EXPECT_EQ(beyond.height, g.dims[2]);
  EXPECT_THROW(make_image_slice(g, 3, 0.0), std::invalid_argument);
  EXPECT_THROW(make_image_slice(g, -1, 0.0), std::invalid_argument);
  EXPECT_THROW(make_image_slice(g, 2, std::nan("")), std::invalid_argument);
}

TEST(resample_sampler, ConstructorRejectsBadMeshesNamingThem) {
  MeshGeometry m = default_mesh();
  m.tets[17][2] = static_cast<int>(m.rest_m.size());
  try {
    DeformedVolumeSampler s(random_image(), {m});
    FAIL() << "out-of-range vertex id accepted";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'brain'"), std::string::npos) << what;
    EXPECT_NE(what.find("tetrahedron 17"), std::string::npos) << what;
  }
  m = default_mesh();
  m.rest_m[5][1] = std::numeric_limits<double>::infinity();
  try {
    DeformedVolumeSampler s(random_image(), {m});
    FAIL() << "non-finite vertex accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 5"), std::string::npos) << e.what();
  }
  ImageGrid bad = random_image();
  bad.values.pop_back();
  EXPECT_THROW(DeformedVolumeSampler(bad, {default_mesh()}), std::invalid_argument);
  SamplerOptions o;
  o.move_tolerance_m = -1.0;
  EXPECT_THROW(DeformedVolumeSampler(random_image(), {default_mesh()}, o), std::invalid_argument);
}

// The whole image through slices and the volume equals the grid values, bit for bit.
void expect_image_reproduced(DeformedVolumeSampler& s, const ImageGrid& g) {
  std::vector<Slice> slices = some_slices(g);
  for (Slice& sl : slices) {
    const ResampleStats st = s.update_slice(sl);
    EXPECT_EQ(st.samples_recomputed, st.samples_total);
    for (int b = 0; b < sl.height; ++b)
      for (int a = 0; a < sl.width; ++a) {
        const auto ijk = pixel_voxel(g, sl, a, b);
        ASSERT_EQ(sl.values[a + sl.width * b], g.values[g.index(ijk[0], ijk[1], ijk[2])])
            << "axis " << sl.axis << " pixel " << a << ", " << b;
      }
  }
  ImageGrid vol;
  const ResampleStats st = s.update_volume(vol);
  EXPECT_EQ(st.samples_recomputed, g.values.size());
  EXPECT_EQ(vol.dims, g.dims);
  EXPECT_EQ(vol.origin_m, g.origin_m);
  EXPECT_EQ(vol.spacing_m, g.spacing_m);
  ASSERT_EQ(vol.values.size(), g.values.size());
  for (std::size_t n = 0; n < g.values.size(); ++n) ASSERT_EQ(vol.values[n], g.values[n]) << n;
}

TEST(resample_sampler, ZeroDisplacementReproducesTheImageExactly) {
  const ImageGrid g = random_image();
  MeshGeometry artery = cube_mesh("artery", Vector3d(0.010, 0.009, 0.010), 3, 0.002, 0.1, 9);
  artery.priority = 1;
  DeformedVolumeSampler s(g, {default_mesh(), artery});
  ASSERT_EQ(s.mesh_count(), 2U);
  EXPECT_EQ(s.find_mesh("artery"), 1);
  EXPECT_EQ(s.find_mesh("liver"), -1);
  // Never set, set to zeros, and back to zero after a push.
  expect_image_reproduced(s, g);
  std::vector<float> zeros(3 * s.mesh(0).rest_m.size(), 0.0F);
  s.set_displacements(0, zeros.data(), zeros.size());
  expect_image_reproduced(s, g);
  std::vector<Vector3d> push(s.mesh(0).rest_m.size(), Vector3d::Zero());
  push[40] = Vector3d(0.001, -0.0005, 0.0002);
  s.set_displacements(0, push);
  EXPECT_NE(s.to_rest(s.mesh(0).rest_m[40] + push[40]), s.mesh(0).rest_m[40] + push[40]);
  push[40].setZero();
  s.set_displacements(0, push);
  expect_image_reproduced(s, g);
  // The point map is the identity, exactly, inside the meshes.
  const Vector3d p(0.0123, 0.0111, 0.0134);
  EXPECT_EQ(s.to_rest(p), p);
  EXPECT_EQ(s.locate(p).mesh, 1);
}

// Inverse of the affine deformation y = (I + A) x + b.
struct AffineCase {
  Matrix3d a;
  Vector3d b;
  Vector3d lo, hi;  // the mesh's rest box
  Vector3d inverse(const Vector3d& y) const {
    return (Matrix3d::Identity() + a).partialPivLu().solve(y - b);
  }
  // Distance (m) of the rest point of y inside the rest box (negative outside).
  double inside_depth(const Vector3d& y) const {
    const Vector3d x = inverse(y);
    return std::min((x - lo).minCoeff(), (hi - x).minCoeff());
  }
};

TEST(resample_sampler, AffineDeformationGivesTheAnalyticallyWarpedImage) {
  const ImageGrid g = linear_image();
  const MeshGeometry mesh = default_mesh();
  AffineCase c;
  c.a << 0.05, 0.02, -0.01, 0.0, -0.04, 0.03, 0.01, 0.0, 0.06;
  c.b = Vector3d(0.5e-3, -0.3e-3, 0.2e-3) - c.a * Vector3d(0.0135, 0.0125, 0.0135);
  c.lo = Vector3d(0.006, 0.005, 0.006);
  c.hi = c.lo + Vector3d::Constant(0.013);
  DeformedVolumeSampler s(g, {mesh});
  s.set_displacements(0, affine_displacement(mesh, c.a, c.b));

  const double edge = 1e-7;  // skip points this close to the deformed boundary (either answer)
  std::size_t inside = 0, outside = 0;
  const auto check = [&](const Vector3d& y, float value, float original) {
    const double depth = c.inside_depth(y);
    if (depth > edge) {
      ++inside;
      const Vector3d x = c.inverse(y);
      ASSERT_LT((s.to_rest(y) - x).norm(), 1e-12) << y.transpose();
      ASSERT_NEAR(value, linear_value(x), 1e-5 * std::abs(linear_value(x))) << y.transpose();
    } else if (depth < -edge) {
      ++outside;
      ASSERT_EQ(s.to_rest(y), y);
      ASSERT_EQ(value, original) << y.transpose();  // unchanged, bit for bit
    }
  };
  std::vector<Slice> slices = some_slices(g);
  for (Slice& sl : slices) {
    s.update_slice(sl);
    for (int b = 0; b < sl.height; ++b)
      for (int a = 0; a < sl.width; ++a) {
        const auto ijk = pixel_voxel(g, sl, a, b);
        check(pixel_point(sl, a, b), sl.values[a + sl.width * b],
              g.values[g.index(ijk[0], ijk[1], ijk[2])]);
      }
  }
  ImageGrid vol;
  s.update_volume(vol);
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Vector3d y = g.origin_m + g.spacing_m.cwiseProduct(Vector3d(i, j, k));
        check(y, vol.values[g.index(i, j, k)], g.values[g.index(i, j, k)]);
      }
  // Both kinds of points were seen in numbers (the test can fail either way).
  EXPECT_GT(inside, 3000U);
  EXPECT_GT(outside, 3000U);
  // Random points too (not on the grid).
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.004, 0.024);
  for (int n = 0; n < 2000; ++n) {
    const Vector3d y(u(rng), u(rng), u(rng));
    check(y, s.sample(y), sample_trilinear(g, y));
  }
}

// Sampler with a 30 mm cube mesh in a 48 x 40 x 44 image, three slices through (20, 19, 20)
// mm and a volume, updated once.
struct Scene {
  ImageGrid g = random_image(11, {48, 40, 44});
  MeshGeometry mesh = cube_mesh("brain", Vector3d(0.008, 0.007, 0.006), 10, 0.003);
  DeformedVolumeSampler s{g, {mesh}};
  std::vector<Slice> slices;
  ImageGrid vol;
  Scene() {
    for (int axis = 0; axis < 3; ++axis) slices.push_back(make_image_slice(g, axis, centre[axis]));
    for (Slice& sl : slices) s.update_slice(sl);
    s.update_volume(vol);
  }
  Vector3d centre{0.020, 0.019, 0.020};
  // Gaussian bump of amplitude `amp` (m) centred at `c`, sigma 1.5 mm, cut below 1 %.
  std::vector<Vector3d> bump(const Vector3d& c, const Vector3d& amp) const {
    std::vector<Vector3d> u(mesh.rest_m.size(), Vector3d::Zero());
    for (std::size_t v = 0; v < u.size(); ++v) {
      const double r2 = (mesh.rest_m[v] - c).squaredNorm();
      const double w = std::exp(-r2 / (2 * 0.0015 * 0.0015));
      if (w > 1e-2) u[v] = w * amp;
    }
    return u;
  }
};

// Fresh outputs of the same geometry, computed in full.
void expect_equal_to_full(DeformedVolumeSampler& s, const std::vector<Slice>& slices,
                          const ImageGrid& vol) {
  for (const Slice& sl : slices) {
    Slice full = sl;
    full.values.clear();
    const ResampleStats st = s.update_slice(full);
    EXPECT_EQ(st.samples_recomputed, st.samples_total);
    ASSERT_EQ(full.values, sl.values) << "axis " << sl.axis;
  }
  ImageGrid full;
  s.update_volume(full);
  ASSERT_EQ(full.values, vol.values);
  s.forget(full);
}

TEST(resample_sampler, IncrementalUpdateEqualsAFullRecompute) {
  Scene sc;
  DeformedVolumeSampler& s = sc.s;
  // Nothing moved: nothing recomputed.
  for (Slice& sl : sc.slices) EXPECT_EQ(s.update_slice(sl).samples_recomputed, 0U);
  EXPECT_EQ(s.update_volume(sc.vol).samples_recomputed, 0U);

  // A local push near the centre of the slices' crossing.
  const Vector3d centre = sc.centre;
  s.set_displacements(0, sc.bump(centre, Vector3d(0.001, -0.0007, 0.0004)));
  std::size_t recomputed = 0, total = 0;
  for (Slice& sl : sc.slices) {
    const ResampleStats st = s.update_slice(sl);
    EXPECT_GT(st.samples_recomputed, 0U);
    EXPECT_GT(st.moved_tets, 0U);
    EXPECT_LT(st.moved_tets, sc.mesh.tets.size() / 4);
    recomputed += st.samples_recomputed;
    total += st.samples_total;
  }
  EXPECT_LT(recomputed, total / 5);
  const ResampleStats vst = s.update_volume(sc.vol);
  EXPECT_GT(vst.samples_recomputed, 0U);
  EXPECT_LT(vst.samples_recomputed, vst.samples_total / 10);
  expect_equal_to_full(s, sc.slices, sc.vol);

  // The push moves elsewhere (old region and new both recomputed), twice without updating
  // the volume in between; then it goes away.
  s.set_displacements(0, sc.bump(centre + Vector3d(0.003, 0.0, -0.002), Vector3d(0, 0.002, 0)));
  for (Slice& sl : sc.slices) s.update_slice(sl);
  s.set_displacements(0, sc.bump(centre + Vector3d(0.004, 0.001, 0.0), Vector3d(-0.001, 0, 0)));
  for (Slice& sl : sc.slices) s.update_slice(sl);
  s.update_volume(sc.vol);
  expect_equal_to_full(s, sc.slices, sc.vol);
  s.set_displacements(0, std::vector<Vector3d>(sc.mesh.rest_m.size(), Vector3d::Zero()));
  for (Slice& sl : sc.slices) s.update_slice(sl);
  s.update_volume(sc.vol);
  expect_equal_to_full(s, sc.slices, sc.vol);
  for (std::size_t n = 0; n < sc.g.values.size(); ++n) ASSERT_EQ(sc.vol.values[n], sc.g.values[n]);

  // The surface bulges out of the rest mesh and comes back: the space it left (outside every
  // rest tetrahedron) must be recomputed too.
  const Vector3d surface(0.038, 0.022, 0.021);
  Slice through = make_image_slice(sc.g, 2, surface[2]);
  s.update_slice(through);
  s.set_displacements(0, sc.bump(surface, Vector3d(0.003, 0.0, 0.0)));
  s.update_slice(through);
  s.update_volume(sc.vol);
  expect_equal_to_full(s, {through}, sc.vol);
  s.set_displacements(0, std::vector<Vector3d>(sc.mesh.rest_m.size(), Vector3d::Zero()));
  s.update_slice(through);
  s.update_volume(sc.vol);
  expect_equal_to_full(s, {through}, sc.vol);
}

TEST(resample_sampler, PushAwayFromASliceLeavesItAlone) {
  Scene sc;
  DeformedVolumeSampler& s = sc.s;
  // Push near one corner of the mesh, far from the x = 20 mm plane.
  s.set_displacements(0, sc.bump(Vector3d(0.035, 0.03, 0.03), Vector3d(0, 0, -0.0008)));
  const ResampleStats st = s.update_slice(sc.slices[0]);
  EXPECT_EQ(st.samples_recomputed, 0U);
  EXPECT_GT(st.moved_tets, 0U);
  expect_equal_to_full(s, {sc.slices[0]}, [&] {
    s.update_volume(sc.vol);
    return sc.vol;
  }());
}

TEST(resample_sampler, ChangedSliceGeometryOrBufferRecomputesInFull) {
  Scene sc;
  DeformedVolumeSampler& s = sc.s;
  Slice& sl = sc.slices[2];
  sl.position_m += sc.g.spacing_m[2];
  ResampleStats st = s.update_slice(sl);
  EXPECT_EQ(st.samples_recomputed, st.samples_total);
  // A new slice object assigned into the same variable (new buffer): full.
  sl = make_image_slice(sc.g, 2, sl.position_m);
  st = s.update_slice(sl);
  EXPECT_EQ(st.samples_recomputed, st.samples_total);
  EXPECT_EQ(s.update_slice(sl).samples_recomputed, 0U);
  s.forget(sl);
  EXPECT_EQ(s.update_slice(sl).samples_recomputed, st.samples_total);
  // Volume whose geometry was changed by the caller: reset to the image grid, full.
  sc.vol.origin_m[0] += 1.0;
  st = s.update_volume(sc.vol);
  EXPECT_EQ(st.samples_recomputed, st.samples_total);
  EXPECT_EQ(sc.vol.origin_m, sc.g.origin_m);
  // Bad slices are refused.
  Slice bad = sl;
  bad.axis = 3;
  EXPECT_THROW(s.update_slice(bad), std::invalid_argument);
  bad = sl;
  bad.spacing_m[1] = 0;
  EXPECT_THROW(s.update_slice(bad), std::invalid_argument);
  bad = sl;
  bad.position_m = std::nan("");
  EXPECT_THROW(s.update_slice(bad), std::invalid_argument);
  bad = sl;
  bad.width = 0;
  EXPECT_THROW(s.update_slice(bad), std::invalid_argument);
}

TEST(resample_sampler, MotionBelowTheToleranceUpdatesTheMapButNoSamples) {
  Scene sc;
  DeformedVolumeSampler& s = sc.s;
  const Vector3d centre = sc.centre;
  const auto u = sc.bump(centre, Vector3d(4e-6, 0, 0));  // below the default 1e-5 m
  s.set_displacements(0, u);
  for (Slice& sl : sc.slices) {
    const ResampleStats st = s.update_slice(sl);
    EXPECT_EQ(st.samples_recomputed, 0U);
    EXPECT_EQ(st.moved_tets, 0U);
  }
  // The point map follows at once.
  std::size_t v = 0;
  for (std::size_t k = 0; k < u.size(); ++k)
    if (u[k].norm() > u[v].norm()) v = k;
  const Vector3d y = sc.mesh.rest_m[v] + u[v];
  EXPECT_LT((s.to_rest(y) - sc.mesh.rest_m[v]).norm(), 1e-12);
  // Accumulated motion past the tolerance is reported.
  s.set_displacements(0, sc.bump(centre, Vector3d(2.5e-5, 0, 0)));
  EXPECT_GT(s.update_slice(sc.slices[0]).samples_recomputed, 0U);
  // With tolerance 0 every change counts.
  SamplerOptions o;
  o.move_tolerance_m = 0.0;
  DeformedVolumeSampler exact(sc.g, {sc.mesh}, o);
  Slice sl = sc.slices[0];
  exact.update_slice(sl);
  exact.set_displacements(0, u);
  EXPECT_GT(exact.update_slice(sl).samples_recomputed, 0U);
}

// Two overlapping meshes translated differently: the higher priority decides.
TEST(resample_sampler, PriorityDecidesWhereMeshesOverlap) {
  const ImageGrid g = linear_image();
  MeshGeometry brain = default_mesh();  // [6, 19] x [5, 18] x [6, 19] mm
  MeshGeometry artery = cube_mesh("artery", Vector3d(0.010, 0.009, 0.010), 3, 0.002, 0.1, 9);
  const Vector3d tb(0.0004, 0.0, 0.0), ta(0.0, -0.0006, 0.0003);
  const auto translate = [](const MeshGeometry& m, const Vector3d& t) {
    return std::vector<Vector3d>(m.rest_m.size(), t);
  };
  const Vector3d in_both(0.0131, 0.0117, 0.0129);  // inside the translated artery
  const Vector3d in_brain(0.0180, 0.0080, 0.0090);
  for (int artery_priority : {1, -1, 0}) {
    artery.priority = artery_priority;
    DeformedVolumeSampler s(g, {brain, artery});
    s.set_displacements(0, translate(brain, tb));
    s.set_displacements(1, translate(artery, ta));
    const Location l = s.locate(in_both);
    const Location lb = s.locate(in_brain);
    EXPECT_EQ(lb.mesh, 0);
    EXPECT_LT((lb.rest_m - (in_brain - tb)).norm(), 1e-12);
    // Equal priorities: the lower mesh index (the brain) wins.
    const int winner = artery_priority > 0 ? 1 : 0;
    EXPECT_EQ(l.mesh, winner) << "artery priority " << artery_priority;
    const Vector3d expected = in_both - (winner == 1 ? ta : tb);
    EXPECT_LT((s.to_rest(in_both) - expected).norm(), 1e-12);
    EXPECT_NEAR(s.sample(in_both), linear_value(expected), 1e-5 * linear_value(expected));
    EXPECT_NEAR(l.weights.sum(), 1.0, 1e-12);
    EXPECT_GE(l.weights.minCoeff(), -1e-9);
    // The slice through that point agrees with sample().
    Slice sl = make_image_slice(g, 2, in_both[2]);
    s.update_slice(sl);
    for (int b = 0; b < sl.height; b += 3)
      for (int a = 0; a < sl.width; a += 3)
        ASSERT_EQ(sl.values[a + sl.width * b], s.sample(pixel_point(sl, a, b)));
  }
}

TEST(resample_sampler, BadDisplacementsAreRejectedAndThePreviousOnesKept) {
  const ImageGrid g = random_image();
  MeshGeometry artery = cube_mesh("artery", Vector3d(0.010, 0.009, 0.010), 3, 0.002, 0.1, 9);
  artery.priority = 1;
  DeformedVolumeSampler s(g, {default_mesh(), artery});
  const std::size_t nv = s.mesh(1).rest_m.size();
  std::vector<float> u(3 * nv, 0.0F);
  for (std::size_t v = 0; v < nv; ++v) u[3 * v + 1] = 0.0003F;
  s.set_displacements(1, u.data(), u.size());
  Slice sl = make_image_slice(g, 2, 0.0125);
  s.update_slice(sl);
  const std::vector<float> before = sl.values;
  const Vector3d p(0.0121, 0.0111, 0.0125);
  const Vector3d rest_before = s.to_rest(p);
  ASSERT_LT((rest_before - (p - Vector3d(0, 0.0003, 0))).norm(), 1e-6);

  const auto expect_rejected = [&](std::vector<float> bad, std::size_t count,
                                   const std::string& must_contain) {
    try {
      s.set_displacements(1, bad.data(), count);
      FAIL() << "accepted: " << must_contain;
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("'artery'"), std::string::npos) << what;
      EXPECT_NE(what.find(must_contain), std::string::npos) << what;
    }
    EXPECT_EQ(s.to_rest(p), rest_before);
    EXPECT_EQ(s.displacements(1)[7].y(), static_cast<double>(0.0003F));
    EXPECT_EQ(s.update_slice(sl).samples_recomputed, 0U);
    EXPECT_EQ(sl.values, before);
  };
  std::vector<float> bad(3 * nv, 0.001F);
  bad[3 * 7 + 2] = std::numeric_limits<float>::quiet_NaN();
  expect_rejected(bad, bad.size(), "vertex 7");
  bad[3 * 7 + 2] = 0.0F;
  bad[3 * 12] = -std::numeric_limits<float>::infinity();
  expect_rejected(bad, bad.size(), "vertex 12");
  expect_rejected(std::vector<float>(3 * nv - 1, 0.0F), 3 * nv - 1, std::to_string(3 * nv));
  expect_rejected(std::vector<float>(nv, 0.0F), nv, "floats");
  // Vector form and mesh index.
  std::vector<Vector3d> vb(nv, Vector3d::Zero());
  vb[3].x() = std::nan("");
  EXPECT_THROW(s.set_displacements(1, vb), std::invalid_argument);
  EXPECT_THROW(s.set_displacements(1, std::vector<Vector3d>(nv + 1)), std::invalid_argument);
  EXPECT_THROW(s.set_displacements(2, u.data(), u.size()), std::invalid_argument);
  EXPECT_THROW(s.set_displacements(1, nullptr, u.size()), std::invalid_argument);
  EXPECT_EQ(s.to_rest(p), rest_before);
}

// All values finite and within the image's range (a rest point is a convex combination of rest
// vertices, or the point itself).
void expect_finite_and_bounded(DeformedVolumeSampler& s, const ImageGrid& g) {
  const auto [lo_it, hi_it] = std::minmax_element(g.values.begin(), g.values.end());
  const float lo = std::min(*lo_it, 0.0F), hi = std::max(*hi_it, 0.0F);
  std::vector<Slice> slices = some_slices(g);
  for (Slice& sl : slices) {
    s.update_slice(sl);
    for (float v : sl.values) {
      ASSERT_TRUE(std::isfinite(v));
      ASSERT_GE(v, lo);
      ASSERT_LE(v, hi);
    }
  }
  ImageGrid vol;
  s.update_volume(vol);
  for (float v : vol.values) {
    ASSERT_TRUE(std::isfinite(v));
    ASSERT_GE(v, lo);
    ASSERT_LE(v, hi);
  }
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-0.01, 0.04);
  for (int n = 0; n < 5000; ++n) {
    const Vector3d p(u(rng), u(rng), u(rng));
    ASSERT_TRUE(s.to_rest(p).allFinite());
    const float v = s.sample(p);
    ASSERT_TRUE(std::isfinite(v));
  }
}

TEST(resample_sampler, InvertedDegenerateAndHugeDeformationsStayFinite) {
  const ImageGrid g = random_image();
  const MeshGeometry mesh = default_mesh();
  DeformedVolumeSampler s(g, {mesh});
  // An interior vertex pushed through its neighbours (inverts the tetrahedra around it).
  const int centre = 2 + 6 * (2 + 6 * 2);  // vertex (2, 2, 2) of the 6^3 grid
  std::vector<Vector3d> u(mesh.rest_m.size(), Vector3d::Zero());
  u[centre] = Vector3d(0.0045, 0.004, -0.0035);
  s.set_displacements(0, u);
  int inverted = 0;
  for (const auto& t : mesh.tets) {
    Vector3d y[4];
    for (int c = 0; c < 4; ++c) y[c] = mesh.rest_m[t[c]] + u[t[c]];
    if (signed_volume(y[0], y[1], y[2], y[3]) < 0) ++inverted;
  }
  EXPECT_GT(inverted, 0) << "the push did not invert anything: the test checks nothing";
  expect_finite_and_bounded(s, g);
  // A tetrahedron collapsed onto a plane: a vertex on the opposite face.
  const auto& t = mesh.tets[100];
  u.assign(mesh.rest_m.size(), Vector3d::Zero());
  u[t[0]] = (mesh.rest_m[t[1]] + mesh.rest_m[t[2]] + mesh.rest_m[t[3]]) / 3.0 - mesh.rest_m[t[0]];
  s.set_displacements(0, u);
  expect_finite_and_bounded(s, g);
  // Huge displacements (1 km, and near float's limit) on some vertices.
  u.assign(mesh.rest_m.size(), Vector3d::Zero());
  u[centre] = Vector3d(1000.0, -2000.0, 500.0);
  u[5] = Vector3d(3e38, -3e38, 3e38);
  std::vector<float> uf;
  for (const Vector3d& x : u)
    for (int a = 0; a < 3; ++a) uf.push_back(static_cast<float>(x[a]));
  s.set_displacements(0, uf.data(), uf.size());
  expect_finite_and_bounded(s, g);
  // Everything collapsed to one point.
  for (std::size_t v = 0; v < u.size(); ++v) u[v] = Vector3d(0.01, 0.01, 0.01) - mesh.rest_m[v];
  s.set_displacements(0, u);
  expect_finite_and_bounded(s, g);
  // And back: exact again.
  s.set_displacements(0, std::vector<Vector3d>(mesh.rest_m.size(), Vector3d::Zero()));
  expect_image_reproduced(s, g);
}

// Slices and the volume are rasterized tetrahedron by tetrahedron; sample() searches point by
// point. Both must pick the same tetrahedron everywhere: two overlapping meshes, a push that
// inverts elements, and every pixel and voxel compared bit for bit.
TEST(resample_sampler, SlicesAndVolumeEqualPointwiseSampling) {
  const ImageGrid g = random_image(4);
  const MeshGeometry brain = default_mesh();
  MeshGeometry artery = cube_mesh("artery", Vector3d(0.0105, 0.0095, 0.0102), 3, 0.0021, 0.2, 5);
  artery.priority = 2;
  DeformedVolumeSampler s(g, {brain, artery});
  std::mt19937 rng(8);
  std::normal_distribution<double> n(0.0, 0.0004);
  std::vector<Vector3d> ub(brain.rest_m.size()), ua(artery.rest_m.size());
  for (auto& u : ub) u = Vector3d(n(rng), n(rng), n(rng));
  for (auto& u : ua) u = Vector3d(n(rng), n(rng), n(rng)) + Vector3d(0.0008, 0, 0);
  ub[2 + 6 * (2 + 6 * 2)] += Vector3d(0.004, 0.003, -0.003);  // inverts its neighbours
  s.set_displacements(0, ub);
  s.set_displacements(1, ua);
  std::size_t mismatches = 0, in_mesh = 0;
  std::vector<Slice> slices = some_slices(g);
  // And one off the image grid: finer, shifted, between voxel planes.
  Slice off;
  off.axis = 1;
  off.position_m = 0.01237;
  off.width = 61;
  off.height = 47;
  off.origin_m = Vector3d(0.00411, 0.0, 0.00533);
  off.spacing_m = Eigen::Vector2d(0.00037, 0.00041);
  slices.push_back(off);
  for (Slice& sl : slices) {
    s.update_slice(sl);
    for (int b = 0; b < sl.height; ++b)
      for (int a = 0; a < sl.width; ++a) {
        const Vector3d p = pixel_point(sl, a, b);
        in_mesh += s.locate(p).mesh >= 0;
        mismatches += sl.values[a + sl.width * b] != s.sample(p);
      }
  }
  ImageGrid vol;
  s.update_volume(vol);
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Vector3d p = g.origin_m + g.spacing_m.cwiseProduct(Vector3d(i, j, k));
        in_mesh += s.locate(p).mesh >= 0;
        mismatches += vol.values[g.index(i, j, k)] != s.sample(p);
      }
  EXPECT_EQ(mismatches, 0U);
  EXPECT_GT(in_mesh, 3000U);
}

// Tetrahedra moved far outside their search grid's domain are still found (the big list).
TEST(resample_sampler, MeshTranslatedFarAwayIsStillFound) {
  const MeshGeometry mesh = default_mesh();
  DeformedVolumeSampler s(random_image(), {mesh});
  const Vector3d far(0.35, -0.2, 0.1);
  s.set_displacements(0, std::vector<Vector3d>(mesh.rest_m.size(), far));
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0065, 0.0185);
  for (int n = 0; n < 500; ++n) {
    const Vector3d x(u(rng), u(rng) - 0.001, u(rng));
    const Location l = s.locate(x + far);
    ASSERT_EQ(l.mesh, 0);
    ASSERT_LT((l.rest_m - x).norm(), 1e-12);
    ASSERT_EQ(s.to_rest(x), x);  // the rest place is empty now
  }
  // And back into the grid.
  s.set_displacements(0, std::vector<Vector3d>(mesh.rest_m.size(), Vector3d(1e-4, 0, 0)));
  const Vector3d x(0.012, 0.011, 0.013);
  EXPECT_LT((s.to_rest(x + Vector3d(1e-4, 0, 0)) - x).norm(), 1e-12);
}

TEST(resample_sampler, PointsOnSharedFacesPickTheLowestIndexTetrahedron) {
  const MeshGeometry mesh = default_mesh();
  DeformedVolumeSampler s(random_image(), {mesh});
  s.set_displacements(0,
                      affine_displacement(mesh, Matrix3d::Identity() * 0.02, Vector3d(1e-4, 0, 0)));
  // Every interior face: its centroid lies in both tetrahedra (within rounding).
  std::map<std::array<int, 3>, std::vector<int>> faces;
  for (std::size_t t = 0; t < mesh.tets.size(); ++t)
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> f{};
      for (int c = 0, n = 0; c < 4; ++c)
        if (c != k) f[n++] = mesh.tets[t][c];
      std::sort(f.begin(), f.end());
      faces[f].push_back(static_cast<int>(t));
    }
  const auto& u = s.displacements(0);
  int shared = 0;
  for (const auto& [f, ts] : faces) {
    if (ts.size() != 2) continue;
    ++shared;
    Vector3d y = Vector3d::Zero(), x = Vector3d::Zero();
    for (int v : f) {
      y += (mesh.rest_m[v] + u[v]) / 3.0;
      x += mesh.rest_m[v] / 3.0;
    }
    const Location l = s.locate(y);
    ASSERT_EQ(l.tet, std::min(ts[0], ts[1]));
    ASSERT_LT((l.rest_m - x).norm(), 1e-12);
  }
  EXPECT_GT(shared, 1000);
}

// The scene's meshes (scenes/brain_artery/*.mesh, Medit, mm): vertices and tetrahedra only,
// enough for these tests (the test links the resampler alone, not the mesh library).
MeshGeometry read_medit_tets(const std::filesystem::path& path, const std::string& id,
                             int priority) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot open");
  MeshGeometry m;
  m.id = id;
  m.priority = priority;
  std::string word;
  while (in >> word) {
    if (word == "Vertices") {
      std::size_t n = 0;
      in >> n;
      m.rest_m.resize(n);
      for (auto& v : m.rest_m) {
        int ref = 0;
        in >> v.x() >> v.y() >> v.z() >> ref;
        v *= 1e-3;
      }
    } else if (word == "Tetrahedra") {
      std::size_t n = 0;
      in >> n;
      m.tets.resize(n);
      for (auto& t : m.tets) {
        int ref = 0;
        in >> t[0] >> t[1] >> t[2] >> t[3] >> ref;
        for (int& v : t) --v;
      }
    }
  }
  if (!in.eof() || m.tets.empty()) throw std::runtime_error(path.string() + ": not read");
  return m;
}

// The brain/artery model on a random image covering the MRI's extent at 2 mm: zero
// displacement is exact, a tool push gives finite values, slices and the volume agree with the
// point search, and an incremental update equals a full one.
TEST(resample_model, BrainAndArteryMeshes) {
  const auto dir = neurosim::testing::source_dir() / "scenes" / "brain_artery";
  if (!std::filesystem::exists(dir / "brain.mesh")) GTEST_SKIP() << "no " << dir;
  const MeshGeometry brain = read_medit_tets(dir / "brain.mesh", "brain", 0);
  const MeshGeometry artery = read_medit_tets(dir / "artery.mesh", "artery", 1);
  ASSERT_GT(brain.tets.size(), 20000U);
  ASSERT_GT(artery.tets.size(), 4000U);
  ImageGrid g;
  g.dims = {91, 109, 91};
  g.spacing_m = Vector3d::Constant(0.002);
  g.values.resize(static_cast<std::size_t>(91) * 109 * 91);
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> d(0.0F, 255.0F);
  for (float& v : g.values) v = d(rng);
  // Tolerance 0: every change is reported, so the incremental result must be exact.
  SamplerOptions exact;
  exact.move_tolerance_m = 0.0;
  DeformedVolumeSampler s(g, {brain, artery}, exact);
  expect_image_reproduced(s, g);

  // Tool: the lateral surface (largest x near y = 115, z = 79 mm), pushed 3 mm inward.
  Vector3d tip = brain.rest_m[0];
  for (const Vector3d& x : brain.rest_m)
    if (x.x() - 4 * std::hypot(x.y() - 0.115, x.z() - 0.079) >
        tip.x() - 4 * std::hypot(tip.y() - 0.115, tip.z() - 0.079))
      tip = x;
  const auto push = [&tip](const MeshGeometry& m, double amp) {
    std::vector<Vector3d> u(m.rest_m.size());
    // Cut at 1e-3: no motion below the move tolerance, so incremental == full exactly.
    for (std::size_t v = 0; v < u.size(); ++v) {
      const double w = std::exp(-(m.rest_m[v] - tip).squaredNorm() / (2 * 0.005 * 0.005));
      u[v] = Vector3d(w > 1e-3 ? -amp * w : 0.0, 0, 0);
    }
    return u;
  };
  std::vector<Slice> slices;
  for (int axis = 0; axis < 3; ++axis) slices.push_back(make_image_slice(g, axis, tip[axis]));
  for (Slice& sl : slices) s.update_slice(sl);
  ImageGrid vol;
  s.update_volume(vol);
  for (double amp : {0.001, 0.003}) {
    s.set_displacements(0, push(brain, amp));
    s.set_displacements(1, push(artery, amp));
    std::size_t recomputed = 0, changed = 0;
    for (Slice& sl : slices) recomputed += s.update_slice(sl).samples_recomputed;
    EXPECT_GT(recomputed, 0U);
    EXPECT_LT(recomputed, 3U * 109 * 91 / 4);
    s.update_volume(vol);
    expect_equal_to_full(s, slices, vol);
    for (const Slice& sl : slices)
      for (int b = 0; b < sl.height; ++b)
        for (int a = 0; a < sl.width; ++a) {
          const float v = sl.values[a + sl.width * b];
          ASSERT_TRUE(std::isfinite(v));
          ASSERT_EQ(v, s.sample(pixel_point(sl, a, b)));
          const auto ijk = pixel_voxel(g, sl, a, b);
          changed += v != g.values[g.index(ijk[0], ijk[1], ijk[2])];
        }
    EXPECT_GT(changed, 10U);  // the push shows
  }
  // The whole volume against the point search.
  std::size_t mismatches = 0;
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Vector3d p = g.origin_m + g.spacing_m.cwiseProduct(Vector3d(i, j, k));
        mismatches += vol.values[g.index(i, j, k)] != s.sample(p);
      }
  EXPECT_EQ(mismatches, 0U);
}

}  // namespace
