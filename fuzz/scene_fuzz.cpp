// Fuzz target: the scene parser and validator (server/scene/scene.cpp: protobuf text format,
// validate_scene, read_settings) on any text. What it refuses must be a std::runtime_error
// naming the source; what it accepts must keep the validator's promises: every value within the
// range the validator's own table states (server/scene/ranges.hpp, read here, never restated),
// every referenced mesh present, ids unique.
#include "fuzz/fuzz_target.hpp"
#include "server/scene/ranges.hpp"
#include "server/scene/scene.hpp"

#include <cmath>
#include <stdexcept>

namespace {

namespace sr = neurosim::scene::ranges;
using neurosim::fuzz::require;

void require_in(double v, const sr::Range& r, const char* property) { require(r.contains(v), property); }
void require_in(const neurosim::scene::Vec3& v, const sr::Range& r, const char* property) {
  require(r.contains(v.x()) && r.contains(v.y()) && r.contains(v.z()), property);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace neurosim;
  const std::string text(reinterpret_cast<const char*>(data), size);
  scene::Scene s;
  scene::Settings settings;
  try {
    s = scene::parse_scene(text, "fuzz.scene");
    settings = scene::read_settings(s, "fuzz.scene");
  } catch (const std::runtime_error& e) {
    require(std::string(e.what()).find("fuzz.scene") != std::string::npos,
            "errors name the source");
    return 0;
  }
  // The scene's own values, as the validator's table bounds them.
  require_in(s.rates().step_hz(), sr::kStepRate, "rates.step_hz in kStepRate");
  require_in(s.rates().viewer_hz(), sr::kViewerRate, "rates.viewer_hz in kViewerRate");
  require_in(s.rates().status_hz(), sr::kStatusRate, "rates.status_hz in kStatusRate");
  require_in(s.haptics().force_scale(), sr::kScale, "haptics.force_scale in kScale");
  require_in(s.haptics().workspace_scale(), sr::kScale, "haptics.workspace_scale in kScale");
  require_in(s.haptics().max_force_n(), sr::kMaxForce, "haptics.max_force_n in kMaxForce");
  require_in(s.image().file_unit_m(), sr::kImageFileUnit, "image.file_unit_m in kImageFileUnit");
  require(s.max_stations() >= 0 && s.max_stations() <= sr::kMaxStations, "max_stations in range");
  // Resolved settings: defaults filled in, so no zero left, and still in range.
  const auto& r = settings.rates;
  require(r.step_hz > 0 && sr::kStepRate.contains(r.step_hz), "resolved step_hz in range");
  require(r.viewer_hz > 0 && sr::kViewerRate.contains(r.viewer_hz), "resolved viewer_hz in range");
  require(r.status_hz > 0 && sr::kStatusRate.contains(r.status_hz), "resolved status_hz in range");
  require(settings.max_stations >= 1 && settings.max_stations <= sr::kMaxStations,
          "resolved max_stations in [1, kMaxStations]");
  const auto& h = settings.haptics;
  require(h.max_force_n > 0 && sr::kMaxForce.contains(h.max_force_n), "resolved max_force_n");
  require(h.force_scale > 0 && sr::kScale.contains(h.force_scale), "resolved force_scale");
  for (const auto& t : s.tools()) {
    require(t.tip_radius_m() > 0.0, "tool tip radius > 0");
    require_in(t.tip_radius_m(), sr::kToolRadius, "tool tip radius in kToolRadius");
    require_in(t.shaft_radius_m(), sr::kToolRadius, "tool shaft radius in kToolRadius");
    require_in(t.shaft_length_m(), sr::kToolLength, "tool shaft length in kToolLength");
    require_in(t.max_speed_m_per_s(), sr::kToolSpeed, "tool speed in kToolSpeed");
  }
  for (const auto& t : settings.tools)
    require(t.max_speed_m_per_s > 0 && sr::kToolSpeed.contains(t.max_speed_m_per_s),
            "resolved tool speed in kToolSpeed");
  for (int i = 0; i < s.meshes_size(); ++i) {
    const auto& m = s.meshes(i);
    require(scene::find_mesh(s, m.id()) == i, "mesh ids are unique");
    if (m.has_file_unit_m()) require_in(m.file_unit_m(), sr::kFileUnit, "file_unit_m in kFileUnit");
    if (m.rigid()) {
      for (const auto& o : m.openings()) {
        require_in(o.center_m(), sr::kCoordinate, "opening centre in kCoordinate");
        require(o.radius_m() > 0 && sr::kOpeningRadius.contains(o.radius_m()), "opening radius");
        require(o.half_length_m() > 0 && sr::kOpeningHalfLength.contains(o.half_length_m()),
                "opening half length");
      }
      continue;
    }
    require(m.has_material(), "a deformable mesh has a material");
    require_in(m.material().youngs_modulus_pa(), sr::kYoungsModulus, "E in kYoungsModulus");
    const double nu = m.material().poisson_ratio();
    require(nu > -1.0 && nu < 0.5, "poisson_ratio in (-1, 0.5)");
    for (const auto& t : m.tissues())
      if (t.has_material())
        require_in(t.material().youngs_modulus_pa(), sr::kYoungsModulus,
                   "tissue E in kYoungsModulus");
    if (m.has_generate()) {
      const auto& g = m.generate();
      require(g.target_vertices() >= 0 && g.target_vertices() <= sr::kMaxGeneratedVertices,
              "target_vertices in [0, kMaxGeneratedVertices]");
      require_in(g.cell_size_m(), sr::kLength, "cell_size_m in kLength");
      if (g.has_box()) {
        require_in(g.box().min_m(), sr::kCoordinate, "box.min_m in kCoordinate");
        require_in(g.box().max_m(), sr::kCoordinate, "box.max_m in kCoordinate");
      } else if (g.has_cylinder()) {
        require_in(g.cylinder().base_center_m(), sr::kCoordinate, "cylinder base in kCoordinate");
        require_in(g.cylinder().axis_m(), sr::kCoordinate, "cylinder axis in kCoordinate");
        require(g.cylinder().radius_m() > 0 && sr::kLength.contains(g.cylinder().radius_m()),
                "cylinder radius in kLength, > 0");
      }
    }
  }
  for (const auto& c : s.couplings())
    require(scene::find_mesh(s, c.host()) >= 0 && scene::find_mesh(s, c.embedded()) >= 0,
            "coupled meshes exist");
  for (const auto& p : s.prescribed()) {
    require(scene::find_mesh(s, p.mesh()) >= 0, "prescribed mesh exists");
    require_in(p.displacement_m(), sr::kDisplacement, "prescribed displacement in kDisplacement");
  }
  for (const auto& l : s.loads()) {
    require(scene::find_mesh(s, l.mesh()) >= 0, "loaded mesh exists");
    require_in(l.force_n(), sr::kForce, "load force in kForce");
  }
  return 0;
}
