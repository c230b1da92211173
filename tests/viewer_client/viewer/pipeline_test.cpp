// Viewer pipeline without a server: a missing or unreadable MRI renders the surfaces
// with a warning naming the file; the slices follow the tool; the command line's errors.
#include "viewer_client/viewer/pipeline.hpp"
#include "viewer_test_util.hpp"

#include <gtest/gtest.h>

namespace nv = neurosim::viewer;
namespace nt = neurosim::testing;
namespace fs = std::filesystem;

namespace {

// A 2 cm tetrahedron near the middle of the Colin27 image (mm coordinates x 0.001).
nv::MeshState small_mesh(const std::string& image) {
  nv::MeshState m;
  m.id = "blob";
  m.rest_m = {{0.08, 0.1, 0.07}, {0.1, 0.1, 0.07}, {0.08, 0.12, 0.07}, {0.08, 0.1, 0.09}};
  m.tets = {{0, 1, 2, 3}};
  m.surface = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  m.image_file = image;
  m.image_unit_m = 0.001;
  return m;
}

std::size_t non_background(const std::vector<std::uint8_t>& rgb) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < rgb.size(); i += 3)
    if (rgb[i] > 40 || rgb[i + 1] > 40 || rgb[i + 2] > 60) ++n;
  return n;
}

}  // namespace

TEST(ViewerPipeline, MissingImageRendersSurfacesWithAWarning) {
  nt::Xvfb x;
  for (const std::string& image :
       {std::string("/nonexistent/brain.nii.gz"), std::string(__FILE__)}) {
    SCOPED_TRACE(image);
    nv::ViewerState state;
    state.set_mesh(small_mesh(image));
    std::vector<std::string> warnings;
    nv::PipelineOptions po;
    po.render.width = 320;
    po.render.height = 240;
    nv::Pipeline pipe(po, [&](const std::string& w) { warnings.push_back(w); });
    pipe.frame(state, "test");
    EXPECT_FALSE(pipe.has_image());
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find(image), std::string::npos) << warnings[0];
    EXPECT_NE(warnings[0].find("without the MRI"), std::string::npos) << warnings[0];
    EXPECT_GT(non_background(pipe.renderer().capture()), 100u) << "the surface did not render";
  }
}

TEST(ViewerPipeline, SlicesFollowTheToolTip) {
  nt::Xvfb x;
  nv::ViewerState state;
  state.set_mesh(small_mesh("/usr/share/mricron/templates/ch2bet.nii.gz"));
  nv::PipelineOptions po;
  po.render.width = 320;
  po.render.height = 240;
  std::vector<std::string> warnings;
  nv::Pipeline pipe(po, [&](const std::string& w) { warnings.push_back(w); });
  pipe.frame(state, "");
  if (!pipe.has_image()) GTEST_SKIP() << "Colin27 MRI not installed (mricron-data)";
  nv::ToolView tool;
  tool.station = "s";
  tool.tip_m = Eigen::Vector3d(0.0904, 0.1012, 0.0795);
  tool.has_pose = true;
  state.set_tool(tool);
  pipe.frame(state, "");
  for (int a = 0; a < 3; ++a) {
    const nv::Slice& s = pipe.slices()[static_cast<std::size_t>(a)];
    EXPECT_EQ(s.axis, a);
    EXPECT_NEAR(s.position_m, tool.tip_m[a], 0.0005 + 1e-12) << "axis " << a;
    EXPECT_GT(s.width * s.height, 0);
  }
  EXPECT_TRUE(warnings.empty());
}

TEST(ViewerCommandLine, ErrorsAndNoServer) {
  const fs::path dir = nt::temp_dir("viewer_cli");
  const std::string bin = (nt::bin_dir() / "neurosim-viewer").string();
  {
    nt::Child c({bin, "--mode", "sideways"}, dir / "bad.log");
    ASSERT_TRUE(c.wait(30));
    EXPECT_EQ(WEXITSTATUS(c.status()), 2);
    // The common error style: program, option and bad value, then where the usage is.
    EXPECT_NE(c.log().find("neurosim-viewer: --mode: sideways"), std::string::npos) << c.log();
    EXPECT_NE(c.log().find("Run with --help"), std::string::npos) << c.log();
  }
  {
    nt::Xvfb x;
    nt::Child c({bin, "--mode", "observe", "--headless", "--frames", "1", "--out",
                 (dir / "frames").string(), "--wait-server", "1.5", "--topic-prefix",
                 "nobody_" + std::to_string(getpid()) + "_"},
                dir / "noserver.log");
    ASSERT_TRUE(c.wait(60));
    EXPECT_EQ(WEXITSTATUS(c.status()), 1);
    EXPECT_NE(c.log().find("no MeshTopology within 1.5 s"), std::string::npos) << c.log();
  }
  fs::remove_all(dir);
}

namespace {

// A closed rigid surface (a UV sphere of radius 35 mm, outward triangles, no tetrahedra) around
// small_mesh, smooth enough for Gouraud shading.
nv::MeshState rigid_shell(const std::string& image) {
  nv::MeshState m;
  m.id = "skull";
  m.rigid = true;
  const Eigen::Vector3d c(0.09, 0.11, 0.08);
  constexpr double kR = 0.035;
  constexpr int kRings = 12, kSegments = 24;
  m.rest_m.push_back(c + Eigen::Vector3d(0, 0, kR));  // north pole 0
  for (int i = 1; i < kRings; ++i)
    for (int j = 0; j < kSegments; ++j) {
      const double th = M_PI * i / kRings, ph = 2 * M_PI * j / kSegments;
      m.rest_m.push_back(c + kR * Eigen::Vector3d(std::sin(th) * std::cos(ph),
                                                  std::sin(th) * std::sin(ph), std::cos(th)));
    }
  const int south = static_cast<int>(m.rest_m.size());
  m.rest_m.push_back(c - Eigen::Vector3d(0, 0, kR));
  auto at = [](int ring, int seg) { return 1 + (ring - 1) * kSegments + seg % kSegments; };
  for (int j = 0; j < kSegments; ++j) {
    m.surface.push_back({0, at(1, j), at(1, j + 1)});
    m.surface.push_back({south, at(kRings - 1, j + 1), at(kRings - 1, j)});
    for (int i = 1; i + 1 < kRings; ++i) {
      m.surface.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.surface.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  }
  m.image_file = image;
  m.image_unit_m = 0.001;
  return m;
}

// Pixels of the bone colour (0.89, 0.85, 0.72) lit: bright, R >= G > B, little red excess.
std::size_t bone_pixels(const std::vector<std::uint8_t>& rgb) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < rgb.size(); i += 3) {
    const int r = rgb[i], g = rgb[i + 1], b = rgb[i + 2];
    if (r > 90 && g > 85 && b > 60 && r >= g && g > b && r - g < r / 8 && g - b > g / 12) ++n;
  }
  return n;
}

std::vector<std::uint8_t> render_skull(const std::string& image, nv::SkullMode mode,
                                       bool* had_image = nullptr) {
  nv::ViewerState state;
  state.set_mesh(rigid_shell(image));
  nv::PipelineOptions po;
  po.render.width = 320;
  po.render.height = 240;
  po.render.overlay = false;
  po.render.skull = mode;
  nv::Pipeline pipe(po, {});
  pipe.frame(state, "");
  if (had_image != nullptr) *had_image = pipe.has_image();
  return pipe.renderer().capture();
}

}  // namespace

TEST(ViewerPipeline, SkullShownTransparentHidden) {
  nt::Xvfb x;
  const std::size_t shown = bone_pixels(render_skull("/nonexistent.nii.gz", nv::SkullMode::Shown));
  const std::size_t transparent =
      bone_pixels(render_skull("/nonexistent.nii.gz", nv::SkullMode::Transparent));
  const std::size_t hidden =
      bone_pixels(render_skull("/nonexistent.nii.gz", nv::SkullMode::Hidden));
  EXPECT_GT(shown, 2000u) << "the opaque skull is not bone-coloured";
  EXPECT_LT(transparent, shown * 9 / 10) << "the transparent skull is as solid as the shown one";
  EXPECT_EQ(hidden, 0u) << "the hidden skull was drawn";
}

TEST(ViewerPipeline, SkullIsNotResampledAndCutsTheSlices) {
  nt::Xvfb x;
  // With the MRI: the rigid mesh (no tetrahedra) stays out of the resampler (no warning), and
  // its contours on the 2D slices are bone-coloured lines only when the skull is not hidden.
  nv::ViewerState state;
  state.set_mesh(small_mesh("/usr/share/mricron/templates/ch2bet.nii.gz"));
  state.set_mesh(rigid_shell("/usr/share/mricron/templates/ch2bet.nii.gz"));
  std::vector<std::string> warnings;
  nv::PipelineOptions po;
  po.render.width = 480;
  po.render.height = 360;
  po.render.overlay = false;
  nv::Pipeline pipe(po, [&](const std::string& w) { warnings.push_back(w); });
  pipe.frame(state, "");
  if (!pipe.has_image()) GTEST_SKIP() << "Colin27 MRI not installed (mricron-data)";
  EXPECT_TRUE(warnings.empty()) << warnings.front();
  // Bone pixels in the 2D views (every viewport but the 3D one at the top left).
  auto bone_in_2d = [&](const std::vector<std::uint8_t>& rgb) {
    std::vector<std::uint8_t> part;
    const int w = pipe.renderer().width(), h = pipe.renderer().height();
    for (int y = 0; y < h; ++y)
      for (int xx = 0; xx < w; ++xx)
        if (!(xx < w / 2 && y >= h / 2))
          for (int k = 0; k < 3; ++k)
            part.push_back(rgb[3 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                                    static_cast<std::size_t>(xx)) +
                               static_cast<std::size_t>(k)]);
    return bone_pixels(part);
  };
  const std::size_t with = bone_in_2d(pipe.renderer().capture());
  pipe.renderer().set_skull(nv::SkullMode::Hidden);
  pipe.frame(state, "");
  const std::size_t without = bone_in_2d(pipe.renderer().capture());
  EXPECT_GT(with, without + 50) << "no skull contour on the slices";
}

TEST(ViewerPipeline, RegionColours) {
  nt::Xvfb x;
  // Two tetrahedra of different regions: --colour region shows the second region's colour
  // (blue), plain does not.
  auto render = [](nv::ColourMode mode) {
    nv::ViewerState state;
    nv::MeshState m = small_mesh("/nonexistent.nii.gz");
    m.rest_m.push_back({0.1, 0.12, 0.09});
    m.tets.push_back({4, 1, 3, 2});
    m.surface = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {4, 2, 1}, {4, 1, 3}, {4, 3, 2}};
    m.tet_region = {0, 1};
    m.region_names = {"cerebrum", "cerebellum"};
    state.set_mesh(m);
    nv::PipelineOptions po;
    po.render.width = 320;
    po.render.height = 240;
    po.render.overlay = false;
    po.render.colour = mode;
    nv::Pipeline pipe(po, {});
    pipe.frame(state, "");
    std::size_t blue = 0;
    const auto rgb = pipe.renderer().capture();
    for (std::size_t i = 0; i < rgb.size(); i += 3)
      if (rgb[i + 2] > 70 && rgb[i + 2] > rgb[i] + 30) ++blue;
    return blue;
  };
  EXPECT_GT(render(nv::ColourMode::Region), 200u);
  EXPECT_EQ(render(nv::ColourMode::Plain), 0u);
}
