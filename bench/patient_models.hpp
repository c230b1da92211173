// The patient models the scaling benchmarks measure: the brain_artery scene built by
// neurosim-model at a given cell size (once per directory, then reused), and the process's
// memory as /proc/self/status states it. Used by scale_bench, ordering_bench and
// contact_convergence_bench.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <stdexcept>
#include <string>

namespace neurosim::bench {

// DIR/c<cell>/brain_artery.scene, built by NEUROSIM_BIN_DIR/neurosim-model --cell-size <cell>
// if it is not there yet (its log beside it); `program` names the caller in the progress line.
inline std::filesystem::path scene_at(double cell_mm, const std::filesystem::path& dir,
                                      const char* program) {
  char name[32];
  std::snprintf(name, sizeof name, "c%g", cell_mm);
  const std::filesystem::path d = dir / name;
  const std::filesystem::path scene = d / "brain_artery.scene";
  if (!std::filesystem::exists(scene)) {
    std::filesystem::create_directories(d);
    const std::string cmd = std::string(NEUROSIM_BIN_DIR) + "/neurosim-model --out-dir '" +
                            d.string() + "' --cell-size " + std::to_string(cell_mm) + " > '" +
                            (d / "model.log").string() + "' 2>&1";
    std::cerr << program << ": building " << scene << "\n";
    if (std::system(cmd.c_str()) != 0)
      throw std::runtime_error("neurosim-model failed (log: " + (d / "model.log").string() + ")");
  }
  return scene;
}

// A field of /proc/self/status in kB (VmRSS, VmHWM, ...), unit MB (-1 if unreadable).
inline double status_mb(const char* field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::string key = std::string(field) + ":";
  while (std::getline(in, line))
    if (line.compare(0, key.size(), key) == 0) return std::stod(line.substr(key.size())) / 1024.0;
  return -1.0;
}

}  // namespace neurosim::bench
