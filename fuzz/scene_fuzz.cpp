// Fuzz target: the scene parser and validator (server/scene/scene.cpp: protobuf text format,
// validate_scene, read_settings) on any text. What it refuses must be a std::runtime_error
// naming the source; what it accepts must keep the validator's promises: every setting within
// its stated range, every referenced mesh present.
#include "fuzz/fuzz_target.hpp"
#include "server/scene/scene.hpp"

#include <cmath>
#include <stdexcept>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace neurosim;
  const std::string text(reinterpret_cast<const char*>(data), size);
  scene::Scene s;
  scene::Settings settings;
  try {
    s = scene::parse_scene(text, "fuzz.scene");
    settings = scene::read_settings(s, "fuzz.scene");
  } catch (const std::runtime_error& e) {
    fuzz::require(std::string(e.what()).find("fuzz.scene") != std::string::npos,
                  "errors name the source");
    return 0;
  }
  const auto& r = settings.rates;
  fuzz::require(r.step_hz >= 10.0 && r.step_hz <= 1e5, "rates.step_hz in [10, 1e5] Hz");
  fuzz::require(r.viewer_hz >= 0.1 && r.viewer_hz <= 1e3, "rates.viewer_hz in [0.1, 1e3] Hz");
  fuzz::require(r.status_hz >= 0.1 && r.status_hz <= 100.0, "rates.status_hz in [0.1, 100] Hz");
  fuzz::require(settings.max_stations >= 1 && settings.max_stations <= 64,
                "max_stations in [1, 64]");
  const auto& h = settings.haptics;
  fuzz::require(h.max_force_n > 0.0 && h.max_force_n <= 100.0, "haptics.max_force_n in (0, 100] N");
  fuzz::require(h.force_scale > 0.0 && h.force_scale <= 1e3, "haptics.force_scale in (0, 1e3]");
  for (const auto& t : settings.tools) {
    fuzz::require(t.tip_radius_m > 0.0 && t.tip_radius_m <= 0.1, "tool tip radius in (0, 0.1] m");
    fuzz::require(t.max_speed_m_per_s > 0.0 && t.max_speed_m_per_s <= 100.0,
                  "tool speed in (0, 100] m/s");
  }
  for (int i = 0; i < s.meshes_size(); ++i) {
    const auto& m = s.meshes(i);
    fuzz::require(scene::find_mesh(s, m.id()) == i, "mesh ids are unique");
    const double e = m.material().youngs_modulus_pa();
    fuzz::require(e >= 1.0 && e <= 1e12, "E in [1, 1e12] Pa");
  }
  for (const auto& c : s.couplings())
    fuzz::require(scene::find_mesh(s, c.host()) >= 0 && scene::find_mesh(s, c.embedded()) >= 0,
                  "coupled meshes exist");
  for (const auto& p : s.prescribed()) {
    fuzz::require(scene::find_mesh(s, p.mesh()) >= 0, "prescribed mesh exists");
    for (double u : {p.displacement_m().x(), p.displacement_m().y(), p.displacement_m().z()})
      fuzz::require(std::abs(u) <= 1.0, "prescribed displacement within 1 m");
  }
  for (const auto& l : s.loads())
    fuzz::require(scene::find_mesh(s, l.mesh()) >= 0, "loaded mesh exists");
  return 0;
}
