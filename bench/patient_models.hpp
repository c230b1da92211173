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

// DIR/c<cell>_r<fine>_at<x>_<y>_<z>/brain_artery.scene: the same brain with cells of fine_mm
// within radius_mm of the image point centre_mm (mm), growing by grading mm per mm beyond
// (neurosim-model --refine-at X Y Z --refine-cell-size fine ...), built once like scene_at.
inline std::filesystem::path refined_scene_at(double cell_mm, double fine_mm, const double (&centre_mm)[3],
                                              double radius_mm, double grading,
                                              const std::filesystem::path& dir, const char* program) {
  char name[128];
  std::snprintf(name, sizeof name, "c%g_r%g_at%.2f_%.2f_%.2f_R%g_g%g", cell_mm, fine_mm, centre_mm[0],
                centre_mm[1], centre_mm[2], radius_mm, grading);
  const std::filesystem::path d = dir / name;
  const std::filesystem::path scene = d / "brain_artery.scene";
  if (!std::filesystem::exists(scene)) {
    std::filesystem::create_directories(d);
    char flags[256];
    std::snprintf(flags, sizeof flags,
                  " --cell-size %.17g --refine-at %.17g %.17g %.17g --refine-cell-size %.17g "
                  "--refine-radius %.17g --refine-grading %.17g",
                  cell_mm, centre_mm[0], centre_mm[1], centre_mm[2], fine_mm, radius_mm, grading);
    const std::string cmd = std::string(NEUROSIM_BIN_DIR) + "/neurosim-model --out-dir '" + d.string() + "'" +
                            flags + " > '" + (d / "model.log").string() + "' 2>&1";
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
