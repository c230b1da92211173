// Medit .mesh reader and writer (ASCII; the format CGAL's output_to_medit writes).
#include "server/mesh/io.hpp"
#include "server/mesh/text_reader.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <stdexcept>

namespace neurosim::mesh {

namespace {

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// Numbers per entry of the sections we skip.
int skipped_section_width(const std::string& key) {
  static const std::pair<const char*, int> kWidths[] = {
      {"edges", 3},          {"quadrilaterals", 5},   {"hexahedra", 9},
      {"prisms", 7},         {"pyramids", 6},         {"corners", 1},
      {"requiredvertices", 1}, {"ridges", 1},         {"requirededges", 1},
      {"requiredtriangles", 1}, {"normals", 3},       {"normalatvertices", 2},
      {"tangents", 3},       {"tangentatedges", 2},   {"tangentatvertices", 2},
      {"normalattrianglevertices", 3}};
  for (const auto& [name, width] : kWidths)
    if (key == name) return width;
  return -1;
}

// Names an entry in messages ("vertex 3 of 12"), built only when a message needs it.
struct Entry {
  std::string name;
  long long i, n;
  std::string str() const { return name + " " + std::to_string(i + 1) + " of " + std::to_string(n); }
};

// Reads one entry: all tokens of the next non-empty line.
int line_entry(TextReader& in, std::string_view* tokens, int max_tokens, const Entry& what) {
  int n = 0;
  std::string_view t;
  if (!in.next(t)) in.fail("unexpected end of file, expected " + what.str());
  tokens[n++] = t;
  while (in.next_on_line(t)) {
    if (n == max_tokens) in.fail("too many numbers in " + what.str());
    tokens[n++] = t;
  }
  in.end_line();
  return n;
}

// The count of a section whose entries have tokens_each numbers, checked against the bytes
// left in the file before the caller allocates for it.
long long count(TextReader& in, const std::string& section, int tokens_each) {
  const long long n = in.integer("number of " + section);
  in.end_line();
  in.check_count(n, tokens_each, section);
  return n;
}

int to_index(TextReader& in, std::string_view tok, long long nv, const std::string& what) {
  long long v;
  if (!TextReader::parse_integer(tok, v)) in.fail("expected " + what + ", got '" + std::string(tok) + "'");
  if (v < 1 || v > nv)
    in.fail(what + " " + std::to_string(v) + " out of range 1.." + std::to_string(nv));
  return static_cast<int>(v - 1);
}

int to_label(TextReader& in, std::string_view tok) {
  long long v;
  if (!TextReader::parse_integer(tok, v) || v < -2147483647LL || v > 2147483647LL)
    in.fail("expected an integer reference, got '" + std::string(tok) + "'");
  return static_cast<int>(v);
}

// surface: a triangle surface (Triangles required, Tetrahedra optional) instead of a volume mesh.
MeshData parse_medit(const std::string& path, double unit_m, bool surface) {
  TextReader in(path, '#');
  MeshData m;
  m.source = path;
  int dimension = 3;
  bool seen_version = false, seen_vertices = false;
  std::string_view tok;
  std::string_view f[8];
  while (in.next(tok)) {
    const std::string key = lower(tok);
    if (key == "meshversionformatted") {
      const long long v = in.integer("mesh version");
      if (v < 0 || v > 4) in.fail("unsupported MeshVersionFormatted " + std::to_string(v));
      seen_version = true;
    } else if (!seen_version) {
      in.fail("not a Medit .mesh file (expected MeshVersionFormatted, got '" + std::string(tok) + "')");
    } else if (key == "dimension") {
      const long long d = in.integer("dimension");
      if (d != 3) in.fail("only 3-dimensional meshes are supported, got Dimension " + std::to_string(d));
      dimension = 3;
    } else if (key == "vertices") {
      // A second section would replace the vertices that earlier elements index.
      if (seen_vertices) in.fail("second Vertices section");
      seen_vertices = true;
      const long long n = count(in, "vertices", 4);
      m.vertices_m.resize(n);
      for (long long i = 0; i < n; ++i) {
        const Entry what{"vertex", i, n};
        const int k = line_entry(in, f, 8, what);
        if (k != dimension + 1) in.fail("expected 3 coordinates and a reference for " + what.str());
        for (int c = 0; c < 3; ++c) {
          double x;
          if (!TextReader::parse_real(f[c], x))
            in.fail("expected a finite coordinate for " + what.str() + ", got '" + std::string(f[c]) + "'");
          m.vertices_m[i][c] = x * unit_m;
        }
        to_label(in, f[3]);
      }
    } else if (key == "triangles" || key == "tetrahedra") {
      const bool tet = key == "tetrahedra";
      const int nodes = tet ? 4 : 3;
      const std::string name = tet ? "tetrahedron" : "triangle";
      const long long nv = static_cast<long long>(m.vertices_m.size());
      if (nv == 0) in.fail(std::string(tok) + " before Vertices");
      const long long n = count(in, tet ? "tetrahedra" : "triangles", nodes + 1);
      if (tet) {
        m.tets.reserve(m.tets.size() + n);
        m.tet_labels.reserve(m.tets.size() + n);
      }
      for (long long i = 0; i < n; ++i) {
        const Entry what{name, i, n};
        const int k = line_entry(in, f, 8, what);
        if (k != nodes + 1)
          in.fail("expected " + std::to_string(nodes) + " vertex indices and a reference for " +
                  what.str());
        if (tet) {
          Tet t;
          for (int c = 0; c < 4; ++c) t[c] = to_index(in, f[c], nv, "vertex index");
          m.tets.push_back(t);
          m.tet_labels.push_back(to_label(in, f[4]));
        } else {
          Tri t;
          for (int c = 0; c < 3; ++c) t[c] = to_index(in, f[c], nv, "vertex index");
          m.triangles.push_back(t);
          m.triangle_labels.push_back(to_label(in, f[3]));
        }
      }
    } else if (key == "end") {
      break;
    } else {
      const int width = skipped_section_width(key);
      if (width < 0) in.fail("unknown Medit keyword '" + std::string(tok) + "'");
      const long long n = count(in, std::string(tok), width);
      for (long long i = 0; i < n; ++i) {
        const Entry what{std::string(tok) + " entry", i, n};
        if (line_entry(in, f, 8, what) != width)
          in.fail("expected " + std::to_string(width) + " numbers in " + what.str());
      }
    }
  }
  if (!seen_version) in.fail("empty file, not a Medit .mesh file");
  if (surface && m.triangles.empty()) in.fail("no Triangles section (a surface mesh needs one)");
  if (!surface && m.tets.empty()) in.fail("no Tetrahedra section");
  return m;
}

}  // namespace

MeshData read_medit(const std::string& path, double unit_m) {
  if (!(unit_m > 0.0) || !std::isfinite(unit_m))
    throw std::invalid_argument(path + ": unit_m must be finite and > 0");
  return guard_out_of_memory(path, [&] { return parse_medit(path, unit_m, false); });
}

MeshData read_medit_surface(const std::string& path, double unit_m) {
  if (!(unit_m > 0.0) || !std::isfinite(unit_m))
    throw std::invalid_argument(path + ": unit_m must be finite and > 0");
  return guard_out_of_memory(path, [&] { return parse_medit(path, unit_m, true); });
}

namespace {
void put(std::ofstream& out, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.write(buf, r.ptr - buf);
}
}  // namespace

void write_medit(const std::string& path, const MeshData& mesh, double unit_m) {
  if (!(unit_m > 0.0) || !std::isfinite(unit_m))
    throw std::invalid_argument(path + ": unit_m must be finite and > 0");
  if (!mesh.tet_labels.empty() && mesh.tet_labels.size() != mesh.tets.size())
    throw std::invalid_argument(path + ": tet_labels size differs from tets");
  if (!mesh.triangle_labels.empty() && mesh.triangle_labels.size() != mesh.triangles.size())
    throw std::invalid_argument(path + ": triangle_labels size differs from triangles");
  const std::size_t nv = mesh.vertices_m.size();
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out << "MeshVersionFormatted 1\nDimension 3\nVertices\n" << nv << "\n";
  for (std::size_t i = 0; i < nv; ++i) {
    const Vec3& p = mesh.vertices_m[i];
    if (!p.allFinite())
      throw std::invalid_argument(path + ": vertex " + std::to_string(i) + " is not finite");
    for (int c = 0; c < 3; ++c) {
      put(out, p[c] / unit_m);
      out << ' ';
    }
    out << "0\n";
  }
  auto check = [&](int v, const char* what, std::size_t i) {
    if (v < 0 || static_cast<std::size_t>(v) >= nv)
      throw std::invalid_argument(path + ": " + what + " " + std::to_string(i) +
                                  " references vertex " + std::to_string(v) + " out of range");
    return v + 1;
  };
  if (!mesh.triangles.empty()) {
    out << "Triangles\n" << mesh.triangles.size() << "\n";
    for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
      for (int v : mesh.triangles[i]) out << check(v, "triangle", i) << ' ';
      out << (mesh.triangle_labels.empty() ? 0 : mesh.triangle_labels[i]) << "\n";
    }
  }
  out << "Tetrahedra\n" << mesh.tets.size() << "\n";
  for (std::size_t i = 0; i < mesh.tets.size(); ++i) {
    for (int v : mesh.tets[i]) out << check(v, "tetrahedron", i) << ' ';
    out << (mesh.tet_labels.empty() ? 0 : mesh.tet_labels[i]) << "\n";
  }
  out << "End\n";
  if (!out.good()) throw std::runtime_error(path + ": write error");
}

}  // namespace neurosim::mesh
