// Mesh file readers (Medit, Gmsh v2/v4, TetGen) and writers: the same cube in every format,
// round trips, and broken files reported with file name and line.
#include "server/mesh/io.hpp"

#include "tests/server/mesh/mesh_fixtures.hpp"
#include "tests/test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

namespace neurosim::mesh {
namespace {

namespace fs = std::filesystem;
using neurosim::testing::slurp;

std::string data(const std::string& name) {
  return (neurosim::testing::source_dir() / "tests/data/mesh" / name).string();
}


void spit(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

// The cube the data files hold: side 2 (mm), vertex i at 2*(i&1, i>>1&1, i>>2&1).
const std::vector<Tet> kCubeTets{{0, 1, 3, 7}, {0, 1, 7, 5}, {0, 2, 7, 3},
                                 {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 7, 6}};

void expect_cube(const std::vector<Vec3>& v, const std::vector<Tet>& tets, double unit_m,
                 int offset = 0) {
  ASSERT_EQ(tets.size(), 6u);
  for (int i = 0; i < 8; ++i)
    EXPECT_EQ(v[i + offset], Vec3(2 * (i & 1), 2 * ((i >> 1) & 1), 2 * ((i >> 2) & 1)) * unit_m)
        << "vertex " << i;
  for (int t = 0; t < 6; ++t)
    for (int k = 0; k < 4; ++k) EXPECT_EQ(tets[t][k], kCubeTets[t][k] + offset);
}

// The message of the runtime_error a read throws.
template <class F>
std::string read_error(F&& read) {
  try {
    read();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "no exception";
}

// Replaces the text of line `line` (1-based) and returns the new file.
std::string with_line(const std::string& text, int line, const std::string& replacement) {
  std::istringstream in(text);
  std::string out, l;
  for (int n = 1; std::getline(in, l); ++n) out += (n == line ? replacement : l) + "\n";
  return out;
}
std::string first_lines(const std::string& text, int lines) {
  std::istringstream in(text);
  std::string out, l;
  for (int n = 0; n < lines && std::getline(in, l); ++n) out += l + "\n";
  return out;
}
int line_of(const std::string& text, const std::string& content) {
  std::istringstream in(text);
  std::string l;
  for (int n = 1; std::getline(in, l); ++n)
    if (l == content) return n;
  return -1;
}

TEST(MeshIo, MeditCube) {
  const MeshData m = read_medit(data("cube.mesh"), 1e-3);
  ASSERT_EQ(m.vertices_m.size(), 9u);  // vertex 1 is unused
  expect_cube(m.vertices_m, m.tets, 1e-3, 1);
  EXPECT_EQ(m.tet_labels, (std::vector<int>{1, 1, 1, 2, 2, 2}));
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[1], (Tri{1, 4, 2}));
  EXPECT_EQ(m.triangle_labels, (std::vector<int>{7, 7}));

  ::testing::internal::CaptureStderr();
  const TetMesh t = load_tet_mesh(data("cube.mesh"), 1e-3);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
  EXPECT_EQ(t.num_vertices(), 8u);
  EXPECT_EQ(t.source_vertex_ids()[0], 1);
  EXPECT_EQ(t.tet_labels(), m.tet_labels);
  EXPECT_EQ(t.inverted_fixed(), 0);
  EXPECT_EQ(t.source(), data("cube.mesh"));
  EXPECT_NEAR(testing::enclosed_volume(t.vertices(), t.surface()), 8e-9, 1e-22);
}

TEST(MeshIo, MeditFromCgal) {
  const MeshData d = read_medit(data("cgal_ball.mesh"));
  ::testing::internal::CaptureStderr();
  const TetMesh m = load_tet_mesh(data("cgal_ball.mesh"));
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");  // CGAL cells are positive
  EXPECT_EQ(m.num_tets(), 187u);
  // CGAL lists each boundary facet in both orientations; ours has each once, outward.
  EXPECT_EQ(2 * m.surface().size(), d.triangles.size());
  std::set<std::array<int, 3>> file_faces;
  for (const Tri& t : d.triangles) file_faces.insert({t[0], t[1], t[2]});
  for (const Tri& t : m.surface()) {
    const int a = m.source_vertex_ids()[t[0]], b = m.source_vertex_ids()[t[1]],
              c = m.source_vertex_ids()[t[2]];
    EXPECT_TRUE(file_faces.count({a, b, c}) || file_faces.count({b, c, a}) || file_faces.count({c, a, b}))
        << "surface face not in CGAL's list";
  }
  double volume = 0.0;
  for (std::size_t t = 0; t < m.num_tets(); ++t) volume += m.tet_volume(int(t));
  EXPECT_NEAR(testing::enclosed_volume(m.vertices(), m.surface()), volume, 1e-9 * volume);
  EXPECT_GT(volume, 0.8 * 4.0 / 3.0 * std::acos(-1.0) * 1000.0);  // inscribed in the radius-10 ball
  EXPECT_LT(volume, 4.0 / 3.0 * std::acos(-1.0) * 1000.0);
}

TEST(MeshIo, GmshV2Cube) {
  const MeshData m = read_gmsh(data("cube_v2.msh"), 1e-3);
  expect_cube(m.vertices_m, m.tets, 1e-3);
  EXPECT_EQ(m.tet_labels, (std::vector<int>{1, 1, 1, 2, 2, 2}));  // physical tags
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangles[0], (Tri{0, 1, 3}));
  EXPECT_EQ(m.triangle_labels[0], 5);  // no physical tag: elementary
}

TEST(MeshIo, GmshV41Cube) {
  const MeshData m = read_gmsh(data("cube_v41.msh"), 1e-3);
  expect_cube(m.vertices_m, m.tets, 1e-3);
  EXPECT_EQ(m.tet_labels, (std::vector<int>{1, 1, 1, 2, 2, 2}));  // physical tags of volumes 7, 8
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangle_labels[0], 5);  // surface entity 5 has no physical tag
}

TEST(MeshIo, GmshV40Cube) {
  const MeshData m = read_mesh(data("cube_v40.msh"), 1e-3);
  expect_cube(m.vertices_m, m.tets, 1e-3);
  EXPECT_EQ(m.tet_labels, (std::vector<int>{1, 1, 1, 2, 2, 2}));  // entity tags
}

TEST(MeshIo, TetgenZeroBasedCube) {
  for (const char* name : {"cube0.node", "cube0.ele", "cube0"}) {
    const MeshData m = read_tetgen(data(name), 1e-3);
    expect_cube(m.vertices_m, m.tets, 1e-3);
    EXPECT_EQ(m.tet_labels, (std::vector<int>{1, 1, 1, 2, 2, 2}));
  }
}

TEST(MeshIo, TetgenRealOutput) {
  ::testing::internal::CaptureStderr();
  const TetMesh m = load_tet_mesh(data("box.1.ele"));
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");  // TetGen's orientation is ours
  EXPECT_EQ(m.inverted_fixed(), 0);
  EXPECT_EQ(m.num_vertices(), 50u);
  EXPECT_EQ(m.num_tets(), 68u);
  for (int label : m.tet_labels()) EXPECT_EQ(label, 7);
  EXPECT_NEAR(testing::enclosed_volume(m.vertices(), m.surface()), 1.0, 1e-12);
  double sum = 0.0;
  for (std::size_t t = 0; t < m.num_tets(); ++t) sum += m.tet_volume(int(t));
  EXPECT_NEAR(sum, 1.0, 1e-12);
}

TEST(MeshIo, AllFormatsAgree) {
  const TetMesh a = load_tet_mesh(data("cube.mesh"));
  for (const char* name : {"cube_v2.msh", "cube_v41.msh", "cube0.node"}) {
    const TetMesh b = load_tet_mesh(data(name));
    EXPECT_EQ(a.vertices(), b.vertices()) << name;
    EXPECT_EQ(a.tets(), b.tets()) << name;
    EXPECT_EQ(a.surface(), b.surface()) << name;
    EXPECT_EQ(a.tet_labels(), b.tet_labels()) << name;
  }
}

TEST(MeshIo, MeditRoundTrip) {
  const auto dir = neurosim::testing::temp_dir("mesh_io");
  auto g = testing::grid_cube(3, 0.1 / 3.0);  // non-representable coordinates on purpose
  MeshData d;
  d.vertices_m = g.vertices;
  d.tets = g.tets;
  for (std::size_t t = 0; t < d.tets.size(); ++t) d.tet_labels.push_back(int(t % 3) + 1);
  d.triangles = {{0, 1, 2}};
  d.triangle_labels = {4};
  const std::string path = (dir / "grid.mesh").string();
  write_medit(path, d, 1e-3);
  const MeshData r = read_medit(path, 1e-3);
  ASSERT_EQ(r.vertices_m.size(), d.vertices_m.size());
  for (std::size_t i = 0; i < d.vertices_m.size(); ++i)
    EXPECT_NEAR((r.vertices_m[i] - d.vertices_m[i]).norm(), 0.0, 1e-16);  // mm -> m rounding
  EXPECT_EQ(r.tets, d.tets);
  EXPECT_EQ(r.tet_labels, d.tet_labels);
  EXPECT_EQ(r.triangles, d.triangles);
  EXPECT_EQ(r.triangle_labels, d.triangle_labels);
  fs::remove_all(dir);
}

TEST(MeshIo, TetgenRoundTrip) {
  const auto dir = neurosim::testing::temp_dir("mesh_io");
  auto g = testing::grid_cube(2, 0.7);
  const TetMesh mesh = TetMesh::build(g.vertices, g.tets);
  MeshData d = to_mesh_data(mesh);
  d.tet_labels.assign(d.tets.size(), 3);
  d.tet_labels[5] = -2;
  const std::string stem = (dir / "grid").string();
  write_tetgen(stem, d);
  const MeshData r = read_mesh(stem + ".node");
  EXPECT_EQ(r.vertices_m, d.vertices_m);  // shortest round-trip formatting is exact
  EXPECT_EQ(r.tets, d.tets);
  EXPECT_EQ(r.tet_labels, d.tet_labels);
  fs::remove_all(dir);
}

// Broken files: each error names the file and the line where reading failed.
class MeshIoBroken : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = neurosim::testing::temp_dir("mesh_broken"); }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    spit(path, text);
    return path;
  }
  void expect_error(const std::string& path, int line, const std::string& what) {
    const std::string e = read_error([&] { read_mesh(path); });
    EXPECT_NE(e.find(path + ":" + std::to_string(line) + ":"), std::string::npos)
        << "expected line " << line << ": " << e;
    EXPECT_NE(e.find(what), std::string::npos) << e;
  }
  fs::path dir_;
};

TEST_F(MeshIoBroken, Medit) {
  const std::string good = slurp(data("cube.mesh"));
  const int tet3 = line_of(good, "2 4 9 5 1");  // tetrahedron 3 (1-based) of the file
  ASSERT_GT(tet3, 0);
  expect_error(write("short.mesh", with_line(good, tet3, "2 4 9 1")), tet3, "expected 4 vertex indices");
  expect_error(write("number.mesh", with_line(good, tet3, "2 4 9x 5 1")), tet3, "'9x'");
  expect_error(write("index.mesh", with_line(good, tet3, "2 4 10 5 1")), tet3, "vertex index 10 out of range 1..9");
  expect_error(write("zero.mesh", with_line(good, tet3, "2 0 9 5 1")), tet3, "out of range");
  const int v4 = line_of(good, "0 2 0 0");
  expect_error(write("coord.mesh", with_line(good, v4, "0 nan 0 0")), v4, "finite coordinate");
  // Truncated inside the tetrahedra: reported at the last line, saying what was expected.
  expect_error(write("cut.mesh", first_lines(good, tet3)), tet3, "unexpected end of file");
  expect_error(write("cut.mesh", first_lines(good, tet3)), tet3, "tetrahedron 4 of 6");
  expect_error(write("key.mesh", with_line(good, 2, "Bogus 3")), 2, "unknown Medit keyword 'Bogus'");
  // A second Vertices section after the tetrahedra would leave their indices out of range
  // (found by fuzz/medit_fuzz.cpp).
  const std::string again = "Vertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\nEnd\n";
  expect_error(write("twice.mesh", first_lines(good, line_of(good, "Corners") - 1) + again),
               line_of(good, "Corners"), "second Vertices section");
  expect_error(write("empty.mesh", ""), 1, "not a Medit");
}

TEST_F(MeshIoBroken, GmshV2) {
  const std::string good = slurp(data("cube_v2.msh"));
  const int e6 = line_of(good, "6 4 2 1 7 11 13 18 14");
  ASSERT_GT(e6, 0);
  expect_error(write("short.msh", with_line(good, e6, "6 4 2 1 7 11 13 18")), e6, "expected 4 node tags");
  expect_error(write("tag.msh", with_line(good, e6, "6 4 2 1 7 11 13 99 14")), e6, "node tag 99 is not in $Nodes");
  expect_error(write("num.msh", with_line(good, e6, "6 4 2 1 7 11 1.5 18 14")), e6, "'1.5'");
  const int n3 = line_of(good, "13 0 2 0");
  expect_error(write("coord.msh", with_line(good, n3, "13 0 2.0.0 0")), n3, "y coordinate");
  expect_error(write("cut.msh", first_lines(good, e6)), e6, "unexpected end of file");
  expect_error(write("bin.msh", with_line(good, 2, "2.2 1 8")), 2, "binary");
}

TEST_F(MeshIoBroken, GmshV41) {
  const std::string good = slurp(data("cube_v41.msh"));
  const int e4 = line_of(good, "4 101 102 108 106 ");
  ASSERT_GT(e4, 0);
  expect_error(write("short.msh", with_line(good, e4, "4 101 102 108")), e4, "expected 4 node tags");
  expect_error(write("tag.msh", with_line(good, e4, "4 101 102 108 100")), e4, "node tag 100 is not in $Nodes");
  const int c = line_of(good, "2 2 0");
  expect_error(write("coord.msh", with_line(good, c, "2 2")), c, "z coordinate");
  // More elements than the block holds: the next block header is read as an element.
  const int blk = line_of(good, "3 8 4 3");
  expect_error(write("count.msh", with_line(good, blk - 4, "3 7 4 4")), blk, "expected 4 node tags");
  expect_error(write("cut.msh", first_lines(good, e4)), e4, "unexpected end of file");
  expect_error(write("ver.msh", with_line(good, 2, "3.0 0 8")), 2, "unsupported .msh format version");
}

TEST_F(MeshIoBroken, Tetgen) {
  const std::string node = slurp(data("cube0.node"));
  const std::string ele = slurp(data("cube0.ele"));
  write("a.node", node);
  write("a.ele", with_line(ele, 4, "2 0 2 9 3 1"));
  expect_error((dir_ / "a.ele").string(), 4, "vertex index 9 out of range 0..7");
  write("a.ele", with_line(ele, 4, "2 0 2 7 3"));
  expect_error((dir_ / "a.ele").string(), 4, "expected 4 vertex indices and 1 attributes");
  write("a.ele", with_line(ele, 4, "2 0 2 7 3 1.5"));
  expect_error((dir_ / "a.ele").string(), 4, "region attribute must be an integer");
  write("a.ele", first_lines(ele, 4));
  expect_error((dir_ / "a.ele").string(), 4, "unexpected end of file, expected tetrahedron 4 of 6");
  write("a.ele", ele);
  write("a.node", with_line(node, 5, "2  2 0 0e  0.5 1"));
  expect_error((dir_ / "a.node").string(), 5, "'0e'");
  write("a.node", with_line(node, 5, "3  2 0 0  0.5 1"));
  expect_error((dir_ / "a.node").string(), 5, "expected point index 2, got 3");
}

// Hostile headers: a count that cannot fit in the rest of the file is refused at its line before
// anything is allocated for it (4e8 vertices would be 9.6 GB; the child has 256 MB to spare).
TEST_F(MeshIoBroken, HugeCountsAreRefusedBeforeAllocating) {
  constexpr std::size_t kSpare = std::size_t{256} << 20;
  const auto expect_refused = [&](const std::string& path, int line, const std::string& what) {
    const std::string e =
        neurosim::testing::message_with_memory_limit(kSpare, [&] { read_mesh(path); });
    EXPECT_NE(e.find(path + ":" + std::to_string(line) + ": " + what), std::string::npos) << e;
  };
  const std::string medit = "MeshVersionFormatted 1\nDimension 3\nVertices\n";
  expect_refused(write("v.mesh", medit + "400000000\n0 0 0 0\n"), 4,
                 "400000000 vertices cannot fit");
  expect_refused(write("t.mesh", medit + "1\n0 0 0 0\nTetrahedra\n1000000000000\n1 1 1 1 0\n"), 7,
                 "1000000000000 tetrahedra cannot fit");
  expect_refused(write("c.mesh", medit + "1\n0 0 0 0\nCorners 400000000\n1\n"), 6,
                 "400000000 Corners cannot fit");
  const std::string v2 = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n";
  expect_refused(write("n.msh", v2 + "$Nodes\n400000000\n1 0 0 0\n"), 5,
                 "400000000 nodes cannot fit");
  expect_refused(write("e.msh", v2 + "$Nodes\n1\n1 0 0 0\n$EndNodes\n$Elements\n1000000000000\n"),
                 9, "1000000000000 elements cannot fit");
  const std::string v41 = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";
  expect_refused(write("b.msh", v41 + "$Nodes\n1 400000000 1 400000000\n3 1 0 400000000\n1\n"), 5,
                 "400000000 nodes cannot fit");
  expect_refused(write("k.msh", v41 + "$Nodes\n1 1 1 1\n3 1 0 400000000\n1\n0 0 0\n"), 6,
                 "400000000 nodes cannot fit");
  expect_refused(write("p.node", "400000000 3 0 0\n1 0 0 0\n"), 1, "400000000 points cannot fit");
  write("q.node", "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  expect_refused(write("q.ele", "1000000000000 4 0\n1 1 2 3 4\n"), 1,
                 "1000000000000 tetrahedra cannot fit");
}

// One line cannot grow a list of numbers without bound either.
TEST_F(MeshIoBroken, EndlessLinesAreRefused) {
  std::string nodes(20000, ' ');
  for (std::size_t i = 0; i < nodes.size(); i += 2) nodes[i] = '1';
  const std::string v2 = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n";
  expect_error(write("l.msh", v2 + "$Elements\n1\n1 4 0 " + nodes + "\n$EndElements\n"), 10,
               "more than 1024 numbers on one element line");
  write("l.node", "1 3 0 0\n1 0 0 0 " + nodes + "\n");
  expect_error((dir_ / "l.node").string(), 2, "more than 4 numbers in point 1 of 1");
}

// Out of memory while reading is an error naming the file, not a crash.
TEST_F(MeshIoBroken, OutOfMemoryNamesTheFile) {
  std::string text = "MeshVersionFormatted 1\nDimension 3\nVertices\n2000000\n";
  text.reserve(text.size() + 2000000 * 8 + 100);
  for (int i = 0; i < 2000000; ++i) text += "0 0 0 0\n";
  text += "Tetrahedra\n1\n1 2 3 4 0\nEnd\n";
  const std::string path = write("big.mesh", text);  // 16 MB of text, 48 MB of vertices
  const std::string e = neurosim::testing::message_with_memory_limit(std::size_t{40} << 20,
                                                                     [&] { load_tet_mesh(path); });
  EXPECT_EQ(e, path + ": out of memory while reading");
}

TEST(MeshIo, UnknownExtensionAndMissingFile) {
  EXPECT_NE(read_error([] { read_mesh("brain.stl"); }).find("unknown mesh format"), std::string::npos);
  EXPECT_NE(read_error([] { read_mesh("/nonexistent/brain.mesh"); }).find("/nonexistent/brain.mesh: cannot open"),
            std::string::npos);
  EXPECT_THROW(read_medit(data("cube.mesh"), 0.0), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::mesh
