#include "viewer_client/viewer/options.hpp"

#include "common/cli.hpp"

#include <cmath>
#include <stdexcept>

namespace neurosim::viewer {

const char* to_string(Mode m) { return m == Mode::Navigation ? "navigation" : "observe"; }

const char* to_string(SkullMode m) {
  switch (m) {
    case SkullMode::Shown: return "shown";
    case SkullMode::Transparent: return "transparent";
    case SkullMode::Hidden: return "hidden";
  }
  return "?";
}

SkullMode next(SkullMode m) {
  switch (m) {
    case SkullMode::Shown: return SkullMode::Transparent;
    case SkullMode::Transparent: return SkullMode::Hidden;
    case SkullMode::Hidden: return SkullMode::Shown;
  }
  return SkullMode::Shown;
}

const char* to_string(ColourMode m) { return m == ColourMode::Region ? "region" : "plain"; }

ViewerOptions parse_options(int argc, const char* const* argv, bool& help) {
  namespace cli = neurosim::cli;
  ViewerOptions o;
  help = false;
  std::string mode;
  cli::Parser p("neurosim-viewer",
                "The navigation / observer station: deformed surfaces, the tool coloured by "
                "force, the MRI resampled through the deformed meshes.");
  p.add_option("--mode", mode,
               "navigation: three MRI slices through the tool tip + surfaces; observe: volume "
               "rendering of the deformed MRI + surfaces")
      ->required()
      ->check(cli::one_of({"navigation", "observe"}));
  auto* headless = p.add_flag("--headless", o.headless,
                              "render offscreen (needs an X display: run under xvfb-run -a) "
                              "and write PNG frames DIR/frame_0000.png ...");
  p.add_option("--frames", o.frames, "headless: stop after N frames (default: no limit)")
      ->check(cli::in_range(1, 2147483647))
      ->needs(headless);
  p.add_option("--out", o.out_dir, "headless: frame folder")
      ->capture_default_str()
      ->check(cli::Check(
          [](std::string& v) {
            return v.empty() ? std::string("empty folder name") : std::string();
          },
          "DIR"))
      ->needs(headless);
  p.add_option("--duration", o.duration_s, "stop after S seconds (default: no limit)")
      ->check(cli::positive());
  p.add_option("--wait-server", o.wait_server_s, "fail if no MeshTopology arrives within S seconds")
      ->check(cli::positive())
      ->capture_default_str();
  p.add_option("--domain", o.domain, "DDS domain id (default: the CYCLONEDDS_URI configuration's)")
      ->check(cli::in_range(0, 230));
  p.add_option("--topic-prefix", o.topic_prefix,
               "prepend P to every topic name (as neurosim-server --topic-prefix)");
  p.add_option_function<std::string>(
       "--size",
       [&o](const std::string& v) {
         const auto x = v.find('x');
         int w = 0, h = 0;
         try {
           if (x == std::string::npos) throw std::invalid_argument("no x");
           std::size_t used_w = 0, used_h = 0;
           w = std::stoi(v.substr(0, x), &used_w);
           h = std::stoi(v.substr(x + 1), &used_h);
           if (used_w != x || used_h != v.size() - x - 1) throw std::invalid_argument("junk");
         } catch (const std::exception&) {
           throw cli::UsageError("--size: expected WxH, got '" + v + "'");
         }
         if (w < 64 || h < 64 || w > 8192 || h > 8192)
           throw cli::UsageError("--size: " + v + " is outside 64x64 .. 8192x8192");
         o.width = w;
         o.height = h;
       },
       "frame size in pixels (default 960x720)")
      ->type_name("WxH");
  p.add_option("--fps", o.fps, "render at most F frames per second")
      ->check(cli::positive())
      ->check(cli::in_range(0, 1000))
      ->capture_default_str();
  p.add_option("--volume-step", o.volume_step, "observe: volume resampled every K voxels")
      ->check(cli::in_range(1, 8))
      ->capture_default_str();
  p.add_option("--force-unit", o.force_unit_n,
               "tool colour f = |F| / N with F in newton (default 1: the paper's rule (R,G,B) "
               "= (min(0.2+f,1), max(0.2-f,0), max(0.2-f,0)))")
      ->check(cli::positive());
  p.add_option("--summary", o.summary_file,
               "write counters (frames, samples, malformed, server lost) as JSON");
  std::string skull = "shown", colour = "plain";
  p.add_option("--skull", skull,
               "rigid meshes (the skull): shown (opaque bone), transparent or hidden; key 'k' "
               "cycles them on screen")
      ->check(cli::one_of({"shown", "transparent", "hidden"}))
      ->capture_default_str();
  p.add_option("--colour", colour,
               "surfaces: plain (brain tan, vessels red) or region (each brain region its own "
               "colour, from the topology's tissue labels)")
      ->check(cli::one_of({"plain", "region"}))
      ->capture_default_str();
  auto* view_from =
      p.add_triple("--view-from", o.view_from,
                   "3-D view: look at the scene from direction X,Y,Z (scene frame, e.g. a "
                   "craniotomy's axis; default from the right, anterior and above)");
  bool no_overlay = false;
  p.add_flag("--no-overlay", no_overlay, "no status text in the frames");
  p.footer("CYCLONEDDS_URI must be set (deploy/cyclonedds/loopback.xml for local runs).");
  if (!p.parse_or_throw(argc, argv)) {
    help = true;
    return ViewerOptions{};
  }
  o.mode = mode == "observe" ? Mode::Observe : Mode::Navigation;
  o.overlay = !no_overlay;
  o.skull = skull == "transparent" ? SkullMode::Transparent
            : skull == "hidden"    ? SkullMode::Hidden
                                   : SkullMode::Shown;
  o.colour = colour == "region" ? ColourMode::Region : ColourMode::Plain;
  if (view_from->count() > 0 &&
      !(std::hypot(o.view_from[0], o.view_from[1], o.view_from[2]) > 1e-9))
    throw cli::UsageError("--view-from: the direction must not be (nearly) zero");
  return o;
}

}  // namespace neurosim::viewer
