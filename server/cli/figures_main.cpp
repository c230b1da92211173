// neurosim-figures: the paper's Figures 10, 13 and 14 on the cube/cylinder scene.
//   neurosim-figures [--scene scenes/cube_cylinder.scene] [--out DIR] [--max-depth M] [--frames N]
//                    [--tip-radius M]   (default 0.02 m: a patch of the face, as the paper's user
//                                        pushes it; 0 keeps the scene's tool)
// Writes into DIR: fig10_cylinder.csv/.png (cylinder motion with and without coupling, pushed from
// the right and from the left), fig14_force.csv/.png (reaction force vs push depth, with and
// without coupling), fig13_residual.csv/.png (iterative baseline residual per iteration) and
// .vtu frames of both meshes (deformed positions, displacement_m) for ParaView.
#include "common/cli.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/iterative_tie.hpp"
#include "server/interaction/simulation.hpp"
#include "server/mesh/vtu.hpp"
#include "server/scene/compile.hpp"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

namespace ni = neurosim::interaction;
namespace fs = std::filesystem;

namespace {

void write_frame(const ni::Simulation& sim, int mesh, const fs::path& file) {
  Eigen::VectorXd u;
  sim.displacements(mesh, u);
  const auto& m = sim.mesh(mesh);
  std::vector<neurosim::mesh::Vec3> x(m.num_vertices()), d(m.num_vertices());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    d[v] = u.segment<3>(3 * v);
    x[v] = m.vertices()[v] + d[v];
  }
  neurosim::mesh::write_vtu(file.string(), x, m.tets(),
                            {neurosim::mesh::make_field("displacement_m", d)});
}

bool plot(const fs::path& script) {
  const std::string cmd = "gnuplot " + script.string() + " 2>&1";
  if (std::system(cmd.c_str()) != 0) {
    std::cerr << "neurosim-figures: gnuplot failed on " << script << " (PNG not written)\n";
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_path = "scenes/cube_cylinder.scene";
  fs::path out = "figures";
  double max_depth = 0.01;
  double tip_radius = 0.02;  // the paper pushes a patch of the face, not one node
  int frames = 8;
  std::string out_dir = out.string();
  neurosim::cli::Parser cli("neurosim-figures",
                            "The paper's Figures 10, 13 and 14 on the cube/cylinder scene.");
  cli.add_option("--scene", scene_path, "scene file")->capture_default_str();
  cli.add_option("--out", out_dir, "output folder")->capture_default_str();
  cli.add_option("--max-depth", max_depth, "deepest push, unit m")
      ->check(neurosim::cli::positive())
      ->capture_default_str();
  cli.add_option("--frames", frames, "push frames (>= 1)")
      ->check(neurosim::cli::in_range(1, 1e9))
      ->capture_default_str();
  cli.add_option("--tip-radius", tip_radius, "tool tip radius, unit m (0: the scene's)")
      ->check(neurosim::cli::finite())
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  out = out_dir;
  try {
    fs::create_directories(out);
    auto model = neurosim::scene::load_model(scene_path);
    if (model.tools.empty()) throw std::runtime_error(scene_path + ": no tool");
    if (model.couplings.empty()) throw std::runtime_error(scene_path + ": no coupling");
    if (tip_radius > 0.0) model.tools[0].tip_radius_m = tip_radius;
    const double r = model.tools[0].tip_radius_m;
    std::ofstream fig10(out / "fig10_cylinder.csv"), fig14(out / "fig14_force.csv");
    fig10 << "coupling,side,depth_m,cylinder_max_displacement_m,cylinder_mean_dx_m\n";
    fig14 << "coupling,side,depth_m,force_n,contact_nodes\n";
    std::unique_ptr<ni::Simulation> coupled;
    for (int coupling = 0; coupling <= 1; ++coupling) {
      model.effects.coupling = coupling != 0;
      auto sim = ni::Simulation::build(model);
      const int host = model.couplings[0].host;
      const int emb = model.couplings[0].embedded;
      neurosim::mesh::Vec3 lo, hi;
      sim->mesh(host).bounds(lo, hi);
      const neurosim::mesh::Vec3 c = 0.5 * (lo + hi);
      // Paper Figure 10: (d-f) pushed from the right, (g-i) from the left; (a-c) without coupling.
      for (int side = 0; side < 2; ++side) {
        const double sign = side == 0 ? 1.0 : -1.0;
        for (int k = 0; k <= frames; ++k) {
          const double depth = max_depth * k / frames;
          ni::ToolPose p;
          p.tip_m = neurosim::mesh::Vec3(side == 0 ? hi.x() + r - depth : lo.x() - r + depth, c.y(),
                                         c.z());
          p.axis = neurosim::mesh::Vec3(sign, 0.0, 0.0);
          std::vector<ni::ToolContact> contacts;
          ni::StepStats stats;
          sim->step({p}, contacts, stats);
          Eigen::VectorXd u;
          sim->displacements(emb, u);
          double mean_dx = 0.0;
          for (int v = 0; v < u.size() / 3; ++v) mean_dx += u[3 * v];
          mean_dx /= std::max<Eigen::Index>(1, u.size() / 3);
          const char* sname = side == 0 ? "right" : "left";
          fig10 << coupling << "," << sname << "," << depth << ","
                << (u.size() ? u.cwiseAbs().maxCoeff() : 0.0) << "," << mean_dx << "\n";
          fig14 << coupling << "," << sname << "," << depth << "," << contacts[0].force_n.norm()
                << "," << contacts[0].nodes.size() << "\n";
          if (k == frames || k == frames / 2) {
            const std::string tag = std::string(coupling ? "coupled" : "uncoupled") + "_" + sname +
                                    "_" + std::to_string(k);
            write_frame(*sim, host, out / ("fig10_" + tag + "_" + sim->mesh_id(host) + ".vtu"));
            write_frame(*sim, emb, out / ("fig10_" + tag + "_" + sim->mesh_id(emb) + ".vtu"));
          }
        }
      }
      if (coupling) coupled = std::move(sim);
    }
    fig10.close();
    fig14.close();

    // Paper Figure 13: the iterative method's residual per iteration, for the last push.
    {
      const int host = model.couplings[0].host;
      const ni::CoupledBody* body = coupled->body_of(host);
      std::vector<int> slots;
      std::vector<ni::Vec3> forces;
      coupled->last_contact_forces(host, slots, forces);
      ni::IterativeTie it(*body);
      Eigen::VectorXd ub;
      const auto res = it.solve(slots, forces, it.exact(slots, forces), ub);
      std::ofstream fig13(out / "fig13_residual.csv");
      fig13 << "iteration,relative_residual\n";
      for (std::size_t i = 0; i < res.residual.size(); ++i)
        fig13 << i + 1 << "," << res.residual[i] << "\n";
    }

    std::ofstream gp(out / "figures.gp");
    gp << "set terminal pngcairo size 800,560\nset datafile separator ','\nset key top left\nset "
          "grid\n"
       << "set output '" << (out / "fig14_force.png").string() << "'\n"
       << "set title 'Reaction force vs push depth (paper Fig. 14)'\nset xlabel 'push depth "
          "(mm)'\nset ylabel 'force (N)'\n"
       << "plot '" << (out / "fig14_force.csv").string()
       << "' using ($1==1 && strcol(2) eq 'right' ? $3*1000 : 1/0):4 "
       << "with linespoints title 'with coupling', '' using ($1==0 && strcol(2) eq 'right' ? "
          "$3*1000 : 1/0):4 "
       << "with linespoints title 'without coupling'\n"
       << "set output '" << (out / "fig10_cylinder.png").string() << "'\n"
       << "set title 'Cylinder displacement when the cube is pushed (paper Fig. 10)'\nset ylabel "
          "'max cylinder displacement (mm)'\n"
       << "plot '" << (out / "fig10_cylinder.csv").string()
       << "' using ($1==1 && strcol(2) eq 'right' ? $3*1000 : 1/0):($4*1000) "
       << "with linespoints title 'coupled, from the right', '' using ($1==1 && strcol(2) eq "
          "'left' ? $3*1000 : 1/0):($4*1000) "
       << "with linespoints title 'coupled, from the left', '' using ($1==0 ? $3*1000 : "
          "1/0):($4*1000) "
       << "with linespoints title 'without coupling'\n"
       << "set output '" << (out / "fig13_residual.png").string() << "'\n"
       << "set title 'Iterative baseline: boundary residual per iteration (paper Fig. 13)'\nset "
          "logscale y\n"
       << "set xlabel 'iteration'\nset ylabel 'relative residual'\n"
       << "plot '" << (out / "fig13_residual.csv").string()
       << "' using 1:2 every ::1 with lines title 'iterative'\n";
    gp.close();
    plot(out / "figures.gp");
    std::cout << "neurosim-figures: wrote " << out.string()
              << "/fig10_cylinder.{csv,png}, fig14_force.{csv,png}, "
              << "fig13_residual.{csv,png}, fig10_*.vtu\n";
  } catch (const std::exception& ex) {
    std::cerr << "neurosim-figures: " << ex.what() << "\n";
    return 1;
  }
  return 0;
}
