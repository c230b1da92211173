#include "server/scene/scene.hpp"

#include "common/input_file.hpp"
#include "server/scene/ranges.hpp"
#include "server/fem/element.hpp"
#include "server/fem/served_tiers.hpp"
#include "server/fem/viscoelastic.hpp"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <optional>
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

using ranges::Range;
using namespace ranges;

void check_range(double value, const Range& r, const std::string& source,
                 const std::string& field) {
  if (r.contains(value)) return;
  std::ostringstream msg;
  msg << value << " is outside [" << r.lo << ", " << r.hi << "]" << (*r.unit ? " " : "")
      << r.unit << (r.zero_is_default ? " (0 or unset: the default)" : "");
  fail(source, field, msg.str());
}

void check_range(const Vec3& v, const Range& r, const std::string& source,
                 const std::string& field) {
  check_range(v.x(), r, source, field + ".x");
  check_range(v.y(), r, source, field + ".y");
  check_range(v.z(), r, source, field + ".z");
}


void check_material(const Material& mat, const std::string& source, const std::string& f) {
  check_range(mat.youngs_modulus_pa(), kYoungsModulus, source, f + ".youngs_modulus_pa");
  if (!std::isfinite(mat.poisson_ratio()) || !(mat.poisson_ratio() > -1.0) ||
      !(mat.poisson_ratio() < 0.5)) {
    std::ostringstream msg;
    msg << mat.poisson_ratio() << " is outside (-1, 0.5)";
    fail(source, f + ".poisson_ratio", msg.str());
  }
  if (!mat.element().empty() && !fem::parse_element(mat.element()))
    fail(source, f + ".element",
         "unknown element \"" + mat.element() + "\" (known: " + fem::element_names() + ")");
  if (mat.has_viscoelastic()) {
    // fem::Viscoelastic::validate names the field and the term ("<f>.viscoelastic.terms[1].g").
    try {
      fem::Viscoelastic v;
      for (const auto& t : mat.viscoelastic().terms()) v.terms.push_back(fem::PronyTerm{t.g(), t.tau_s()});
      v.validate(f + ".viscoelastic");
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(source + ": " + e.what());
    }
  }
}

// A rigid mesh: a closed triangle surface from a file, with openings; nothing of a body.
void check_rigid(const Mesh& m, const std::string& source, const std::string& f) {
  if (m.source_case() != Mesh::kFile)
    fail(source, f + ".generate", "a rigid mesh is read from a file (a closed triangle surface)");
  if (m.has_material()) fail(source, f + ".material", "a rigid mesh has no material (remove it)");
  if (m.fixed_size() > 0) fail(source, f + ".fixed", "a rigid mesh does not move: no fixed regions");
  if (m.labels_size() > 0) fail(source, f + ".labels", "a rigid mesh has no tetrahedra to select");
  if (m.tissues_size() > 0) fail(source, f + ".tissues", "a rigid mesh has no tetrahedra to label");
  for (int k = 0; k < m.openings_size(); ++k) {
    const auto& o = m.openings(k);
    const std::string g = f + ".openings[" + std::to_string(k) + "]";
    check_vec(o.center_m(), source, g + ".center_m");
    check_range(o.center_m(), kCoordinate, source, g + ".center_m");
    check_vec(o.axis(), source, g + ".axis");
    if (!(to_vec3(o.axis()).norm() > 0.0)) fail(source, g + ".axis", "must be non-zero");
    check_range(o.radius_m(), kOpeningRadius, source, g + ".radius_m");
    if (!(o.radius_m() > 0.0)) fail(source, g + ".radius_m", "must be > 0");
    check_range(o.half_length_m(), kOpeningHalfLength, source, g + ".half_length_m");
    if (!(o.half_length_m() > 0.0)) fail(source, g + ".half_length_m", "must be > 0");
  }
}

// Tissues: labels and names unique, their own materials valid.
void check_tissues(const Mesh& m, const std::string& source, const std::string& f) {
  std::set<int> labels;
  std::set<std::string> names;
  for (int k = 0; k < m.tissues_size(); ++k) {
    const auto& t = m.tissues(k);
    const std::string g = f + ".tissues[" + std::to_string(k) + "]";
    if (!labels.insert(t.label()).second)
      fail(source, g + ".label", "label " + std::to_string(t.label()) + " listed twice");
    if (t.name().empty()) fail(source, g + ".name", "missing");
    if (!names.insert(t.name()).second) fail(source, g + ".name", "duplicate name \"" + t.name() + "\"");
    if (t.has_material()) {
      check_material(t.material(), source, g + ".material");
      const auto mesh_element = m.material().element().empty()
                                    ? std::optional<fem::Element>(fem::kDefaultSceneElement)
                                    : fem::parse_element(m.material().element());
      if (!t.material().element().empty() && fem::parse_element(t.material().element()) != mesh_element)
        fail(source, g + ".material.element",
             "\"" + t.material().element() + "\" differs from the mesh's element (one element per mesh)");
    }
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
  // Regular files only, at most kMaxSceneFileBytes: a named pipe or a device is refused before
  // reading (opening a pipe alone would wait for a writer).
  const std::string text = common::read_input_file(path.string(), kMaxSceneFileBytes, "scene file");
  try {
    return parse_scene(text, path.string());
  } catch (const std::bad_alloc&) {
    throw std::runtime_error(path.string() + ": out of memory while parsing the scene");
  }
}

void validate_scene(const Scene& scene, const std::string& source) {
  if (scene.meshes_size() == 0) fail(source, "meshes", "a scene needs at least one mesh");
  std::set<std::string> ids, rigid_ids;
  for (int i = 0; i < scene.meshes_size(); ++i) {
    const auto& m = scene.meshes(i);
    const std::string f = "meshes[" + std::to_string(i) + "]";
    if (m.id().empty()) fail(source, f + ".id", "missing");
    if (!ids.insert(m.id()).second) fail(source, f + ".id", "duplicate id \"" + m.id() + "\"");
    if (m.source_case() == Mesh::SOURCE_NOT_SET) {
      fail(source, f, "give file or generate");
    }
    if (m.has_file_unit_m()) check_range(m.file_unit_m(), kFileUnit, source, f + ".file_unit_m");
    if (m.rigid()) {
      check_rigid(m, source, f);
      rigid_ids.insert(m.id());
      continue;
    }
    if (m.openings_size() > 0) fail(source, f + ".openings", "only rigid meshes have openings");
    check_tissues(m, source, f);
    if (m.source_case() == Mesh::kGenerate) {
      const auto& g = m.generate();
      if (g.shape_case() == Generator::SHAPE_NOT_SET) fail(source, f + ".generate", "no shape");
      if (g.target_vertices() < 0 || g.target_vertices() > kMaxGeneratedVertices) {
        fail(source, f + ".generate.target_vertices",
             std::to_string(g.target_vertices()) + " is outside [0, " +
                 std::to_string(kMaxGeneratedVertices) + "] (0: use cell_size_m)");
      }
      check_positive(g.cell_size_m(), source, f + ".generate.cell_size_m", true);
      check_range(g.cell_size_m(), kLength, source, f + ".generate.cell_size_m");
      if (g.target_vertices() == 0 && g.cell_size_m() == 0.0) {
        fail(source, f + ".generate", "give target_vertices or cell_size_m");
      }
      if (g.has_box()) {
        check_vec(g.box().min_m(), source, f + ".generate.box.min_m");
        check_vec(g.box().max_m(), source, f + ".generate.box.max_m");
        check_range(g.box().min_m(), kCoordinate, source, f + ".generate.box.min_m");
        check_range(g.box().max_m(), kCoordinate, source, f + ".generate.box.max_m");
      } else {
        check_vec(g.cylinder().base_center_m(), source, f + ".generate.cylinder.base_center_m");
        check_vec(g.cylinder().axis_m(), source, f + ".generate.cylinder.axis_m");
        check_positive(g.cylinder().radius_m(), source, f + ".generate.cylinder.radius_m", false);
        check_range(g.cylinder().base_center_m(), kCoordinate, source,
                    f + ".generate.cylinder.base_center_m");
        check_range(g.cylinder().axis_m(), kCoordinate, source, f + ".generate.cylinder.axis_m");
        check_range(g.cylinder().radius_m(), kLength, source, f + ".generate.cylinder.radius_m");
      }
    }
    if (!m.has_material()) fail(source, f + ".material", "missing");
    check_material(m.material(), source, f + ".material");
    for (int r = 0; r < m.fixed_size(); ++r) {
      check_region(m.fixed(r), source, f + ".fixed[" + std::to_string(r) + "]");
    }
  }
  if (rigid_ids.size() == ids.size())
    fail(source, "meshes", "every mesh is rigid: a scene needs at least one deformable mesh");
  auto check_mesh_ref = [&](const std::string& id, const std::string& field) {
    if (!ids.count(id)) fail(source, field, "no mesh with id \"" + id + "\"");
    if (rigid_ids.count(id))
      fail(source, field, "mesh \"" + id + "\" is rigid (never in the solve): no couplings, loads or prescribed displacements");
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
    check_range(l.force_n(), kForce, source, f + ".force_n");
  }
  for (int i = 0; i < scene.prescribed_size(); ++i) {
    const auto& p = scene.prescribed(i);
    const std::string f = "prescribed[" + std::to_string(i) + "]";
    check_mesh_ref(p.mesh(), f + ".mesh");
    check_region(p.region(), source, f + ".region");
    check_vec(p.displacement_m(), source, f + ".displacement_m");
    check_range(p.displacement_m(), kDisplacement, source, f + ".displacement_m");
    std::set<char> held;
    for (char c : p.components()) {
      if (c != 'x' && c != 'y' && c != 'z')
        fail(source, f + ".components", "'" + p.components() + "': give a subset of \"xyz\"");
      if (!held.insert(c).second)
        fail(source, f + ".components", "'" + p.components() + "': component repeated");
    }
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
    check_range(t.tip_radius_m(), kToolRadius, source, f + ".tip_radius_m");
    check_range(t.shaft_radius_m(), kToolRadius, source, f + ".shaft_radius_m");
    check_range(t.shaft_length_m(), kToolLength, source, f + ".shaft_length_m");
    check_range(t.max_speed_m_per_s(), kToolSpeed, source, f + ".max_speed_m_per_s");
  }
  check_range(scene.rates().step_hz(), kStepRate, source, "rates.step_hz");
  check_range(scene.rates().viewer_hz(), kViewerRate, source, "rates.viewer_hz");
  check_range(scene.rates().status_hz(), kStatusRate, source, "rates.status_hz");
  check_range(scene.haptics().force_scale(), kScale, source, "haptics.force_scale");
  check_range(scene.haptics().workspace_scale(), kScale, source, "haptics.workspace_scale");
  check_range(scene.haptics().max_force_n(), kMaxForce, source, "haptics.max_force_n");
  check_range(scene.image().file_unit_m(), kImageFileUnit, source,
              "image.file_unit_m");
  if (scene.max_stations() < 0 || scene.max_stations() > kMaxStations) {
    fail(source, "max_stations",
         std::to_string(scene.max_stations()) + " is outside [0, " +
             std::to_string(kMaxStations) + "] (0 or unset: the default)");
  }
  if (scene.effects().coupling() && scene.couplings_size() == 0) {
    fail(source, "effects.coupling", "set, but the scene lists no couplings");
  }
}

namespace {
double or_default(double value, double fallback) { return value > 0.0 ? value : fallback; }
}  // namespace

Settings read_settings(const Scene& scene, const std::string& source) {
  Settings s;
  s.name = scene.name();
  s.description = scene.description();
  s.source = source;
  const auto& fx = scene.effects();
  switch (fx.tier()) {
    case Effects::LINEAR: s.effects.tier = Tier::kLinear; break;
    case Effects::COROTATIONAL: fail(source, "effects.tier", fem::kCorotationalWithdrawn); break;
    case Effects::NONLINEAR: s.effects.tier = Tier::kNonlinear; break;
    default: fail(source, "effects.tier", "unknown tier " + std::to_string(fx.tier()));
  }
  s.effects.coupling = fx.coupling();
  s.effects.tool_contact = fx.tool_contact();
  s.effects.deformation_output = fx.deformation_output();
  if (!std::isfinite(fx.max_expected_force_error()) || fx.max_expected_force_error() < 0.0 ||
      fx.max_expected_force_error() > 10.0) {
    std::ostringstream msg;
    msg << fx.max_expected_force_error()
        << " is outside [0, 10] (a fraction: 0.1 = 10 %; 0: no bound)";
    fail(source, "effects.max_expected_force_error", msg.str());
  }
  s.effects.max_expected_force_error = fx.max_expected_force_error();
  const Settings defaults;
  s.rates.step_hz = or_default(scene.rates().step_hz(), defaults.rates.step_hz);
  s.rates.viewer_hz = or_default(scene.rates().viewer_hz(), defaults.rates.viewer_hz);
  s.rates.status_hz = or_default(scene.rates().status_hz(), defaults.rates.status_hz);
  const auto& h = scene.haptics();
  s.haptics.force_scale = or_default(h.force_scale(), defaults.haptics.force_scale);
  s.haptics.workspace_scale = or_default(h.workspace_scale(), defaults.haptics.workspace_scale);
  s.haptics.max_force_n = or_default(h.max_force_n(), defaults.haptics.max_force_n);
  for (const auto& t : scene.tools()) {
    ToolDef d;
    d.id = t.id();
    d.tip_radius_m = t.tip_radius_m();
    d.shaft_radius_m = t.shaft_radius_m();
    d.shaft_length_m = t.shaft_length_m();
    d.max_speed_m_per_s = or_default(t.max_speed_m_per_s(), ToolDef{}.max_speed_m_per_s);
    s.tools.push_back(d);
  }
  s.image.file = scene.image().file();
  if (!s.image.file.empty() && std::filesystem::path(s.image.file).is_relative()) {
    s.image.file = (std::filesystem::absolute(source).parent_path() / s.image.file)
                       .lexically_normal()
                       .string();
  }
  s.image.file_unit_m = scene.image().file_unit_m();
  for (const auto& m : scene.meshes()) {
    for (const auto& o : m.openings()) {
      OpeningDef d;
      d.mesh = m.id();
      d.center_m = {o.center_m().x(), o.center_m().y(), o.center_m().z()};
      const Eigen::Vector3d a = to_vec3(o.axis()).normalized();  // non-zero: validated
      d.axis = {a.x(), a.y(), a.z()};
      d.radius_m = o.radius_m();
      s.openings.push_back(d);
    }
  }
  s.max_stations = scene.max_stations() > 0 ? scene.max_stations() : defaults.max_stations;
  return s;
}

Settings load_settings(const std::filesystem::path& path) {
  return read_settings(read_scene(path), path.string());
}

int find_mesh(const Scene& scene, const std::string& id) {
  for (int i = 0; i < scene.meshes_size(); ++i) {
    if (scene.meshes(i).id() == id) return i;
  }
  return -1;
}

}  // namespace neurosim::scene
