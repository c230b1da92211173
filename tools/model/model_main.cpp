// neurosim-model: builds the brain/artery scene from the Colin27 MRI.
// `neurosim-model --help` lists the options.
#include "common/cli.hpp"
#include "tools/model/model.hpp"

#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  namespace cli = neurosim::cli;
  neurosim::model::ModelOptions o;
  std::string out_dir = o.out_dir.string(), material = "literature";
  double seed = o.seed;
  cli::Parser p("neurosim-model",
                "Builds the brain/artery patient scene from the Colin27 MRI: DIR/NAME.scene and "
                "DIR/NAME/{brain,artery}.mesh.");
  p.add_option("--mri", o.mri_path, "the T1 MRI (NIfTI)")->capture_default_str();
  p.add_option("--out-dir", out_dir, "output folder DIR")->capture_default_str();
  p.add_option("--cell-size", o.brain_cell_size_mm, "brain cell size, unit mm")
      ->check(cli::finite())
      ->capture_default_str();
  p.add_option("--artery-cell-size", o.artery_cell_size_mm, "artery cell size, unit mm")
      ->check(cli::finite())
      ->capture_default_str();
  std::vector<double> refine_at;
  auto& refine = o.brain_refinement;
  p.add_option("--refine-at", refine_at,
               "finer brain cells around this point X Y Z, image mm (the mesh files' "
               "coordinates; the scene's, in m, times 1000); needs --refine-cell-size")
      ->expected(3)
      ->check(cli::finite());
  p.add_option("--refine-cell-size", refine.cell_size_mm,
               "brain cell size at --refine-at, unit mm (below --cell-size)")
      ->check(cli::finite());
  p.add_option("--refine-radius", refine.radius_mm,
               "radius of the finest cells around --refine-at, unit mm")
      ->check(cli::finite())
      ->capture_default_str();
  p.add_option("--refine-grading", refine.grading,
               "growth of the cell size beyond --refine-radius, mm per mm, in (0, 1]")
      ->check(cli::finite())
      ->capture_default_str();
  p.add_option("--seed", seed, "mesher seed, an integer in [0, 2^32)")
      ->check(cli::Check(
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
  p.add_option("--material", material, "material set")
      ->check(cli::one_of({"literature", "paper"}))
      ->capture_default_str();
  p.add_option("--name", o.name, "scene name NAME (with --skull: brain_skull unless given)")
      ->capture_default_str();
  bool skull = false;
  p.add_flag("--skull,--approach", skull,
             "write the approach scene instead: AAL brain regions (tissues) and the skull as a "
             "rigid surface with a craniotomy (default NAME brain_skull)");
  std::vector<double> centre, axis;
  double radius_mm = o.opening_radius_mm;
  p.add_option("--opening-center-mni", centre,
               "craniotomy centre X Y Z, MNI mm (default: over the right cerebellar hemisphere)")
      ->expected(3)
      ->check(cli::finite());
  p.add_option("--opening-axis-mni", axis, "craniotomy axis X Y Z, out of the head")
      ->expected(3)
      ->check(cli::finite());
  p.add_option("--opening-radius", radius_mm, "craniotomy radius, unit mm")
      ->check(cli::finite())
      ->capture_default_str();
  p.footer(
      "Exit status 1 on error, 2 on a usage error or when an artery vertex is not inside the "
      "brain.");
  if (auto rc = p.parse(argc, argv)) return *rc;
  o.out_dir = out_dir;
  o.skull = skull;
  if (skull && p.count("--name") == 0) o.name = "brain_skull";
  if ((!centre.empty() || !axis.empty() || p.count("--opening-radius") > 0) && !skull) {
    std::cerr << "neurosim-model: --opening-* options need --skull\n";
    return 2;
  }
  if (!centre.empty() || !axis.empty() || p.count("--opening-radius") > 0) {
    const auto d = neurosim::model::default_suboccipital_opening();
    o.opening_given = true;
    o.opening_center_mni_mm = centre.empty() ? d.center_mm : neurosim::model::Vec3(centre[0], centre[1], centre[2]);
    o.opening_axis_mni = axis.empty() ? d.axis : neurosim::model::Vec3(axis[0], axis[1], axis[2]);
    o.opening_radius_mm = radius_mm;
    o.opening_half_length_mm = d.half_length_mm;
    if (!(o.opening_axis_mni.norm() > 0.0) || !(radius_mm > 0.0)) {
      std::cerr << "neurosim-model: --opening-axis-mni must be non-zero and --opening-radius > 0\n";
      return 2;
    }
  }
  if (refine_at.empty() != (refine.cell_size_mm == 0.0)) {
    std::cerr << "neurosim-model: --refine-at and --refine-cell-size go together\n";
    return 2;
  }
  if (!refine_at.empty()) refine.centre_mm = neurosim::model::Vec3(refine_at[0], refine_at[1], refine_at[2]);
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
