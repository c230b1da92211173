// neurosim-model: builds the brain/artery scene from the Colin27 MRI.
#include "tools/model/model.hpp"

#include <cstdlib>
#include <iostream>
#include <stdexcept>
#include <string>

namespace {

const char* kUsage =
    "usage: neurosim-model [--mri FILE] [--out-dir DIR] [--cell-size MM] [--artery-cell-size MM]\n"
    "                      [--seed N] [--material literature|paper] [--name NAME]\n"
    "Writes DIR/NAME.scene and DIR/NAME/{brain,artery}.mesh (defaults: the Colin27 ch2bet MRI,\n"
    "scenes, brain_artery, cell size 7.0 mm, artery cell size 0.9 mm, seed 1, literature).\n"
    "Exit status 1 on error, 2 when an artery vertex is not inside the brain.\n";

double parse_double(const std::string& flag, const std::string& value) {
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != value.size()) throw std::invalid_argument(flag + ": not a number: " + value);
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  neurosim::model::ModelOptions o;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a == "-h" || a == "--help") {
        std::cout << kUsage;
        return 0;
      }
      if (i + 1 >= argc) throw std::invalid_argument(a + ": missing value (or unknown option)");
      const std::string v = argv[++i];
      if (a == "--mri") {
        o.mri_path = v;
      } else if (a == "--out-dir") {
        o.out_dir = v;
      } else if (a == "--name") {
        o.name = v;
      } else if (a == "--cell-size") {
        o.brain_cell_size_mm = parse_double(a, v);
      } else if (a == "--artery-cell-size") {
        o.artery_cell_size_mm = parse_double(a, v);
      } else if (a == "--seed") {
        const double s = parse_double(a, v);
        if (!(s >= 0.0 && s <= 4294967295.0) ||
            s != static_cast<double>(static_cast<long long>(s))) {
          throw std::invalid_argument("--seed: need an integer in [0, 2^32): " + v);
        }
        o.seed = static_cast<std::uint32_t>(s);
      } else if (a == "--material") {
        if (v == "literature") {
          o.material = neurosim::model::MaterialSet::Literature;
        } else if (v == "paper") {
          o.material = neurosim::model::MaterialSet::Paper;
        } else {
          throw std::invalid_argument("--material: literature or paper, not " + v);
        }
      } else {
        throw std::invalid_argument("unknown option " + a);
      }
    }
    const auto result = neurosim::model::build_model(o);
    std::cout << neurosim::model::summary(result);
    return result.artery_vertices_outside == 0 ? 0 : 2;
  } catch (const std::exception& e) {
    std::cerr << "neurosim-model: " << e.what() << "\n" << kUsage;
    return 1;
  }
}
