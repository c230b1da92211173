// neurosim-viewer's run loop: DDS -> state -> pipeline -> window or PNG frames.
#pragma once

#include "viewer_client/viewer/options.hpp"

#include <atomic>
#include <ostream>

namespace neurosim::viewer {

// Runs until --frames / --duration / *stop / the window closes. Returns the process exit code:
// 0 done, 1 runtime failure (no server within --wait-server, DDS, output folder), 2 no display.
// Progress and warnings go to `log`.
int run_viewer(const ViewerOptions& options, std::ostream& log, const std::atomic<bool>* stop);

}  // namespace neurosim::viewer
