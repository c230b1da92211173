// neurosim-viewer command line: what to show, where to write frames, which DDS domain.
#pragma once

#include <array>
#include <string>
#include <vector>

namespace neurosim::viewer {

enum class Mode {
  Navigation,  // three orthogonal MRI slices through the tool tip + surfaces
  Observe,     // volume rendering of the resampled MRI + surfaces
};
const char* to_string(Mode m);

// How rigid meshes (the skull) are drawn.
enum class SkullMode { Shown, Transparent, Hidden };
const char* to_string(SkullMode m);
// The next mode of the interactive cycle: shown -> transparent -> hidden -> shown.
SkullMode next(SkullMode m);

// How the deformable surfaces are coloured: plain (brain tan, vessels red) or by region (the
// tissue of each surface triangle, when the topology carries regions).
enum class ColourMode { Plain, Region };
const char* to_string(ColourMode m);

struct ViewerOptions {
  Mode mode = Mode::Navigation;
  bool headless = false;      // render offscreen, write PNG frames into out_dir
  int frames = 0;             // headless: stop after this many frames (0: no limit)
  std::string out_dir = ".";  // headless: frame_0000.png ...
  double duration_s = 0;      // stop after this long (0: no limit), unit s
  double wait_server_s = 30;  // give up if no MeshTopology arrives within this, unit s
  int domain = -1;            // DDS domain id (-1: the CYCLONEDDS_URI configuration's)
  std::string topic_prefix;   // prepended to every topic name, as neurosim-server's
  int width = 960;            // window / frame size, unit px
  int height = 720;
  double fps = 10;            // render at most this often, unit 1/s
  int volume_step = 2;        // observe: resample the volume every this many voxels
  double force_unit_n = 1.0;  // colour rule's f = |F| / force_unit_n (paper: F in N, so 1 N)
  std::string summary_file;   // JSON summary written at exit ("" none)
  bool overlay = true;        // status text in the frame
  SkullMode skull = SkullMode::Shown;
  ColourMode colour = ColourMode::Plain;
  // 3-D view: the camera looks at the scene's centre from this direction (scene frame; zero:
  // the default, from the right, a little anterior and above).
  std::array<double, 3> view_from{0, 0, 0};
};

// Parses argv (common/cli: CLI11). Throws std::invalid_argument (cli::UsageError) with a message
// naming the option on any bad or missing value or unknown option. For --help or --version it
// prints the help or version on stdout, sets help = true and returns defaults.
ViewerOptions parse_options(int argc, const char* const* argv, bool& help);

}  // namespace neurosim::viewer
