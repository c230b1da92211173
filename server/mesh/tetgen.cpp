// TetGen .node/.ele reader and writer.
#include "server/mesh/io.hpp"
#include "server/mesh/text_reader.hpp"

#include <charconv>
#include <cmath>
#include <fstream>
#include <stdexcept>

namespace neurosim::mesh {

namespace {

std::string stem_of(const std::string& path) {
  for (const char* ext : {".node", ".ele"}) {
    const std::string e(ext);
    if (path.size() > e.size() && path.compare(path.size() - e.size(), e.size(), e) == 0)
      return path.substr(0, path.size() - e.size());
  }
  return path;
}

// All tokens of the next non-empty line; more than max_fields is an error (a line never needs
// more than its header allows, and a broken one must not grow the list without bound).
void read_line(TextReader& in, std::vector<std::string_view>& fields, const std::string& what,
               std::size_t max_fields) {
  fields.clear();
  std::string_view t;
  if (!in.next(t)) in.fail("unexpected end of file, expected " + what);
  fields.push_back(t);
  while (in.next_on_line(t)) {
    if (fields.size() == max_fields)
      in.fail("more than " + std::to_string(max_fields) + " numbers in " + what);
    fields.push_back(t);
  }
  in.end_line();
}

long long as_int(TextReader& in, std::string_view tok, const char* what) {
  long long v;
  if (!TextReader::parse_integer(tok, v))
    in.fail(std::string("expected ") + what + " (an integer), got '" + std::string(tok) + "'");
  return v;
}

double as_real(TextReader& in, std::string_view tok, const char* what) {
  double v;
  if (!TextReader::parse_real(tok, v))
    in.fail(std::string("expected ") + what + " (a finite number), got '" + std::string(tok) + "'");
  return v;
}

MeshData parse_tetgen(const std::string& path, double unit_m) {
  const std::string stem = stem_of(path);
  MeshData m;
  m.source = stem + ".node";
  std::vector<std::string_view> f;
  int base = 0;

  // .node: "<#points> <dimension 3> <#attributes> <boundary markers 0|1>", then points.
  {
    TextReader in(stem + ".node", '#');
    read_line(in, f, "the .node header", 4);
    if (f.size() < 2 || f.size() > 4) in.fail("expected '<#points> 3 [<#attributes> [<#markers>]]'");
    const long long n = as_int(in, f[0], "number of points");
    if (n < 1) in.fail("bad number of points " + std::to_string(n));
    if (as_int(in, f[1], "dimension") != 3) in.fail("dimension must be 3");
    const long long nattr = f.size() > 2 ? as_int(in, f[2], "number of attributes") : 0;
    const long long nmark = f.size() > 3 ? as_int(in, f[3], "number of boundary markers") : 0;
    if (nattr < 0 || nattr > 1000 || nmark < 0 || nmark > 1) in.fail("bad attribute or marker count");
    const std::size_t width = static_cast<std::size_t>(4 + nattr + nmark);
    in.check_count(n, static_cast<int>(width), "points");
    m.vertices_m.resize(n);
    for (long long i = 0; i < n; ++i) {
      read_line(in, f, "point " + std::to_string(i + 1) + " of " + std::to_string(n), width);
      if (f.size() != width)
        in.fail("expected " + std::to_string(width) + " numbers for a point (index, x, y, z, " +
                std::to_string(nattr) + " attributes, " + std::to_string(nmark) + " markers), got " +
                std::to_string(f.size()));
      const long long id = as_int(in, f[0], "point index");
      if (i == 0) {
        if (id != 0 && id != 1) in.fail("first point index must be 0 or 1, got " + std::to_string(id));
        base = static_cast<int>(id);
      } else if (id != base + i) {
        in.fail("expected point index " + std::to_string(base + i) + ", got " + std::to_string(id));
      }
      for (int c = 0; c < 3; ++c) m.vertices_m[i][c] = as_real(in, f[1 + c], "coordinate") * unit_m;
    }
  }

  // .ele: "<#tetrahedra> <nodes per tetrahedron 4|10> <#attributes>", then tetrahedra.
  {
    TextReader in(stem + ".ele", '#');
    read_line(in, f, "the .ele header", 3);
    if (f.size() < 2 || f.size() > 3) in.fail("expected '<#tetrahedra> <4|10> [<#attributes>]'");
    const long long n = as_int(in, f[0], "number of tetrahedra");
    if (n < 1) in.fail("bad number of tetrahedra " + std::to_string(n));
    const long long per = as_int(in, f[1], "nodes per tetrahedron");
    if (per != 4 && per != 10) in.fail("nodes per tetrahedron must be 4 or 10, got " + std::to_string(per));
    const long long nattr = f.size() > 2 ? as_int(in, f[2], "number of attributes") : 0;
    if (nattr < 0 || nattr > 1000) in.fail("bad number of attributes " + std::to_string(nattr));
    const std::size_t width = static_cast<std::size_t>(1 + per + nattr);
    const long long nv = static_cast<long long>(m.vertices_m.size());
    in.check_count(n, static_cast<int>(width), "tetrahedra");
    m.tets.resize(n);
    m.tet_labels.assign(n, 0);
    for (long long i = 0; i < n; ++i) {
      read_line(in, f, "tetrahedron " + std::to_string(i + 1) + " of " + std::to_string(n), width);
      if (f.size() != width)
        in.fail("expected " + std::to_string(per) + " vertex indices and " + std::to_string(nattr) +
                " attributes after the tetrahedron index, got " + std::to_string(f.size() - 1) +
                " numbers");
      const long long id = as_int(in, f[0], "tetrahedron index");
      if (id != base + i)
        in.fail("expected tetrahedron index " + std::to_string(base + i) + ", got " + std::to_string(id));
      for (long long k = 0; k < per; ++k) {
        const long long v = as_int(in, f[1 + k], "vertex index");
        if (v < base || v >= base + nv)
          in.fail("vertex index " + std::to_string(v) + " out of range " + std::to_string(base) +
                  ".." + std::to_string(base + nv - 1));
        if (k < 4) m.tets[i][k] = static_cast<int>(v - base);
      }
      if (nattr > 0) {
        const double a = as_real(in, f[1 + per], "region attribute");
        if (a != std::round(a) || std::abs(a) > 2147483647.0)
          in.fail("region attribute must be an integer, got " + std::string(f[1 + per]));
        m.tet_labels[i] = static_cast<int>(a);
      }
    }
  }
  return m;
}

}  // namespace

MeshData read_tetgen(const std::string& path, double unit_m) {
  if (!(unit_m > 0.0) || !std::isfinite(unit_m))
    throw std::invalid_argument(path + ": unit_m must be finite and > 0");
  return guard_out_of_memory(path, [&] { return parse_tetgen(path, unit_m); });
}

void write_tetgen(const std::string& stem, const MeshData& mesh, double unit_m) {
  if (!(unit_m > 0.0) || !std::isfinite(unit_m))
    throw std::invalid_argument(stem + ": unit_m must be finite and > 0");
  if (!mesh.tet_labels.empty() && mesh.tet_labels.size() != mesh.tets.size())
    throw std::invalid_argument(stem + ": tet_labels size differs from tets");
  const std::size_t nv = mesh.vertices_m.size();
  {
    std::ofstream out(stem + ".node");
    if (!out) throw std::runtime_error(stem + ".node: cannot open for writing");
    out << nv << " 3 0 0\n";
    char buf[32];
    for (std::size_t i = 0; i < nv; ++i) {
      if (!mesh.vertices_m[i].allFinite())
        throw std::invalid_argument(stem + ": vertex " + std::to_string(i) + " is not finite");
      out << i + 1;
      for (int c = 0; c < 3; ++c) {
        const auto r = std::to_chars(buf, buf + sizeof buf, mesh.vertices_m[i][c] / unit_m);
        out << ' ';
        out.write(buf, r.ptr - buf);
      }
      out << '\n';
    }
    if (!out.good()) throw std::runtime_error(stem + ".node: write error");
  }
  std::ofstream out(stem + ".ele");
  if (!out) throw std::runtime_error(stem + ".ele: cannot open for writing");
  const bool labels = !mesh.tet_labels.empty();
  out << mesh.tets.size() << " 4 " << (labels ? 1 : 0) << '\n';
  for (std::size_t i = 0; i < mesh.tets.size(); ++i) {
    out << i + 1;
    for (int v : mesh.tets[i]) {
      if (v < 0 || static_cast<std::size_t>(v) >= nv)
        throw std::invalid_argument(stem + ": tetrahedron " + std::to_string(i) +
                                    " references vertex " + std::to_string(v) + " out of range");
      out << ' ' << v + 1;
    }
    if (labels) out << ' ' << mesh.tet_labels[i];
    out << '\n';
  }
  if (!out.good()) throw std::runtime_error(stem + ".ele: write error");
}

}  // namespace neurosim::mesh
