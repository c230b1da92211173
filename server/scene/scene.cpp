#include "server/scene/scene.hpp"

#include "server/mesh/generate.hpp"
#include "server/mesh/io.hpp"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

namespace neurosim::scene {
namespace {

// Collects protobuf's text-format errors as "file:line:col: message" (1-based).
class ErrorCollector : public google::protobuf::io::ErrorCollector {
 public:
  explicit ErrorCollector(std::string source) : source_(std::move(source)) {}
  void AddError(int line, google::protobuf::io::ColumnNumber column,
                const std::string& message) override {
    std::ostringstream out;
    out << source_ << ":" << line + 1 << ":" << column + 1 << ": " << message;
    errors_.push_back(out.str());
  }
  void AddWarning(int line, google::protobuf::io::ColumnNumber column,
                  const std::string& message) override {
    AddError(line, column, "warning: " + message);
  }
  std::string text() const {
    std::string all;
    for (const auto& e : errors_) all += (all.empty() ? "" : "\n") + e;
    return all;
  }

 private:
  std::string source_;
  std::vector<std::string> errors_;
};

[[noreturn]] void fail(const std::string& source, const std::string& field,
                       const std::string& message) {
  throw std::runtime_error(source + ": " + field + ": " + message);
}

bool finite(const Vec3& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

void check_vec(const Vec3& v, const std::string& source, const std::string& field) {
  if (!finite(v)) fail(source, field, "non-finite component");
}

void check_region(const Region& region, const std::string& source, const std::string& field) {
  switch (region.select_case()) {
    case Region::kNodes:
      for (int i = 0; i < region.nodes().ids_size(); ++i) {
        if (region.nodes().ids(i) < 0) {
          fail(source, field + ".nodes.ids[" + std::to_string(i) + "]", "negative node id");
        }
      }
      break;
    case Region::kBox: {
      check_vec(region.box().min_m(), source, field + ".box.min_m");
      check_vec(region.box().max_m(), source, field + ".box.max_m");
      const auto lo = to_vec3(region.box().min_m()), hi = to_vec3(region.box().max_m());
      if ((hi.array() < lo.array()).any()) fail(source, field + ".box", "max_m < min_m");
      break;
    }
    case Region::kHalfSpace:
      check_vec(region.half_space().point_m(), source, field + ".half_space.point_m");
      check_vec(region.half_space().normal(), source, field + ".half_space.normal");
      if (!(to_vec3(region.half_space().normal()).norm() > 0.0)) {
        fail(source, field + ".half_space.normal", "must be non-zero");
      }
      break;
    case Region::SELECT_NOT_SET:
      fail(source, field, "empty region: give nodes, box or half_space");
  }
}

void check_positive(double value, const std::string& source, const std::string& field,
                    bool zero_allowed) {
  if (!std::isfinite(value) || value < 0.0 || (!zero_allowed && value == 0.0)) {
    std::ostringstream msg;
    msg << value << " must be finite and " << (zero_allowed ? ">= 0" : "> 0");
    fail(source, field, msg.str());
  }
}

}  // namespace

Scene parse_scene(const std::string& text, const std::string& source) {
  Scene scene;
  ErrorCollector errors(source);
  google::protobuf::TextFormat::Parser parser;
  parser.RecordErrorsTo(&errors);
  if (!parser.ParseFromString(text, &scene)) {
    throw std::runtime_error("malformed scene file:\n" + errors.text());
  }
  validate_scene(scene, source);
  return scene;
}

Scene read_scene(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot open scene file");
  std::stringstream text;
  text << in.rdbuf();
  return parse_scene(text.str(), path.string());
}

fem::Material to_material(const Material& material, const std::string& what) {
  fem::Material m;
  m.youngs_modulus_pa = material.youngs_modulus_pa();
  m.poisson_ratio = material.poisson_ratio();
  m.name = material.name().empty() ? what : material.name();
  try {
    m.validate();
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(what + ": " + e.what());
  }
  return m;
}

void validate_scene(const Scene& scene, const std::string& source) {
  if (scene.meshes_size() == 0) fail(source, "meshes", "a scene needs at least one mesh");
  std::set<std::string> ids;
  for (int i = 0; i < scene.meshes_size(); ++i) {
    const auto& m = scene.meshes(i);
    const std::string f = "meshes[" + std::to_string(i) + "]";
    if (m.id().empty()) fail(source, f + ".id", "missing");
    if (!ids.insert(m.id()).second) fail(source, f + ".id", "duplicate id \"" + m.id() + "\"");
    if (m.source_case() == Mesh::SOURCE_NOT_SET) {
      fail(source, f, "give file or generate");
    }
    if (m.has_file_unit_m()) check_positive(m.file_unit_m(), source, f + ".file_unit_m", false);
    if (m.source_case() == Mesh::kGenerate) {
      const auto& g = m.generate();
      if (g.shape_case() == Generator::SHAPE_NOT_SET) fail(source, f + ".generate", "no shape");
      if (g.target_vertices() < 0) fail(source, f + ".generate.target_vertices", "negative");
      check_positive(g.cell_size_m(), source, f + ".generate.cell_size_m", true);
      if (g.target_vertices() == 0 && g.cell_size_m() == 0.0) {
        fail(source, f + ".generate", "give target_vertices or cell_size_m");
      }
      if (g.has_box()) {
        check_vec(g.box().min_m(), source, f + ".generate.box.min_m");
        check_vec(g.box().max_m(), source, f + ".generate.box.max_m");
      } else {
        check_vec(g.cylinder().base_center_m(), source, f + ".generate.cylinder.base_center_m");
        check_vec(g.cylinder().axis_m(), source, f + ".generate.cylinder.axis_m");
        check_positive(g.cylinder().radius_m(), source, f + ".generate.cylinder.radius_m", false);
      }
    }
    if (!m.has_material()) fail(source, f + ".material", "missing");
    to_material(m.material(), source + ": " + f + ".material");
    for (int r = 0; r < m.fixed_size(); ++r) {
      check_region(m.fixed(r), source, f + ".fixed[" + std::to_string(r) + "]");
    }
  }
  auto check_mesh_ref = [&](const std::string& id, const std::string& field) {
    if (!ids.count(id)) fail(source, field, "no mesh with id \"" + id + "\"");
  };
  for (int i = 0; i < scene.couplings_size(); ++i) {
    const auto& c = scene.couplings(i);
    const std::string f = "couplings[" + std::to_string(i) + "]";
    check_mesh_ref(c.host(), f + ".host");
    check_mesh_ref(c.embedded(), f + ".embedded");
    if (c.host() == c.embedded()) fail(source, f, "a mesh cannot be coupled to itself");
  }
  for (int i = 0; i < scene.loads_size(); ++i) {
    const auto& l = scene.loads(i);
    const std::string f = "loads[" + std::to_string(i) + "]";
    check_mesh_ref(l.mesh(), f + ".mesh");
    check_region(l.region(), source, f + ".region");
    check_vec(l.force_n(), source, f + ".force_n");
  }
  for (int i = 0; i < scene.prescribed_size(); ++i) {
    const auto& p = scene.prescribed(i);
    const std::string f = "prescribed[" + std::to_string(i) + "]";
    check_mesh_ref(p.mesh(), f + ".mesh");
    check_region(p.region(), source, f + ".region");
    check_vec(p.displacement_m(), source, f + ".displacement_m");
  }
  std::set<std::string> tool_ids;
  for (int i = 0; i < scene.tools_size(); ++i) {
    const auto& t = scene.tools(i);
    const std::string f = "tools[" + std::to_string(i) + "]";
    if (t.id().empty()) fail(source, f + ".id", "missing");
    if (!tool_ids.insert(t.id()).second) fail(source, f + ".id", "duplicate id");
    check_positive(t.tip_radius_m(), source, f + ".tip_radius_m", false);
    check_positive(t.shaft_radius_m(), source, f + ".shaft_radius_m", true);
    check_positive(t.shaft_length_m(), source, f + ".shaft_length_m", true);
    check_positive(t.max_speed_m_per_s(), source, f + ".max_speed_m_per_s", true);
  }
  check_positive(scene.rates().step_hz(), source, "rates.step_hz", true);
  check_positive(scene.rates().viewer_hz(), source, "rates.viewer_hz", true);
  check_positive(scene.rates().status_hz(), source, "rates.status_hz", true);
  check_positive(scene.haptics().force_scale(), source, "haptics.force_scale", true);
  check_positive(scene.haptics().workspace_scale(), source, "haptics.workspace_scale", true);
  check_positive(scene.haptics().max_force_n(), source, "haptics.max_force_n", true);
  if (scene.max_stations() < 0) fail(source, "max_stations", "negative");
  if (scene.effects().coupling() && scene.couplings_size() == 0) {
    fail(source, "effects.coupling", "set, but the scene lists no couplings");
  }
}

int find_mesh(const Scene& scene, const std::string& id) {
  for (int i = 0; i < scene.meshes_size(); ++i) {
    if (scene.meshes(i).id() == id) return i;
  }
  return -1;
}

std::vector<int> select_nodes(const mesh::TetMesh& mesh, const Region& region,
                              const std::string& what) {
  std::vector<int> nodes;
  const auto& x = mesh.vertices();
  const int n = static_cast<int>(x.size());
  switch (region.select_case()) {
    case Region::kNodes:
      for (int id : region.nodes().ids()) {
        if (id < 0 || id >= n) {
          throw std::runtime_error(what + ": node id " + std::to_string(id) +
                                   " out of range (mesh has " + std::to_string(n) + " nodes)");
        }
        nodes.push_back(id);
      }
      break;
    case Region::kBox: {
      const auto lo = to_vec3(region.box().min_m()), hi = to_vec3(region.box().max_m());
      for (int i = 0; i < n; ++i) {
        if ((x[i].array() >= lo.array()).all() && (x[i].array() <= hi.array()).all()) {
          nodes.push_back(i);
        }
      }
      break;
    }
    case Region::kHalfSpace: {
      const auto p = to_vec3(region.half_space().point_m());
      const auto nrm = to_vec3(region.half_space().normal()).normalized();
      for (int i = 0; i < n; ++i) {
        if ((x[i] - p).dot(nrm) <= 0.0) nodes.push_back(i);
      }
      break;
    }
    case Region::SELECT_NOT_SET:
      throw std::runtime_error(what + ": empty region");
  }
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  if (nodes.empty()) throw std::runtime_error(what + ": region selects no node");
  return nodes;
}

LoadedMesh load_mesh(const Mesh& entry, const std::filesystem::path& scene_dir,
                     const std::string& source) {
  const std::string what = source + ": mesh \"" + entry.id() + "\"";
  LoadedMesh out{entry.id(), mesh::TetMesh{}, to_material(entry.material(), what + " material"),
                 {}, entry.priority(), entry.provenance(), 0.0};
  if (entry.source_case() == Mesh::kFile) {
    std::filesystem::path file = entry.file();
    if (file.is_relative()) file = scene_dir / file;
    const double unit = entry.has_file_unit_m() ? entry.file_unit_m() : 1.0;
    mesh::MeshData data = mesh::read_mesh(file.string(), unit);
    if (entry.labels_size() > 0) {
      // Keep only the tetrahedra of the requested subdomains.
      std::set<int> keep(entry.labels().begin(), entry.labels().end());
      std::vector<mesh::Tet> tets;
      std::vector<int> labels;
      for (std::size_t t = 0; t < data.tets.size(); ++t) {
        if (keep.count(data.tet_labels[t])) {
          tets.push_back(data.tets[t]);
          labels.push_back(data.tet_labels[t]);
        }
      }
      if (tets.empty()) throw std::runtime_error(what + ": no tetrahedron has the given labels");
      data.tets = std::move(tets);
      data.tet_labels = std::move(labels);
    }
    mesh::BuildOptions build;
    build.source = file.string();
    out.mesh = mesh::TetMesh::build(std::move(data.vertices_m), std::move(data.tets), build);
    out.mesh.set_tet_labels(std::move(data.tet_labels));
  } else {
    const auto& g = entry.generate();
    mesh::MeshingOptions options;
    options.target_vertices = g.target_vertices();
    options.cell_size_m = g.cell_size_m();
    options.seed = g.seed();
    mesh::GeneratedMesh generated =
        g.has_box() ? mesh::generate_box(to_vec3(g.box().min_m()), to_vec3(g.box().max_m()), options)
                    : mesh::generate_cylinder(to_vec3(g.cylinder().base_center_m()),
                                              to_vec3(g.cylinder().axis_m()),
                                              g.cylinder().radius_m(), options);
    out.mesh = std::move(generated.mesh);
    out.generator_cell_size_m = generated.cell_size_m;
  }
  for (int r = 0; r < entry.fixed_size(); ++r) {
    auto nodes = select_nodes(out.mesh, entry.fixed(r), what + " fixed[" + std::to_string(r) + "]");
    out.fixed_nodes.insert(out.fixed_nodes.end(), nodes.begin(), nodes.end());
  }
  std::sort(out.fixed_nodes.begin(), out.fixed_nodes.end());
  out.fixed_nodes.erase(std::unique(out.fixed_nodes.begin(), out.fixed_nodes.end()),
                        out.fixed_nodes.end());
  return out;
}

}  // namespace neurosim::scene
