// Gmsh .msh reader, ASCII format 2.x, 4.0 and 4.1.
#include "server/mesh/io.hpp"
#include "server/mesh/text_reader.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <unordered_map>

namespace neurosim::mesh {

namespace {

enum class Version { v2, v40, v41 };

bool is_volume_type(long long type) {
  switch (type) {
    case 4: case 5: case 6: case 7: case 11: case 12: case 13: case 14: case 17: case 18:
    case 19: case 29: case 30: case 31: case 92: case 93:
      return true;
    default:
      return false;
  }
}

// Next token on the current line, or "path:line: expected <what>".
std::string_view on_line(TextReader& in, const char* what) {
  std::string_view t;
  if (!in.next_on_line(t)) in.fail(std::string("expected ") + what + " on this line");
  return t;
}
long long int_on_line(TextReader& in, const char* what) {
  const std::string_view t = on_line(in, what);
  long long v;
  if (!TextReader::parse_integer(t, v))
    in.fail(std::string("expected ") + what + " (an integer), got '" + std::string(t) + "'");
  return v;
}
double real_on_line(TextReader& in, const char* what) {
  const std::string_view t = on_line(in, what);
  double v;
  if (!TextReader::parse_real(t, v))
    in.fail(std::string("expected ") + what + " (a finite number), got '" + std::string(t) + "'");
  return v;
}
long long first_int(TextReader& in, const char* what) {
  return in.integer(what);  // may start a new line
}
void no_more_on_line(TextReader& in, const char* what) {
  std::string_view t;
  if (in.next_on_line(t)) in.fail(std::string("unexpected '") + std::string(t) + "' after " + what);
  in.end_line();
}
// A count read from the file, checked against the bytes left in it (entries of at least
// tokens_each numbers) before anything is allocated for it.
long long checked_count(TextReader& in, long long n, int tokens_each, const char* what) {
  in.check_count(n, tokens_each, what);
  return n;
}

// Numbers on one element line: tag, type, up to 100 tags and the nodes of any Gmsh element type
// (the largest have a few hundred); more is a broken file, not a reason to grow without bound.
constexpr std::size_t kMaxFieldsPerLine = 1024;

// Skips tokens up to and including end ("$EndNodeData").
void skip_section(TextReader& in, const std::string& end) {
  std::string_view t;
  const int start = in.line();
  while (in.next(t))
    if (t == end) return;
  in.fail_at(start, "section is not closed by " + end);
}

int to_label(TextReader& in, long long v) {
  if (v < -2147483647LL || v > 2147483647LL) in.fail("tag out of range: " + std::to_string(v));
  return static_cast<int>(v);
}

// Node tag -> vertex index.
class NodeIndex {
 public:
  void add(TextReader& in, long long tag, int index) {
    if (tag < 1) in.fail("node tag must be positive, got " + std::to_string(tag));
    if (!map_.emplace(tag, index).second) in.fail("node tag " + std::to_string(tag) + " repeated");
  }
  int operator()(TextReader& in, std::string_view tok) const {
    long long tag;
    if (!TextReader::parse_integer(tok, tag))
      in.fail("expected a node tag (an integer), got '" + std::string(tok) + "'");
    const auto it = map_.find(tag);
    if (it == map_.end()) in.fail("node tag " + std::to_string(tag) + " is not in $Nodes");
    return it->second;
  }
  void reserve(std::size_t n) { map_.reserve(n); }
  bool empty() const { return map_.empty(); }

 private:
  std::unordered_map<long long, int> map_;
};

struct Reader {
  TextReader& in;
  double unit_m;
  MeshData& m;
  Version version{Version::v41};
  NodeIndex nodes;
  // (dim, entity tag) -> first physical tag (from $Entities).
  std::map<std::pair<int, long long>, long long> physical;
  std::vector<std::string_view> fields;

  void mesh_format() {
    const std::string_view v = in.token("format version");
    double ver;
    if (!TextReader::parse_real(v, ver)) in.fail("bad format version '" + std::string(v) + "'");
    if (ver >= 2.0 && ver < 3.0) version = Version::v2;
    else if (v == "4" || v == "4.0") version = Version::v40;
    else if (v == "4.1") version = Version::v41;
    else in.fail("unsupported .msh format version " + std::string(v) + " (2.x, 4.0, 4.1 supported)");
    const long long file_type = in.integer("file type");
    if (file_type != 0) in.fail("binary .msh is not supported, save as ASCII");
    in.integer("data size");
    in.expect("$EndMeshFormat");
  }

  void entities() {
    long long n[4];
    for (int d = 0; d < 4; ++d)
      n[d] = checked_count(in, in.integer("number of entities"), 5, "entities");
    for (int d = 0; d < 4; ++d)
      for (long long i = 0; i < n[d]; ++i) {
        const long long tag = in.integer("entity tag");
        const int coords = (d == 0 && version == Version::v41) ? 3 : 6;
        for (int c = 0; c < coords; ++c) in.real("entity bounding box");
        const long long np =
            checked_count(in, in.integer("number of physical tags"), 1, "physical tags");
        for (long long p = 0; p < np; ++p) {
          const long long ptag = in.integer("physical tag");
          if (p == 0) physical[{d, tag}] = ptag;
        }
        if (d > 0) {
          const long long nb =
              checked_count(in, in.integer("number of bounding entities"), 1, "bounding entities");
          for (long long b = 0; b < nb; ++b) in.integer("bounding entity tag");
        }
      }
    in.expect("$EndEntities");
  }

  void check_dimension(long long dim) {
    if (dim < 0 || dim > 3) in.fail("entity dimension must be 0..3, got " + std::to_string(dim));
  }

  void add_vertex(double x, double y, double z) {
    m.vertices_m.emplace_back(x * unit_m, y * unit_m, z * unit_m);
  }

  void nodes_v2() {
    const long long n = checked_count(in, in.integer("number of nodes"), 4, "nodes");
    no_more_on_line(in, "number of nodes");
    nodes.reserve(n);
    m.vertices_m.reserve(n);
    for (long long i = 0; i < n; ++i) {
      const long long tag = first_int(in, "node tag");
      const double x = real_on_line(in, "x coordinate"), y = real_on_line(in, "y coordinate"),
                   z = real_on_line(in, "z coordinate");
      no_more_on_line(in, "node coordinates");
      nodes.add(in, tag, static_cast<int>(m.vertices_m.size()));
      add_vertex(x, y, z);
    }
    in.expect("$EndNodes");
  }

  void nodes_v4() {
    const long long blocks =
        checked_count(in, in.integer("number of node blocks"), 4, "node blocks");
    const long long total = checked_count(in, int_on_line(in, "number of nodes"), 4, "nodes");
    in.end_line();
    nodes.reserve(total);
    m.vertices_m.reserve(total);
    std::vector<long long> tags;
    for (long long b = 0; b < blocks; ++b) {
      long long dim = first_int(in, "entity dimension");
      long long tag = int_on_line(in, "entity tag");
      if (version == Version::v40) std::swap(dim, tag);  // 4.0: tag first
      check_dimension(dim);
      const long long parametric = int_on_line(in, "parametric flag");
      const long long n =
          checked_count(in, int_on_line(in, "number of nodes in block"), 4, "nodes");
      no_more_on_line(in, "node block header");
      const int extra = parametric ? static_cast<int>(dim) : 0;
      if (version == Version::v41) {
        tags.resize(n);
        for (long long i = 0; i < n; ++i) {
          tags[i] = first_int(in, "node tag");
          no_more_on_line(in, "node tag");
        }
        for (long long i = 0; i < n; ++i) {
          const double x = in.real("x coordinate"), y = real_on_line(in, "y coordinate"),
                       z = real_on_line(in, "z coordinate");
          for (int e = 0; e < extra; ++e) real_on_line(in, "parametric coordinate");
          no_more_on_line(in, "node coordinates");
          nodes.add(in, tags[i], static_cast<int>(m.vertices_m.size()));
          add_vertex(x, y, z);
        }
      } else {
        for (long long i = 0; i < n; ++i) {
          const long long t = first_int(in, "node tag");
          const double x = real_on_line(in, "x coordinate"), y = real_on_line(in, "y coordinate"),
                       z = real_on_line(in, "z coordinate");
          for (int e = 0; e < extra; ++e) real_on_line(in, "parametric coordinate");
          no_more_on_line(in, "node coordinates");
          nodes.add(in, t, static_cast<int>(m.vertices_m.size()));
          add_vertex(x, y, z);
        }
      }
    }
    if (static_cast<long long>(m.vertices_m.size()) != total)
      in.fail("$Nodes header says " + std::to_string(total) + " nodes, blocks hold " +
              std::to_string(m.vertices_m.size()));
    in.expect("$EndNodes");
  }

  // Reads the node tags of one element from fields[first..] into out.
  template <std::size_t N>
  void element_nodes(std::size_t first, std::array<int, N>& out) {
    for (std::size_t k = 0; k < N; ++k) out[k] = nodes(in, fields[first + k]);
  }

  void add_element(long long type, std::size_t first, int label) {
    // fields[first..] are the node tags.
    const std::size_t have = fields.size() - first;
    const std::size_t need = type == 2 ? 3 : type == 4 ? 4 : 10;
    if (have != need)
      in.fail("expected " + std::to_string(need) + " node tags for element type " +
              std::to_string(type) + ", got " + std::to_string(have));
    if (type == 2) {
      Tri t;
      element_nodes(first, t);
      m.triangles.push_back(t);
      m.triangle_labels.push_back(label);
    } else {
      Tet t;  // type 11: the first 4 nodes are the corners
      element_nodes(first, t);
      if (type == 11)
        for (std::size_t k = 4; k < 10; ++k) nodes(in, fields[first + k]);
      m.tets.push_back(t);
      m.tet_labels.push_back(label);
    }
  }

  // All tokens of the next element line into fields.
  void read_line(const char* what) {
    fields.clear();
    fields.push_back(in.token(what));
    std::string_view t;
    while (in.next_on_line(t)) {
      if (fields.size() == kMaxFieldsPerLine)
        in.fail("more than " + std::to_string(kMaxFieldsPerLine) + " numbers on one " + what +
                " line");
      fields.push_back(t);
    }
    in.end_line();
  }

  long long field_int(std::size_t i, const char* what) {
    long long v;
    if (i >= fields.size()) in.fail(std::string("expected ") + what + " on this line");
    if (!TextReader::parse_integer(fields[i], v))
      in.fail(std::string("expected ") + what + " (an integer), got '" + std::string(fields[i]) + "'");
    return v;
  }

  void elements_v2() {
    if (nodes.empty()) in.fail("$Elements before $Nodes");
    const long long n = checked_count(in, in.integer("number of elements"), 4, "elements");
    no_more_on_line(in, "number of elements");
    for (long long i = 0; i < n; ++i) {
      read_line("element");
      if (fields[0].front() == '$') in.fail("expected element " + std::to_string(i + 1) + " of " + std::to_string(n) + ", got '" + std::string(fields[0]) + "'");
      field_int(0, "element tag");
      const long long type = field_int(1, "element type");
      const long long ntags = field_int(2, "number of tags");
      if (ntags < 0 || ntags > 100) in.fail("bad number of tags " + std::to_string(ntags));
      long long label = 0;
      for (long long k = 0; k < ntags; ++k) {
        const long long tag = field_int(3 + k, "element tag");
        if (k == 0) label = tag;  // physical
        else if (k == 1 && label == 0) label = tag;  // elementary
      }
      if (type == 2 || type == 4 || type == 11) {
        add_element(type, static_cast<std::size_t>(3 + ntags), to_label(in, label));
      } else if (is_volume_type(type)) {
        in.fail("element type " + std::to_string(type) + " is a volume element other than a tetrahedron (4 or 11)");
      }
    }
    in.expect("$EndElements");
  }

  void elements_v4() {
    if (nodes.empty()) in.fail("$Elements before $Nodes");
    const long long blocks =
        checked_count(in, in.integer("number of element blocks"), 4, "element blocks");
    const long long total = checked_count(in, int_on_line(in, "number of elements"), 2, "elements");
    in.end_line();
    long long seen = 0;
    for (long long b = 0; b < blocks; ++b) {
      long long dim = first_int(in, "entity dimension");
      long long tag = int_on_line(in, "entity tag");
      if (version == Version::v40) std::swap(dim, tag);
      check_dimension(dim);
      const long long type = int_on_line(in, "element type");
      const long long n =
          checked_count(in, int_on_line(in, "number of elements in block"), 2, "elements");
      no_more_on_line(in, "element block header");
      const auto it = physical.find({static_cast<int>(dim), tag});
      const int label = to_label(in, it != physical.end() ? it->second : tag);
      const bool keep = type == 2 || type == 4 || type == 11;
      if (!keep && (dim == 3 || is_volume_type(type)))
        in.fail("element type " + std::to_string(type) + " is a volume element other than a tetrahedron (4 or 11)");
      for (long long i = 0; i < n; ++i) {
        read_line("element");
        if (fields[0].front() == '$') in.fail("expected element " + std::to_string(i + 1) + " of block " + std::to_string(b + 1) + ", got '" + std::string(fields[0]) + "'");
        field_int(0, "element tag");
        if (keep) add_element(type, 1, label);
      }
      seen += n;
    }
    if (seen != total)
      in.fail("$Elements header says " + std::to_string(total) + " elements, blocks hold " + std::to_string(seen));
    in.expect("$EndElements");
  }
};

MeshData parse_gmsh(const std::string& path, double unit_m) {
  TextReader in(path, 0);
  MeshData m;
  m.source = path;
  Reader r{in, unit_m, m, Version::v41, {}, {}, {}};
  bool format = false;
  std::string_view tok;
  while (in.next(tok)) {
    if (tok == "$MeshFormat") {
      r.mesh_format();
      format = true;
    } else if (!format) {
      in.fail("not a Gmsh .msh file (expected $MeshFormat, got '" + std::string(tok) + "')");
    } else if (tok == "$Entities" && r.version != Version::v2) {
      r.entities();
    } else if (tok == "$Nodes") {
      if (!r.nodes.empty()) in.fail("second $Nodes section");
      if (r.version == Version::v2) r.nodes_v2();
      else r.nodes_v4();
    } else if (tok == "$Elements") {
      if (r.version == Version::v2) r.elements_v2();
      else r.elements_v4();
    } else if (tok.size() > 1 && tok.front() == '$' && tok.substr(0, 4) != "$End") {
      skip_section(in, "$End" + std::string(tok.substr(1)));
    } else {
      in.fail("expected a section ($Name), got '" + std::string(tok) + "'");
    }
  }
  if (!format) in.fail("empty file, not a Gmsh .msh file");
  if (m.tets.empty()) in.fail("no tetrahedra (element type 4 or 11)");
  return m;
}

}  // namespace

MeshData read_gmsh(const std::string& path, double unit_m) {
  if (!(unit_m > 0.0) || !std::isfinite(unit_m))
    throw std::invalid_argument(path + ": unit_m must be finite and > 0");
  return guard_out_of_memory(path, [&] { return parse_gmsh(path, unit_m); });
}

}  // namespace neurosim::mesh
