// press_refinement_bench: the coarse brain's patch press (FemBrainPress's problem: the Colin27
// brain of `neurosim-model --cell-size C`, the surface nodes within 12 mm (--patch-radius) of the topmost node
// held and pressed straight down) solved by CalculiX C3D10 (a node at the middle of every edge)
// and by smoothed-tet and linear-tet on the same mesh, in NONLINEAR (neo-Hookean as
// fem::write_calculix_input: C10 = E / (4 (1 + nu)), D1 = 6 (1 - 2 nu) / E; ccx NLGEOM, equal
// increments, *CONTROLS 1e-9; ours fem::EquilibriumSolver) and LINEAR (ccx *ELASTIC; ours
// fem::StaticSolver), on the mesh and on its 1 -> 8 splits (tet_split.hpp: the same geometry,
// clamp and patch: a new node is held when both ends of its edge are). The question: how much of
// an element's ratio to C3D10 on the coarse mesh is C3D10's own error there (C3D10 is
// conforming: with the patch held its force is above the continuum's and falls under refinement).
//
// --region R: the press's neighbourhood only (sub_model.hpp: the tetrahedra with centroid within
// R of the topmost node, the cut faces clamped, each split keeping exactly that clamp), so that
// C3D10 NLGEOM on the split mesh runs in minutes; a different problem from the whole brain's
// (a nearer clamp), the same for every element and split. --region 0: the whole brain, its base
// fixed as in the scene.
//
// Prints per mesh, nu and model: each element's patch force and its ratio to C3D10 on the same
// mesh and on the finest mesh C3D10 ran on; writes DIR/press_refinement.csv. With three or more
// meshes, the converged answer: Richardson extrapolation of each element's three finest forces
// (F(h) = F* + C h^p, h halved per split: observed order p = log2((F0 - F1) / (F1 - F2)),
// F* = F2 - (F1 - F2) / (2^p - 1)), refused (printed as nan, with the reason) when the
// differences change sign or the order is below 0.3 (no asymptotic range); and every force
// against C3D10's extrapolated limit. Writes DIR/press_refinement_limits.csv. --disc-table FILE:
// the unsplit mesh's LINEAR discretization error against the converged answer (C3D10's limit, or
// smoothed-tet's when C3D10 ran on fewer than three meshes), keyed by the whole scene mesh: the
// brain's rows of share/accuracy/discretization_error.csv.
// `press_refinement_bench --out DIR --region 40 --splits 1 --depth 10 --nu 0.49`.
#include "c3d10_press.hpp"
#include "common/cli.hpp"
#include "richardson.hpp"
#include "server/fem/calculix.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/static_solver.hpp"
#include "server/scene/compile.hpp"
#include "sub_model.hpp"
#include "tet_split.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace fs = std::filesystem;
namespace fem = neurosim::fem;
using Vec3 = Eigen::Vector3d;

namespace {

constexpr double kPatchRadiusMm = 12.0;  // FemBrainPress's patch: within 12 mm of the top node

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The patch force along +z (the tissue pushing back up) from reactions, unit N.
double patch_force(const Eigen::VectorXd& reaction_n, const std::vector<int>& nodes) {
  double f = 0.0;
  for (int v : nodes) f -= reaction_n[3 * v + 2];
  return f;
}

using Quadratic = neurosim::bench::QuadraticTets;

// C3D10 by ccx (one thread; c3d10_press.hpp): the patch force, unit N.
double c3d10_force(const Quadratic& q, const fem::Material& mat, const std::vector<int>& fixed_q,
                   const std::vector<int>& patch_q, double depth_m, bool nlgeom, int increments,
                   const fs::path& dir, const std::string& job) {
  neurosim::bench::C3d10Press press;
  press.nlgeom = nlgeom;
  press.increments = increments;
  press.timeout_s = 7200.0;
  const auto r = neurosim::bench::run_c3d10_press(dir, job, "press_refinement_bench", q, mat,
                                                  fixed_q, patch_q, Vec3(0.0, 0.0, -depth_m),
                                                  press);
  return patch_force(r.reaction_n, patch_q);
}

// Our element on the corner mesh: NONLINEAR (EquilibriumSolver) or LINEAR (StaticSolver).
double element_force(const neurosim::mesh::TetMesh& m, fem::Material mat, fem::Element element,
                     const std::vector<int>& fixed, const std::vector<int>& patch, double depth_m,
                     bool nonlinear) {
  mat.element = element;
  const fem::MaterialMap mats = fem::MaterialMap::uniform(mat);
  if (nonlinear) {
    fem::PrescribedDofs pressed;
    pressed.nodes = patch;
    pressed.displacement_m = Vec3(0.0, 0.0, -depth_m);
    fem::EquilibriumSolver solver({&m, mats, fem::Tier::kNonlinear, fixed, {pressed}, {}});
    fem::NewtonOptions o;
    o.tangent_predictor = true;
    const auto s = solver.solve(Eigen::VectorXd(), o);
    return patch_force(s.reaction_n, patch);
  }
  Eigen::VectorXd values(3 * static_cast<Eigen::Index>(patch.size()));
  for (std::size_t i = 0; i < patch.size(); ++i)
    values.segment<3>(3 * static_cast<Eigen::Index>(i)) = Vec3(0.0, 0.0, -depth_m);
  const auto s = fem::StaticSolver(m, mats, fixed).solve_prescribed(patch, values);
  return patch_force(s.reaction_n, patch);
}

using neurosim::bench::Limit;
using neurosim::bench::richardson;

struct Level {
  int split{0};
  std::size_t nodes{0}, tets{0}, patch_nodes{0}, c3d10_nodes{0};
};

struct Result {
  int split;
  double nu;
  std::string model, element;  // model: NONLINEAR / LINEAR; element: C3D10, smoothed-tet, ...
  double force_n, seconds;
};

}  // namespace

int main(int argc, char** argv) {
  std::string out_dir, disc_table, table_scene = "brain_artery";
  double cell_mm = 10.0, depth_mm = 10.0, region_mm = 0.0, patch_mm = kPatchRadiusMm;
  int splits = 1, c3d10_splits = -1, increments = 10;
  std::vector<double> nus;
  bool skip_linear = false, skip_nonlinear = false, keep_pinned = false;
  neurosim::cli::Parser cli("press_refinement_bench",
                            "The coarse brain's patch press in C3D10 (ccx), smoothed-tet and "
                            "linear-tet, NONLINEAR and LINEAR, on the mesh and its 1 -> 8 splits.");
  cli.add_option("--out", out_dir, "output folder (models, ccx decks, press_refinement.csv)")
      ->required();
  cli.add_option("--cell-size", cell_mm, "neurosim-model --cell-size, unit mm")
      ->capture_default_str();
  cli.add_option("--depth", depth_mm, "press depth, unit mm")->capture_default_str();
  cli.add_option("--patch-radius", patch_mm,
                 "the held patch: surface nodes within this distance of the top node, unit mm")
      ->check(neurosim::cli::range(1.0, 80.0))
      ->capture_default_str();
  cli.add_option("--region", region_mm,
                 "sub-model radius around the top node, unit mm (0: the whole brain)")
      ->capture_default_str();
  cli.add_option("--splits", splits, "1 -> 8 splits: meshes 0..N")
      ->check(neurosim::cli::range(0, 3))
      ->capture_default_str();
  cli.add_option("--c3d10-splits", c3d10_splits, "C3D10 on meshes 0..N only (default: all)");
  cli.add_option("--increments", increments, "ccx NLGEOM equal increments")->capture_default_str();
  cli.add_option("--nu", nus, "Poisson ratio, repeatable (default 0.49)");
  cli.add_flag("--no-linear", skip_linear, "NONLINEAR only");
  cli.add_flag("--no-nonlinear", skip_nonlinear, "LINEAR only");
  cli.add_flag("--keep-pinned", keep_pinned,
               "--region: a fixed node of the mesh inside the region stays fixed (the bundled brain's "
               "pinned fragment near the top, --cell-size 5); refused without");
  cli.add_option("--disc-table", disc_table,
                 "write the LINEAR press's discretization rows of the unsplit mesh against the "
                 "converged answer to this file (share/accuracy/discretization_error.csv's "
                 "format, keyed by the whole scene mesh; needs --splits 2 or more)");
  cli.add_option("--table-scene", table_scene, "the scene column of --disc-table's rows")
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  if (skip_linear && skip_nonlinear) {
    std::fprintf(stderr, "press_refinement_bench: error: --no-linear and --no-nonlinear leave nothing to run\n");
    return 2;
  }
  if (keep_pinned && region_mm <= 0.0) {
    std::fprintf(stderr, "press_refinement_bench: error: --keep-pinned needs --region (the whole "
                         "brain keeps every fixed node anyway)\n");
    return 2;
  }
  if (!disc_table.empty() && (skip_linear || splits < 2)) {
    std::fprintf(stderr, "press_refinement_bench: error: --disc-table needs the LINEAR press on "
                         "three meshes (--splits 2 or more, no --no-linear)\n");
    return 2;
  }
  if (nus.empty()) nus.push_back(0.49);
  if (c3d10_splits < 0) c3d10_splits = splits;
  try {
    const fs::path out(out_dir);
    const fs::path models = out / "models";
    fs::create_directories(models);
    const std::string name = "brain_press_c" + std::to_string(static_cast<int>(std::lround(cell_mm * 10)));
    if (!fs::exists(models / (name + ".scene"))) {
      const std::string cmd = std::string(NEUROSIM_BIN_DIR) + "/neurosim-model --cell-size " +
                              std::to_string(cell_mm) + " --name " + name + " --out-dir '" +
                              models.string() + "' > '" + (models / (name + ".log")).string() +
                              "' 2>&1";
      if (std::system(cmd.c_str()) != 0)
        throw std::runtime_error("neurosim-model failed (log " + (models / (name + ".log")).string() + ")");
    }
    neurosim::scene::Model model = neurosim::scene::load_model(models / (name + ".scene"));
    neurosim::scene::LoadedMesh brain = model.meshes.front();
    // The whole scene mesh: what --disc-table's rows are keyed by (the server's host).
    const std::size_t host_vertices = brain.mesh.num_vertices(), host_tets = brain.mesh.num_tets();
    const double depth_m = depth_mm * 1e-3;

    // The top node of the whole brain; the region around it.
    auto top_of = [](const neurosim::mesh::TetMesh& m) {
      int top = m.surface_vertices().front();
      for (int v : m.surface_vertices())
        if (m.vertices()[static_cast<std::size_t>(v)].z() > m.vertices()[static_cast<std::size_t>(top)].z()) top = v;
      return top;
    };
    const Vec3 top_x = brain.mesh.vertices()[static_cast<std::size_t>(top_of(brain.mesh))];
    std::vector<neurosim::mesh::Tri> cut_faces;
    const bool region = region_mm > 0.0;
    if (region) cut_faces = neurosim::bench::cut_region(brain, top_x, region_mm * 1e-3, keep_pinned);
    // The patch on the first mesh: the surface nodes within --patch-radius of the top
    // (FemBrainPress's: 12 mm).
    std::vector<int> patch;  // ascending, as split_node_set keeps it
    {
      std::vector<char> in_patch(brain.mesh.num_vertices(), 0);
      for (int v : brain.mesh.surface_vertices())
        if ((brain.mesh.vertices()[static_cast<std::size_t>(v)] - top_x).norm() < patch_mm * 1e-3)
          in_patch[static_cast<std::size_t>(v)] = 1;
      for (int v : brain.fixed_nodes)
        if (in_patch[static_cast<std::size_t>(v)])
          throw std::runtime_error("the patch holds a clamped node: a larger --region");
      for (std::size_t v = 0; v < in_patch.size(); ++v)
        if (in_patch[v]) patch.push_back(static_cast<int>(v));
    }

    std::ofstream csv(out / "press_refinement.csv");
    csv << "split,nodes,tets,patch_nodes,nu,model,element,force_n,solve_s\n";
    std::vector<Level> levels;
    std::vector<Result> results;
    for (int s = 0; s <= splits; ++s) {
      if (s > 0) {
        // The patch follows the split: a midpoint is in it when both ends of its edge are.
        patch = neurosim::bench::split_node_set(neurosim::bench::split_tets(brain.mesh), patch);
        if (region) neurosim::bench::split_region(brain, cut_faces);
        else neurosim::bench::split_loaded_mesh(brain);
      }
      const auto& m = brain.mesh;
      Level lv{s, m.num_vertices(), m.num_tets(), patch.size(), 0};
      const bool ccx = s <= c3d10_splits;
      Quadratic q;
      std::vector<int> fixed_q, patch_q;
      if (ccx) {
        q = neurosim::bench::quadratic_tets(m);
        lv.c3d10_nodes = q.nodes.size();
        patch_q = q.with_mid(patch);
        if (region) {  // exactly the cut faces clamped (their edges' mid-nodes, no other edge)
          fixed_q = neurosim::bench::clamp_of_faces(q, brain.fixed_nodes, cut_faces);
        } else {
          fixed_q = q.with_mid(brain.fixed_nodes);
        }
      }
      levels.push_back(lv);
      std::fprintf(stderr,
                   "mesh split %d: %zu nodes, %zu tetrahedra, %zu fixed, %zu pressed (C3D10: %zu "
                   "nodes%s)\n",
                   s, lv.nodes, lv.tets, brain.fixed_nodes.size(), lv.patch_nodes, lv.c3d10_nodes,
                   ccx ? "" : ", not run");
      for (double nu : nus) {
        fem::Material mat = brain.material;
        mat.poisson_ratio = nu;
        for (bool nonlinear : {true, false}) {
          if (!nonlinear && skip_linear) continue;
          if (nonlinear && skip_nonlinear) continue;
          const std::string mname = nonlinear ? "NONLINEAR" : "LINEAR";
          auto add = [&](const std::string& el, double f, double sec) {
            results.push_back({s, nu, mname, el, f, sec});
            char line[256];
            std::snprintf(line, sizeof line, "%d,%zu,%zu,%zu,%.2f,%s,%s,%.6g,%.1f", s, lv.nodes,
                          lv.tets, lv.patch_nodes, nu, mname.c_str(), el.c_str(), f, sec);
            csv << line << '\n';
            csv.flush();
            std::fprintf(stderr, "  %s\n", line);
          };
          for (auto el : {fem::Element::kSmoothedTet, fem::Element::kLinearTet}) {
            const auto t0 = std::chrono::steady_clock::now();
            const double f = element_force(m, mat, el, brain.fixed_nodes, patch, depth_m, nonlinear);
            add(fem::element_name(el), f, seconds_since(t0));
          }
          if (ccx) {
            char job[64];
            std::snprintf(job, sizeof job, "s%d_nu%03d_%s", s, static_cast<int>(std::lround(nu * 100)),
                          nonlinear ? "nl" : "lin");
            const auto t0 = std::chrono::steady_clock::now();
            const double f = c3d10_force(q, mat, fixed_q, patch_q, depth_m, nonlinear, increments,
                                         out / "ccx", job);
            add("C3D10", f, seconds_since(t0));
          }
        }
      }
    }
    // The table: each element against C3D10 on the same mesh and on the finest C3D10 mesh.
    auto find = [&](int s, double nu, const std::string& mname, const std::string& el) {
      for (const auto& r : results)
        if (r.split == s && r.nu == nu && r.model == mname && r.element == el) return r.force_n;
      return std::nan("");
    };
    const int finest_c3d10 = std::min(c3d10_splits, splits);
    std::printf("# press %.3g mm on the %.3g mm brain%s, patch within %.3g mm of the top node\n",
                depth_mm, cell_mm,
                region ? (", sub-model within " + std::to_string(region_mm) + " mm, cut clamped").c_str() : "",
                patch_mm);
    std::printf("split,nu,model,element,force_n,over_c3d10_same_mesh,over_c3d10_split_%d\n", finest_c3d10);
    for (const auto& r : results) {
      const double same = find(r.split, r.nu, r.model, "C3D10");
      const double fine = find(finest_c3d10, r.nu, r.model, "C3D10");
      std::printf("%d,%.2f,%s,%s,%.6g,%.4f,%.4f\n", r.split, r.nu, r.model.c_str(),
                  r.element.c_str(), r.force_n, r.force_n / same, r.force_n / fine);
    }
    // The converged answer: each element's three finest meshes extrapolated (Richardson).
    if (splits >= 2) {
      // An element's three finest meshes (C3D10 may stop before ours: --c3d10-splits).
      auto limit_of = [&](double nu, const std::string& mname, const std::string& el,
                          int* finest) {
        int top = splits;
        while (top >= 0 && !std::isfinite(find(top, nu, mname, el))) --top;
        *finest = top;
        if (top < 2) {
          Limit l;
          l.why = "fewer than three meshes";
          return l;
        }
        return richardson(find(top - 2, nu, mname, el), find(top - 1, nu, mname, el),
                          find(top, nu, mname, el));
      };
      std::ofstream lcsv(out / "press_refinement_limits.csv");
      lcsv << "nu,model,element,finest_split,f_finest_minus_2,f_finest_minus_1,f_finest,order,"
              "limit_n,reason\n";
      std::printf("\n# Richardson limits, each from its element's three finest meshes (h halved "
                  "per split)\n");
      std::printf("nu,model,element,finest_split,order,limit_n,limit_over_c3d10_limit,reason\n");
      std::vector<std::string> model_names;
      if (!skip_nonlinear) model_names.push_back("NONLINEAR");
      if (!skip_linear) model_names.push_back("LINEAR");
      const std::vector<std::string> elements = {"C3D10", "smoothed-tet", "linear-tet"};
      std::vector<std::string> disc_rows, disc_notes;
      for (double nu : nus) {
        for (const auto& mname : model_names) {
          int c_top = 0, s_top = 0;
          const Limit c = limit_of(nu, mname, "C3D10", &c_top);
          const Limit st = limit_of(nu, mname, "smoothed-tet", &s_top);
          const neurosim::bench::ConvergedAnswer answer = neurosim::bench::converged_answer(c, st);
          const double converged = answer.force_n;
          const char* converged_by = answer.by;
          for (const auto& el : elements) {
            int top = 0;
            const Limit l = limit_of(nu, mname, el, &top);
            char line[320];
            std::snprintf(line, sizeof line, "%.2f,%s,%s,%d,%.6g,%.6g,%.6g,%.3f,%.6g,%s", nu,
                          mname.c_str(), el.c_str(), top, find(top - 2, nu, mname, el),
                          find(top - 1, nu, mname, el), find(top, nu, mname, el), l.order,
                          l.force_n, l.why.c_str());
            lcsv << line << '\n';
            std::printf("%.2f,%s,%s,%d,%.3f,%.6g,%.4f,%s\n", nu, mname.c_str(), el.c_str(), top,
                        l.order, l.force_n, l.force_n / c.force_n, l.why.c_str());
          }
          // Every mesh's force against the converged answer.
          for (int sp = 0; sp <= splits; ++sp)
            for (const auto& el : elements)
              if (std::isfinite(find(sp, nu, mname, el)))
                std::printf("  split %d %s %s: %.6g N = %.4f of %s\n", sp, mname.c_str(),
                            el.c_str(), find(sp, nu, mname, el),
                            find(sp, nu, mname, el) / converged, converged_by);
          if (mname == "LINEAR" && !disc_table.empty()) {
            if (!std::isfinite(converged))
              throw std::runtime_error("--disc-table: no converged answer at nu " +
                                       std::to_string(nu) + " (" + c.why + "; " + st.why + ")");
            for (const char* el : {"smoothed-tet", "linear-tet"}) {
              char line[256];
              std::snprintf(line, sizeof line, "%s,%s,%.2f,%zu,%zu,%.4g", table_scene.c_str(), el,
                            nu, host_vertices, host_tets,
                            std::abs(find(0, nu, mname, el) / converged - 1.0));
              disc_rows.push_back(line);
            }
            disc_notes.push_back(std::string(converged_by) + " at nu " + std::to_string(nu));
          }
        }
      }
      if (!disc_table.empty()) {
        std::ofstream t(disc_table);
        if (!t) throw std::runtime_error(disc_table + ": cannot write");
        char what[320];
        std::snprintf(what, sizeof what,
                      "# press_refinement_bench: the %.3g mm brain's LINEAR patch press (%.3g mm, "
                      "the surface nodes within %.3g mm of the top node)%s, on the mesh and %d "
                      "nested 1 -> 8 splits.\n",
                      cell_mm, depth_mm, patch_mm,
                      region ? (" on its " + std::to_string(static_cast<int>(region_mm)) +
                                " mm sub-model").c_str()
                             : "",
                      splits);
        t << "# Discretization error (element + mesh) of the unsplit mesh against the converged\n"
             "# answer (Richardson extrapolation of three nested meshes: ";
        for (std::size_t i = 0; i < disc_notes.size(); ++i) t << (i ? ", " : "") << disc_notes[i];
        t << "),\n" << what
          << "scene,element,poisson_ratio,host_vertices,host_tetrahedra,discretization_error\n";
        for (const auto& line : disc_rows) t << line << '\n';
        std::printf("\n# %s: %zu discretization rows\n", disc_table.c_str(), disc_rows.size());
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "press_refinement_bench: error: %s\n", e.what());
    return 1;
  }
}
