// neurosim-model: builds the brain/artery scene from the Colin27 MRI.
// `neurosim-model --help` lists the options.
#include "common/cli.hpp"
#include "tools/model/model.hpp"

#include <iostream>
#include <stdexcept>
#include <string>

int main(int argc, char** argv) {
  namespace cli = neurosim::cli;
  neurosim::model::ModelOptions o;
  std::string out_dir = o.out_dir.string(), material = "literature";
  double seed = o.seed;
  cli::Parser p("neurosim-model",
                "Builds the brain/artery patient scene from the Colin27 MRI: DIR/NAME.scene and "
                "DIR/NAME/{brain,artery}.mesh.");
  p->add_option("--mri", o.mri_path, "the T1 MRI (NIfTI)")->capture_default_str();
  p->add_option("--out-dir", out_dir, "output folder DIR")->capture_default_str();
  p->add_option("--cell-size", o.brain_cell_size_mm, "brain cell size, unit mm")
      ->check(cli::finite())
      ->capture_default_str();
  p->add_option("--artery-cell-size", o.artery_cell_size_mm, "artery cell size, unit mm")
      ->check(cli::finite())
      ->capture_default_str();
  p->add_option("--seed", seed, "mesher seed, an integer in [0, 2^32)")
      ->check(CLI::Validator(
          [](std::string& v) {
            double s = -1;
            try {
              std::size_t used = 0;
              s = std::stod(v, &used);
              if (used != v.size()) s = -1;
            } catch (const std::exception&) {
            }
            const bool ok = s >= 0.0 && s <= 4294967295.0 &&
                            s == static_cast<double>(static_cast<long long>(s));
            return ok ? std::string() : "need an integer in [0, 2^32): " + v;
          },
          "N"))
      ->capture_default_str();
  p->add_option("--material", material, "material set")
      ->check(CLI::IsMember({"literature", "paper"}))
      ->capture_default_str();
  p->add_option("--name", o.name, "scene name NAME")->capture_default_str();
  p->footer(
      "Exit status 1 on error, 2 on a usage error or when an artery vertex is not inside the "
      "brain.");
  if (auto rc = p.parse(argc, argv)) return *rc;
  o.out_dir = out_dir;
  o.seed = static_cast<std::uint32_t>(seed);
  o.material = material == "paper" ? neurosim::model::MaterialSet::Paper
                                   : neurosim::model::MaterialSet::Literature;
  try {
    const auto result = neurosim::model::build_model(o);
    std::cout << neurosim::model::summary(result);
    return result.artery_vertices_outside == 0 ? 0 : 2;
  } catch (const std::exception& e) {
    std::cerr << "neurosim-model: " << e.what() << "\n";
    return 1;
  }
}
