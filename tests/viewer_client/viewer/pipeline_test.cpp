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
