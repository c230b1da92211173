// VTK XML UnstructuredGrid writer and a reader for the ASCII files it writes.
#include "server/mesh/vtu.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

namespace neurosim::mesh {

VtuField make_field(std::string name, const std::vector<double>& scalars) {
  return VtuField{std::move(name), 1, scalars};
}

VtuField make_field(std::string name, const std::vector<int>& scalars) {
  return VtuField{std::move(name), 1, std::vector<double>(scalars.begin(), scalars.end())};
}

VtuField make_field(std::string name, const std::vector<Vec3>& vectors) {
  VtuField f{std::move(name), 3, {}};
  f.values.reserve(3 * vectors.size());
  for (const Vec3& v : vectors) f.values.insert(f.values.end(), {v.x(), v.y(), v.z()});
  return f;
}

std::string xml_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

namespace {

void append(std::string& out, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

void append(std::string& out, long long v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

void check_fields(const std::string& path, const std::vector<VtuField>& fields, std::size_t count,
                  const char* kind) {
  for (const VtuField& f : fields) {
    if (f.name.empty()) throw std::invalid_argument(path + ": " + kind + " field without a name");
    if (f.components < 1)
      throw std::invalid_argument(path + ": " + kind + " field '" + f.name +
                                  "' has components < 1");
    if (f.values.size() != count * static_cast<std::size_t>(f.components))
      throw std::invalid_argument(path + ": " + kind + " field '" + f.name + "' has " +
                                  std::to_string(f.values.size()) + " values, expected " +
                                  std::to_string(count) + " x " + std::to_string(f.components));
    for (std::size_t i = 0; i < f.values.size(); ++i)
      if (!std::isfinite(f.values[i]))
        throw std::invalid_argument(path + ": " + kind + " field '" + f.name + "' entry " +
                                    std::to_string(i / f.components) + " component " +
                                    std::to_string(i % f.components) + " is not finite");
  }
}

void write_fields(std::string& out, const std::vector<VtuField>& fields, const char* section) {
  if (fields.empty()) return;
  out += "      <";
  out += section;
  out += ">\n";
  for (const VtuField& f : fields) {
    out += "        <DataArray type=\"Float64\" Name=\"" + xml_escape(f.name) +
           "\" NumberOfComponents=\"" + std::to_string(f.components) + "\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < f.values.size(); ++i) {
      append(out, f.values[i]);
      out += (i + 1) % static_cast<std::size_t>(f.components) == 0 ? '\n' : ' ';
    }
    out += "        </DataArray>\n";
  }
  out += "      </";
  out += section;
  out += ">\n";
}

template <std::size_t N>
void write_cells(const std::string& path, const std::vector<Vec3>& points,
                 const std::vector<std::array<int, N>>& cells, int vtk_type,
                 const std::vector<VtuField>& point_data, const std::vector<VtuField>& cell_data) {
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite())
      throw std::invalid_argument(path + ": point " + std::to_string(i) + " is not finite");
  for (std::size_t c = 0; c < cells.size(); ++c)
    for (int v : cells[c])
      if (v < 0 || static_cast<std::size_t>(v) >= points.size())
        throw std::invalid_argument(path + ": cell " + std::to_string(c) + " references point " +
                                    std::to_string(v) + ", outside [0, " +
                                    std::to_string(points.size()) + ")");
  check_fields(path, point_data, points.size(), "point");
  check_fields(path, cell_data, cells.size(), "cell");

  std::string out;
  out.reserve(64 * points.size() + 48 * cells.size() + 1024);
  out +=
      "<?xml version=\"1.0\"?>\n"
      "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" "
      "header_type=\"UInt64\">\n  <UnstructuredGrid>\n";
  out += "    <Piece NumberOfPoints=\"" + std::to_string(points.size()) + "\" NumberOfCells=\"" +
         std::to_string(cells.size()) + "\">\n";
  write_fields(out, point_data, "PointData");
  write_fields(out, cell_data, "CellData");
  out += "      <Points>\n        <DataArray type=\"Float64\" Name=\"Points\" "
         "NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (const Vec3& p : points) {
    append(out, p.x());
    out += ' ';
    append(out, p.y());
    out += ' ';
    append(out, p.z());
    out += '\n';
  }
  out += "        </DataArray>\n      </Points>\n      <Cells>\n";
  out += "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
  for (const auto& cell : cells) {
    for (std::size_t k = 0; k < N; ++k) {
      append(out, static_cast<long long>(cell[k]));
      out += k + 1 < N ? ' ' : '\n';
    }
  }
  out += "        </DataArray>\n        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  for (std::size_t c = 0; c < cells.size(); ++c) {
    append(out, static_cast<long long>(N * (c + 1)));
    out += (c + 1) % 16 == 0 || c + 1 == cells.size() ? '\n' : ' ';
  }
  out += "        </DataArray>\n        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (std::size_t c = 0; c < cells.size(); ++c) {
    append(out, static_cast<long long>(vtk_type));
    out += (c + 1) % 32 == 0 || c + 1 == cells.size() ? '\n' : ' ';
  }
  out += "        </DataArray>\n      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n";

  std::ofstream file(path, std::ios::binary);
  if (!file) throw std::runtime_error(path + ": cannot open for writing");
  file.write(out.data(), static_cast<std::streamsize>(out.size()));
  if (!file.good()) throw std::runtime_error(path + ": write error");
}

constexpr int kVtkTriangle = 5;
constexpr int kVtkTetra = 10;

}  // namespace

void write_vtu(const std::string& path, const std::vector<Vec3>& points_m,
               const std::vector<Tet>& tets, const std::vector<VtuField>& point_data,
               const std::vector<VtuField>& cell_data) {
  write_cells(path, points_m, tets, kVtkTetra, point_data, cell_data);
}

void write_vtu(const std::string& path, const std::vector<Vec3>& points_m,
               const std::vector<Tri>& triangles, const std::vector<VtuField>& point_data,
               const std::vector<VtuField>& cell_data) {
  write_cells(path, points_m, triangles, kVtkTriangle, point_data, cell_data);
}

void write_vtu(const std::string& path, const TetMesh& mesh,
               const std::vector<VtuField>& point_data, const std::vector<VtuField>& cell_data) {
  const bool has_label = std::any_of(cell_data.begin(), cell_data.end(),
                                     [](const VtuField& f) { return f.name == "label"; });
  if (has_label) {
    write_vtu(path, mesh.vertices(), mesh.tets(), point_data, cell_data);
    return;
  }
  std::vector<VtuField> cells = cell_data;
  cells.push_back(make_field("label", mesh.tet_labels()));
  write_vtu(path, mesh.vertices(), mesh.tets(), point_data, cells);
}

const VtuField* VtuData::point_field(const std::string& name) const {
  for (const VtuField& f : point_data)
    if (f.name == name) return &f;
  return nullptr;
}

const VtuField* VtuData::cell_field(const std::string& name) const {
  for (const VtuField& f : cell_data)
    if (f.name == name) return &f;
  return nullptr;
}

namespace {

// A minimal scanner for the XML that write_vtu produces: elements, attributes, text.
class VtuParser {
 public:
  explicit VtuParser(std::string path) : path_(std::move(path)) {
    std::ifstream in(path_, std::ios::binary);
    if (!in) throw std::runtime_error(path_ + ": cannot open file");
    std::ostringstream buf;
    buf << in.rdbuf();
    text_ = buf.str();
  }

  [[noreturn]] void fail(std::size_t at, const std::string& msg) const {
    const long line = 1 + std::count(text_.begin(), text_.begin() + std::min(at, text_.size()), '\n');
    throw std::runtime_error(path_ + ":" + std::to_string(line) + ": " + msg);
  }

  struct Tag {
    std::string name;
    std::map<std::string, std::string> attr;
    bool closing{false};
    bool self_closing{false};
    std::size_t at{0};
  };

  // Next element tag; false at the end of the text.
  bool next_tag(Tag& tag) {
    for (;;) {
      pos_ = text_.find('<', pos_);
      if (pos_ == std::string::npos) return false;
      if (text_.compare(pos_, 4, "<!--") == 0) {
        const std::size_t end = text_.find("-->", pos_);
        if (end == std::string::npos) fail(pos_, "unterminated comment");
        pos_ = end + 3;
        continue;
      }
      if (text_.compare(pos_, 2, "<?") == 0) {
        const std::size_t end = text_.find("?>", pos_);
        if (end == std::string::npos) fail(pos_, "unterminated declaration");
        pos_ = end + 2;
        continue;
      }
      break;
    }
    tag = Tag{};
    tag.at = pos_;
    const std::size_t end = text_.find('>', pos_);
    if (end == std::string::npos) fail(pos_, "unterminated tag");
    std::string body = text_.substr(pos_ + 1, end - pos_ - 1);
    pos_ = end + 1;
    if (!body.empty() && body.front() == '/') {
      tag.closing = true;
      body.erase(0, 1);
    }
    if (!body.empty() && body.back() == '/') {
      tag.self_closing = true;
      body.pop_back();
    }
    std::size_t i = 0;
    while (i < body.size() && !std::isspace(static_cast<unsigned char>(body[i]))) ++i;
    tag.name = body.substr(0, i);
    // Attributes: name="value".
    while (i < body.size()) {
      while (i < body.size() && std::isspace(static_cast<unsigned char>(body[i]))) ++i;
      if (i >= body.size()) break;
      const std::size_t eq = body.find('=', i);
      if (eq == std::string::npos || eq + 1 >= body.size() || (body[eq + 1] != '"' && body[eq + 1] != '\''))
        fail(tag.at, "malformed attribute in <" + tag.name + ">");
      const char quote = body[eq + 1];
      const std::size_t close = body.find(quote, eq + 2);
      if (close == std::string::npos) fail(tag.at, "unterminated attribute in <" + tag.name + ">");
      std::string key = body.substr(i, eq - i);
      while (!key.empty() && std::isspace(static_cast<unsigned char>(key.back()))) key.pop_back();
      tag.attr[key] = unescape(body.substr(eq + 2, close - eq - 2));
      i = close + 1;
    }
    return true;
  }

  // Numbers up to the next '<' (the DataArray's text).
  std::vector<double> numbers(const Tag& tag) {
    std::vector<double> out;
    const std::size_t end = text_.find('<', pos_);
    if (end == std::string::npos) fail(tag.at, "DataArray is not closed");
    const char* p = text_.data() + pos_;
    const char* e = text_.data() + end;
    while (p < e) {
      while (p < e && std::isspace(static_cast<unsigned char>(*p))) ++p;
      if (p >= e) break;
      double v;
      const auto r = std::from_chars(p, e, v);
      if (r.ec != std::errc() || !std::isfinite(v) ||
          (r.ptr < e && !std::isspace(static_cast<unsigned char>(*r.ptr))))
        fail(static_cast<std::size_t>(p - text_.data()),
             "bad number in DataArray '" + attr(tag, "Name", "") + "'");
      out.push_back(v);
      p = r.ptr;
    }
    pos_ = end;
    return out;
  }

  static std::string attr(const Tag& tag, const std::string& key, const std::string& fallback) {
    const auto it = tag.attr.find(key);
    return it == tag.attr.end() ? fallback : it->second;
  }

 private:
  static std::string unescape(const std::string& s) {
    std::string out;
    for (std::size_t i = 0; i < s.size(); ++i) {
      if (s[i] == '&') {
        static const std::pair<const char*, char> kEnt[] = {
            {"&amp;", '&'}, {"&lt;", '<'}, {"&gt;", '>'}, {"&quot;", '"'}, {"&apos;", '\''}};
        bool done = false;
        for (const auto& [ent, ch] : kEnt)
          if (s.compare(i, std::strlen(ent), ent) == 0) {
            out += ch;
            i += std::strlen(ent) - 1;
            done = true;
            break;
          }
        if (done) continue;
      }
      out += s[i];
    }
    return out;
  }

  std::string path_;
  std::string text_;
  std::size_t pos_{0};
};

std::size_t size_attr(VtuParser& p, const VtuParser::Tag& tag, const std::string& key) {
  const std::string v = VtuParser::attr(tag, key, "");
  long long n = -1;
  const auto r = std::from_chars(v.data(), v.data() + v.size(), n);
  if (r.ec != std::errc() || r.ptr != v.data() + v.size() || n < 0)
    p.fail(tag.at, "<" + tag.name + "> needs a non-negative " + key);
  return static_cast<std::size_t>(n);
}

}  // namespace

VtuData read_vtu(const std::string& path) {
  VtuParser p(path);
  VtuData d;
  VtuParser::Tag tag;
  std::string section;  // PointData, CellData, Points, Cells
  bool seen_file = false, seen_piece = false;
  std::size_t npoints = 0, ncells = 0;
  std::vector<double> connectivity, offsets, types;
  while (p.next_tag(tag)) {
    if (tag.closing) {
      if (tag.name == section) section.clear();
      continue;
    }
    if (tag.name == "VTKFile") {
      if (VtuParser::attr(tag, "type", "") != "UnstructuredGrid")
        p.fail(tag.at, "not an UnstructuredGrid VTKFile");
      seen_file = true;
    } else if (tag.name == "Piece") {
      if (seen_piece) p.fail(tag.at, "more than one Piece is not supported");
      seen_piece = true;
      npoints = size_attr(p, tag, "NumberOfPoints");
      ncells = size_attr(p, tag, "NumberOfCells");
    } else if (tag.name == "PointData" || tag.name == "CellData" || tag.name == "Points" ||
               tag.name == "Cells") {
      if (!tag.self_closing) section = tag.name;
    } else if (tag.name == "DataArray") {
      if (VtuParser::attr(tag, "format", "ascii") != "ascii")
        p.fail(tag.at, "only format=\"ascii\" DataArrays are supported");
      const std::string name = VtuParser::attr(tag, "Name", "");
      const std::string comps = VtuParser::attr(tag, "NumberOfComponents", "1");
      int nc = 0;
      std::from_chars(comps.data(), comps.data() + comps.size(), nc);
      if (nc < 1) p.fail(tag.at, "bad NumberOfComponents in DataArray '" + name + "'");
      std::vector<double> values = tag.self_closing ? std::vector<double>{} : p.numbers(tag);
      if (section == "Points") {
        if (nc != 3 || values.size() != 3 * npoints)
          p.fail(tag.at, "Points must hold NumberOfPoints 3-vectors");
        d.points_m.resize(npoints);
        for (std::size_t i = 0; i < npoints; ++i)
          d.points_m[i] = Vec3(values[3 * i], values[3 * i + 1], values[3 * i + 2]);
      } else if (section == "Cells") {
        if (name == "connectivity") connectivity = std::move(values);
        else if (name == "offsets") offsets = std::move(values);
        else if (name == "types") types = std::move(values);
      } else if (section == "PointData" || section == "CellData") {
        const std::size_t count = section == "PointData" ? npoints : ncells;
        if (values.size() != count * static_cast<std::size_t>(nc))
          p.fail(tag.at, "DataArray '" + name + "' holds " + std::to_string(values.size()) +
                             " values, expected " + std::to_string(count) + " x " + comps);
        auto& list = section == "PointData" ? d.point_data : d.cell_data;
        list.push_back(VtuField{name, nc, std::move(values)});
      }
    }
  }
  if (!seen_file || !seen_piece) p.fail(0, "not a VTK UnstructuredGrid file");
  if (types.size() != ncells || offsets.size() != ncells)
    p.fail(0, "Cells need NumberOfCells offsets and types");
  std::size_t prev = 0;
  for (std::size_t c = 0; c < ncells; ++c) {
    const int type = static_cast<int>(types[c]);
    const std::size_t n = type == kVtkTetra ? 4 : type == kVtkTriangle ? 3 : 0;
    if (n == 0) p.fail(0, "cell " + std::to_string(c) + " has VTK type " + std::to_string(type) +
                              " (only tetrahedra 10 and triangles 5 are supported)");
    if (static_cast<int>(types[c]) != static_cast<int>(types[0]))
      p.fail(0, "mixed cell types are not supported");
    const std::size_t end = static_cast<std::size_t>(offsets[c]);
    if (end != prev + n || end > connectivity.size())
      p.fail(0, "cell " + std::to_string(c) + " has inconsistent offsets/connectivity");
    int ids[4];
    for (std::size_t k = 0; k < n; ++k) {
      const double v = connectivity[prev + k];
      if (v < 0 || v >= static_cast<double>(npoints) || v != std::floor(v))
        p.fail(0, "cell " + std::to_string(c) + " references point " + std::to_string(v) +
                      " out of range");
      ids[k] = static_cast<int>(v);
    }
    if (n == 4) d.tets.push_back({ids[0], ids[1], ids[2], ids[3]});
    else d.triangles.push_back({ids[0], ids[1], ids[2]});
    prev = end;
  }
  return d;
}

}  // namespace neurosim::mesh
