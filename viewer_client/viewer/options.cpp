#include "viewer_client/viewer/options.hpp"

#include <cmath>
#include <stdexcept>

namespace neurosim::viewer {

const char* to_string(Mode m) { return m == Mode::Navigation ? "navigation" : "observe"; }

const char* usage() {
  return "usage: neurosim-viewer --mode navigation|observe [--headless --frames N --out DIR]\n"
         "                       [--duration S] [--wait-server S] [--domain D] [--topic-prefix P]\n"
         "                       [--size WxH] [--fps F] [--volume-step K] [--force-unit N]\n"
         "                       [--summary FILE.json] [--no-overlay]\n"
         "  --mode M          navigation: three MRI slices through the tool tip + surfaces;\n"
         "                    observe: volume rendering of the deformed MRI + surfaces\n"
         "  --headless        render offscreen (needs an X display: run under xvfb-run -a) and\n"
         "                    write PNG frames DIR/frame_0000.png ...\n"
         "  --frames N        headless: stop after N frames (default: no limit)\n"
         "  --out DIR         headless: frame folder (default .)\n"
         "  --duration S      stop after S seconds (default: no limit)\n"
         "  --wait-server S   fail if no MeshTopology arrives within S seconds (default 30)\n"
         "  --domain D        DDS domain id (default: the CYCLONEDDS_URI configuration's)\n"
         "  --topic-prefix P  prepend P to every topic name (as neurosim-server --topic-prefix)\n"
         "  --size WxH        frame size in pixels (default 960x720)\n"
         "  --fps F           render at most F frames per second (default 10)\n"
         "  --volume-step K   observe: volume resampled every K voxels (default 2)\n"
         "  --force-unit N    tool colour f = |F| / N with F in newton (default 1: the paper's\n"
         "                    rule (R,G,B) = (min(0.2+f,1), max(0.2-f,0), max(0.2-f,0)))\n"
         "  --summary FILE    write counters (frames, samples, malformed, server lost) as JSON\n"
         "  --no-overlay      no status text in the frames\n"
         "CYCLONEDDS_URI must be set (deploy/cyclonedds/loopback.xml for local runs).\n";
}

namespace {

double to_double(const std::string& opt, const std::string& s) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || s.empty() || !std::isfinite(v))
    throw std::invalid_argument(opt + ": '" + s + "' is not a number");
  return v;
}

int to_int(const std::string& opt, const std::string& s) {
  std::size_t used = 0;
  long v = 0;
  try {
    v = std::stol(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || s.empty() || v < -2147483647L || v > 2147483647L)
    throw std::invalid_argument(opt + ": '" + s + "' is not an integer");
  return static_cast<int>(v);
}

}  // namespace

ViewerOptions parse_options(int argc, const char* const* argv, bool& help) {
  ViewerOptions o;
  help = false;
  bool have_mode = false, have_frames = false, have_out = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "--mode") {
      const std::string v = value();
      if (v == "navigation")
        o.mode = Mode::Navigation;
      else if (v == "observe")
        o.mode = Mode::Observe;
      else
        throw std::invalid_argument("--mode: '" + v + "' is not navigation or observe");
      have_mode = true;
    } else if (a == "--headless") {
      o.headless = true;
    } else if (a == "--frames") {
      o.frames = to_int(a, value());
      if (o.frames <= 0) throw std::invalid_argument("--frames: must be a positive count");
      have_frames = true;
    } else if (a == "--out") {
      o.out_dir = value();
      if (o.out_dir.empty()) throw std::invalid_argument("--out: empty folder name");
      have_out = true;
    } else if (a == "--duration") {
      o.duration_s = to_double(a, value());
      if (o.duration_s <= 0) throw std::invalid_argument("--duration: must be > 0 s");
    } else if (a == "--wait-server") {
      o.wait_server_s = to_double(a, value());
      if (o.wait_server_s <= 0) throw std::invalid_argument("--wait-server: must be > 0 s");
    } else if (a == "--domain") {
      o.domain = to_int(a, value());
      if (o.domain < 0 || o.domain > 230)
        throw std::invalid_argument("--domain: " + std::to_string(o.domain) +
                                    " is not a domain id in [0, 230]");
    } else if (a == "--topic-prefix") {
      o.topic_prefix = value();
    } else if (a == "--size") {
      const std::string v = value();
      const auto x = v.find('x');
      if (x == std::string::npos)
        throw std::invalid_argument("--size: expected WxH, got '" + v + "'");
      o.width = to_int(a, v.substr(0, x));
      o.height = to_int(a, v.substr(x + 1));
      if (o.width < 64 || o.height < 64 || o.width > 8192 || o.height > 8192)
        throw std::invalid_argument("--size: " + v + " is outside 64x64 .. 8192x8192");
    } else if (a == "--fps") {
      o.fps = to_double(a, value());
      if (o.fps <= 0 || o.fps > 1000) throw std::invalid_argument("--fps: must be in (0, 1000]");
    } else if (a == "--volume-step") {
      o.volume_step = to_int(a, value());
      if (o.volume_step < 1 || o.volume_step > 8)
        throw std::invalid_argument("--volume-step: must be in 1 .. 8");
    } else if (a == "--force-unit") {
      o.force_unit_n = to_double(a, value());
      if (o.force_unit_n <= 0) throw std::invalid_argument("--force-unit: must be > 0 N");
    } else if (a == "--summary") {
      o.summary_file = value();
    } else if (a == "--no-overlay") {
      o.overlay = false;
    } else if (a == "-h" || a == "--help") {
      help = true;
      return o;
    } else {
      throw std::invalid_argument("unknown option '" + a + "'");
    }
  }
  if (!have_mode) throw std::invalid_argument("--mode navigation|observe is required");
  if ((have_frames || have_out) && !o.headless)
    throw std::invalid_argument("--frames and --out need --headless");
  return o;
}

}  // namespace neurosim::viewer
