// .vtu writer: well-formed XML, exact round trip, bad input refused.
#include "server/mesh/vtu.hpp"

#include "tests/server/mesh/mesh_fixtures.hpp"
#include "tests/test_support.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>

namespace neurosim::mesh {
namespace {

namespace fs = std::filesystem;

class MeshVtu : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = neurosim::testing::temp_dir("mesh_vtu"); }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

// Parses the file with Python's XML parser and checks the VTK structure it needs.
void expect_valid_xml(const std::string& file, int points, int cells) {
  if (std::system("python3 -c 'import xml.dom.minidom' >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "python3 not available";
  std::ostringstream cmd;
  cmd << "python3 -c \"import sys, xml.dom.minidom as m\n"
         "d = m.parse(sys.argv[1]); p = d.getElementsByTagName('Piece')[0]\n"
         "assert d.documentElement.getAttribute('type') == 'UnstructuredGrid'\n"
         "assert p.getAttribute('NumberOfPoints') == sys.argv[2], 'points'\n"
         "assert p.getAttribute('NumberOfCells') == sys.argv[3], 'cells'\n"
         "for a in d.getElementsByTagName('DataArray'):\n"
         "    n = len(a.firstChild.data.split()) if a.firstChild else 0\n"
         "    assert n > 0, a.getAttribute('Name')\n"
         "\" '"
      << file << "' " << points << ' ' << cells;
  EXPECT_EQ(std::system(cmd.str().c_str()), 0) << cmd.str();
}

TEST_F(MeshVtu, TetMeshWithFieldsRoundTrip) {
  auto g = testing::grid_cube(2, 0.1);
  TetMesh mesh = TetMesh::build(g.vertices, g.tets);
  std::vector<int> labels(mesh.num_tets());
  for (std::size_t t = 0; t < labels.size(); ++t) labels[t] = int(t % 4);
  mesh.set_tet_labels(labels);
  std::vector<Vec3> u(mesh.num_vertices());
  std::vector<double> s(mesh.num_vertices());
  for (std::size_t i = 0; i < u.size(); ++i) {
    u[i] = mesh.vertices()[i] * (1.0 / 3.0) + Vec3(1e-300, -2.5e-7, 0.1);
    s[i] = std::sqrt(double(i));
  }
  std::vector<double> vol(mesh.num_tets());
  for (std::size_t t = 0; t < vol.size(); ++t) vol[t] = mesh.tet_volume(int(t));
  const std::string file = path("result.vtu");
  write_vtu(file, mesh, {make_field("displacement_m", u), make_field("stress<Pa>", s)},
            {make_field("volume_m3", vol)});
  expect_valid_xml(file, int(mesh.num_vertices()), int(mesh.num_tets()));

  const VtuData r = read_vtu(file);
  EXPECT_EQ(r.points_m, mesh.vertices());
  EXPECT_EQ(r.tets, mesh.tets());
  EXPECT_TRUE(r.triangles.empty());
  ASSERT_NE(r.point_field("displacement_m"), nullptr);
  EXPECT_EQ(r.point_field("displacement_m")->components, 3);
  EXPECT_EQ(r.point_field("displacement_m")->values, make_field("", u).values);
  ASSERT_NE(r.point_field("stress<Pa>"), nullptr);  // escaped and unescaped
  EXPECT_EQ(r.point_field("stress<Pa>")->values, s);
  ASSERT_NE(r.cell_field("volume_m3"), nullptr);
  EXPECT_EQ(r.cell_field("volume_m3")->values, vol);
  ASSERT_NE(r.cell_field("label"), nullptr);
  EXPECT_EQ(r.cell_field("label")->values, make_field("", labels).values);
  EXPECT_EQ(r.point_field("missing"), nullptr);
}

TEST_F(MeshVtu, SurfaceTriangles) {
  auto g = testing::grid_cube(1, 1.0);
  const TetMesh mesh = TetMesh::build(g.vertices, g.tets);
  std::vector<Vec3> normals;
  for (const Tri& t : mesh.surface()) {
    const auto& v = mesh.vertices();
    normals.push_back((v[t[1]] - v[t[0]]).cross(v[t[2]] - v[t[0]]).normalized());
  }
  const std::string file = path("surface.vtu");
  write_vtu(file, mesh.vertices(), mesh.surface(), {}, {make_field("normal", normals)});
  expect_valid_xml(file, 8, 12);
  const VtuData r = read_vtu(file);
  EXPECT_TRUE(r.tets.empty());
  EXPECT_EQ(r.triangles, mesh.surface());
  EXPECT_EQ(r.cell_field("normal")->values, make_field("", normals).values);
}

TEST_F(MeshVtu, BadInputRefused) {
  auto g = testing::grid_cube(1, 1.0);
  std::vector<double> s(8, 1.0);
  s[6] = std::numeric_limits<double>::quiet_NaN();
  try {
    write_vtu(path("nan.vtu"), g.vertices, g.tets, {make_field("pressure_Pa", s)});
    FAIL() << "NaN written";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'pressure_Pa' entry 6"), std::string::npos) << e.what();
  }
  EXPECT_THROW(write_vtu(path("size.vtu"), g.vertices, g.tets, {make_field("p", std::vector<double>(7))}),
               std::invalid_argument);
  EXPECT_THROW(write_vtu(path("cell.vtu"), g.vertices, g.tets, {}, {make_field("c", std::vector<double>(8))}),
               std::invalid_argument);
  g.tets[2][0] = 8;
  EXPECT_THROW(write_vtu(path("index.vtu"), g.vertices, g.tets), std::invalid_argument);
  EXPECT_THROW(write_vtu("/nonexistent/dir/x.vtu", g.vertices, std::vector<Tri>{}), std::runtime_error);
}

TEST_F(MeshVtu, BrokenFileNamesLine) {
  auto g = testing::grid_cube(1, 1.0);
  const std::string file = path("ok.vtu");
  write_vtu(file, g.vertices, g.tets);
  std::ifstream in(file);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto at = text.find("\n1 1 0\n");  // point 3
  ASSERT_NE(at, std::string::npos);
  ++at;
  text.replace(at, 5, "1 x 0");
  const int line = 1 + int(std::count(text.begin(), text.begin() + long(at), '\n'));
  std::ofstream(path("bad.vtu")) << text;
  try {
    read_vtu(path("bad.vtu"));
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path("bad.vtu") + ":" + std::to_string(line) + ":"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace neurosim::mesh
