// accuracy_bench: what accuracy costs in time. For the cube/cylinder scene and the brain/artery
// scene, each element (--element, repeatable: linear-tet, anp-tet, smoothed-tet) x elasticity
// tier x three mesh resolutions x the coupling method (EXACT; the paper's ITERATIVE at 1, 3, 10
// and 30 iterations, LINEAR only: the simulator refuses ITERATIVE with the other tiers;
// --exact-only leaves it out) over recorded presses of 5, 10 and 20 mm and one lateral stroke
// (10 mm deep, then 10 mm sideways, which rotates the tissue under the tool; --press picks some).
// Each press is a recording file (DIR/recordings/, 200 Hz: approach, smooth press, hold)
// stepped through the offline replay (server/cli/replay.hpp) with synchronous tier updates, so
// every run is deterministic.
//
// Per run: the contact step's time without the tier update (what the 1 kHz loop pays; the update
// runs on its own thread in the server) p50/p99 over the steps that computed no new compliance
// column (a node's first touch costs block solves once per run, counted on stderr), the update rate 1 / mean update time, and at
// the end of the hold the tool force and the host's displacement field compared with the
// reference run of the same element (NONLINEAR, finest mesh, EXACT coupling, same press):
// force_rel_error = |f - f_ref| / |f_ref|; disp_rel_error = RMS over the reference mesh's nodes of
// |u - u_ref| (u interpolated in the run's mesh) / RMS |u_ref|; max_strain = largest principal
// Green-Lagrange strain of the run's fields. These three are errors against our own answer.
//
// Against the converged answer (columns after max_strain): discretization_error = the error of
// the run's element on the run's mesh in a small-strain patch press against the converged
// (continuum) answer of that press: the surface nodes within the patch radius of the press point
// (brain 12 mm, cube 20 mm on the face) held and moved 2 mm along -up, linear elastic (the
// element's LINEAR StaticSolver), |F - F*| / F* with F the patch force. F* comes from
// --converged-table (default share/accuracy/discretization_error.csv, the server's table: the
// brain's rows by press_refinement_bench) when it has the row of the run's host (element, nu,
// vertex and tetrahedron counts); else it is computed here: the host's sub-model within
// region_m of the press point (sub_model.hpp, the cut faces clamped; the brain 60 mm, the cube
// whole), smoothed-tet on it and on its two nested 1 -> 8 splits (tet_split.hpp, the patch and
// the clamp kept), Richardson extrapolation (richardson.hpp) to F*; with ccx, CalculiX C3D10 on
// every level of at most 120000 tetrahedra as the outside check, and its limit is F* when it ran
// on all three (DIR/converged.csv: every level's force, both limits, each against F*).
// discretization_reference says which ("table" or "splits"; "none" and nan: not computed, the
// finest split would exceed 600000 tetrahedra, as the cube's finest mesh whole does).
// model_error = |f - f_nl| / |f_nl| with f_nl the NONLINEAR tier's force on the same mesh, element
// and press (the tier's error; 0 for NONLINEAR, which is the model). total_error =
// discretization_error + model_error (the two parts may also cancel).
// --nu X (repeatable): the hosts' Poisson ratio axis (every run once per value; default the
// scenes' own).
// The cube is also compared with CalculiX (NLGEOM, neo-Hookean, C3D4 on the same mesh, against
// the tiers with linear-tet, the element C3D4 is, whatever --element says): the
// tool's footprint prescribed to the press depth, DIR/calculix.csv.
//
// Writes DIR/accuracy.csv (the table printed), DIR/converged.csv, DIR/calculix.csv,
// DIR/pareto.png (total error against the converged answer, against step time and against the
// tier's update rate, log-log, one series per element, tier and nu, a Pareto front per nu), and
// the two measured tables the server reads for its live estimate (SimStatus
// expected_force_error, discretization_error_estimate, total_error_estimate): the tier's error
// (--table, default DIR/force_error.csv: finest mesh, exact coupling, every element, with the
// element and the host's nu) and the discretization error (--disc-table, default
// DIR/discretization_error.csv: the rows computed here by splits, keyed by the host's element,
// nu, vertex and tetrahedron counts). The committed ones are in share/accuracy/.
//
// A run's force has settled when it moved at most 0.1 % (kSettledSpread) over the last 20 steps
// (kSettleSteps); the tier table takes only rows whose run and NONLINEAR reference settled.
// --max-hold S holds the tool at its last pose up to S seconds longer (one step per sample
// period) until it settles; --trace writes every run's per-step force (DIR/traces/);
// --tier-update-steps N: Newton steps per equilibrium update (0: each update converges).
// --brain-scene PATH: the brain's finest mesh is that scene's (a neurosim-model brain_artery of
// another cell size) instead of the bundled one.
//
// --finest-only: only the finest mesh of each scene (the bundled one for the brain), no C3D10
// and no CalculiX comparison (the discretization part still from the table or the splits): the
// runs the tier table takes (its rows are the finest mesh's), at a fraction of the time.
#include "c3d10_press.hpp"
#include "common/cli.hpp"
#include "common/stats.hpp"
#include "idl/wire/recording_io.hpp"
#include "richardson.hpp"
#include "server/cli/replay.hpp"
#include "server/fem/calculix.hpp"
#include "server/fem/element.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/static_solver.hpp"
#include "server/fem/strain.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "server/service/discretization_table.hpp"
#include "sub_model.hpp"

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace fs = std::filesystem;
namespace ni = neurosim::interaction;
using Vec3 = Eigen::Vector3d;

namespace {

constexpr double kSampleHz = 200.0;     // recording rate (one replay step per sample)
constexpr double kApproachM = 0.003;    // the tip starts this far outside the surface, unit m
constexpr double kPressS = 0.5;         // smooth press (and sideways stroke) duration, unit s
constexpr double kHoldS = 0.3;          // hold at the end, unit s
constexpr double kLateralM = 0.010;     // sideways stroke of the lateral case, unit m
constexpr double kLateralDepthM = 0.010;
constexpr std::size_t kSettleSteps = 20;  // the hold's last steps checked for a settled force
constexpr double kSettledSpread = 1e-3;   // settled: |f - f_end| <= this x |f_end| over those steps

struct Press {
  std::string label;  // press_mm column: "5", "10", "20", "L10" (lateral stroke 10 mm deep)
  double depth_m{0.0};
  bool lateral{false};
};

struct Resolution {
  std::string label;  // e.g. "cube 906 v"
  neurosim::scene::Model model;
  int host_vertices{0};
};

struct SceneCase {
  std::string name;
  Vec3 origin;   // the press point on the host's surface, unit m
  Vec3 up;       // outward normal there (unit)
  Vec3 side;     // direction of the lateral stroke (unit, tangent)
  double tip_radius_m{0.0};
  // The discretization check's patch: surface nodes within this distance of `origin` (and on
  // the plane through it normal to `up` when `flat_face`), unit m.
  double patch_radius_m{0.0};
  bool flat_face{false};
  // The converged answer's sub-model: the tetrahedra with centroid within this distance of
  // `origin` (sub_model.hpp), unit m; 0: the whole host, its fixed nodes as in the scene.
  double region_m{0.0};
  std::vector<Resolution> resolutions;  // coarse to fine
};

struct RunResult {
  std::vector<double> step_us;    // per step, without the tier update, unit us
  std::vector<double> update_us;  // per update, unit us
  Vec3 force_n{Vec3::Zero()};     // end of the hold
  Eigen::VectorXd host_u_m;       // host field at the end of the hold, unit m
  double max_strain{0.0};
  int unconverged_steps{0};
  int column_steps{0};  // steps that computed new compliance columns (left out of step_us)
  // Largest |f - f_end| over the last kSettleSteps steps, relative to |f_end| (0 if f_end = 0):
  // a force still moving at the end of the hold (the step/update fixed point not reached).
  double unsettled{0.0};
  int extra_hold_steps{0};  // steps held beyond the recording (--max-hold) until settled
};

// Per-run options of run_press.
struct RunOptions {
  double max_hold_s{0.0};  // --max-hold: hold up to this much longer until the force settles
  std::string trace;       // --trace: per-step force CSV written here (empty: none)
};

struct Reference {
  const neurosim::mesh::TetMesh* mesh{nullptr};  // finest host mesh
  Eigen::VectorXd host_u_m;
  Vec3 force_n{Vec3::Zero()};
};

double smoothstep(double s) {
  s = std::clamp(s, 0.0, 1.0);
  return s * s * (3.0 - 2.0 * s);
}

// Quaternion (w, x, y, z) turning the tool frame's +z (tip towards handle) onto `axis`.
neurosim::recording::Quaternion orientation_for(const Vec3& axis) {
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitZ(), axis);
  neurosim::recording::Quaternion out;
  out.set_w(q.w());
  out.set_x(q.x());
  out.set_y(q.y());
  out.set_z(q.z());
  return out;
}

// Writes the recording of `press` on `sc` and returns its path.
std::string write_press(const SceneCase& sc, const Press& press, const fs::path& dir) {
  fs::create_directories(dir);
  const fs::path file = dir / (sc.name + "_" + press.label + ".rec");
  neurosim::recording::Header h;
  h.set_scene_name(sc.name);
  h.set_station_id("bench");
  h.set_tool_id(sc.resolutions.front().model.tools.at(0).id);
  h.set_sample_rate_hz(kSampleHz);
  h.set_label("accuracy_bench press " + press.label);
  h.mutable_device()->set_kind("script:press");
  neurosim::wire::RecordingWriter w(file, h);
  const double r = sc.tip_radius_m;
  const double total_s = kPressS + (press.lateral ? kPressS : 0.0) + kHoldS;
  const int n = static_cast<int>(std::lround(total_s * kSampleHz));
  const auto q = orientation_for(sc.up);
  for (int k = 0; k <= n; ++k) {
    const double t = k / kSampleHz;
    const double depth = -kApproachM + (press.depth_m + kApproachM) * smoothstep(t / kPressS);
    const double side =
        press.lateral ? kLateralM * smoothstep((t - kPressS) / kPressS) : 0.0;
    const Vec3 tip = sc.origin + (r - depth) * sc.up + side * sc.side;
    neurosim::recording::Sample s;
    s.set_time_s(t);
    s.mutable_position_m()->set_x(tip.x());
    s.mutable_position_m()->set_y(tip.y());
    s.mutable_position_m()->set_z(tip.z());
    *s.mutable_orientation() = q;
    w.write(s);
  }
  w.close();
  return file.string();
}

// Interpolates a nodal field of `mesh` at points (barycentric in the containing tetrahedron; a
// point outside every tetrahedron by more than 5 % of one in barycentric terms is skipped).
class FieldProbe {
 public:
  explicit FieldProbe(const neurosim::mesh::TetMesh& mesh) : mesh_(mesh) {
    const auto& x = mesh.vertices();
    lo_ = hi_ = x.front();
    for (const auto& p : x) {
      lo_ = lo_.cwiseMin(p);
      hi_ = hi_.cwiseMax(p);
    }
    const double cells = std::cbrt(static_cast<double>(mesh.num_tets()) / 2.0);
    n_ = std::max(1, static_cast<int>(cells));
    h_ = (hi_ - lo_) / n_ + Vec3::Constant(1e-12);
    grid_.resize(static_cast<std::size_t>(n_ * n_ * n_));
    const auto& tets = mesh.tets();
    for (std::size_t e = 0; e < tets.size(); ++e) {
      Vec3 a = x[tets[e][0]], b = a;
      for (int k = 1; k < 4; ++k) {
        a = a.cwiseMin(x[tets[e][k]]);
        b = b.cwiseMax(x[tets[e][k]]);
      }
      const auto ia = cell(a), ib = cell(b);
      for (int i = ia[0]; i <= ib[0]; ++i)
        for (int j = ia[1]; j <= ib[1]; ++j)
          for (int k = ia[2]; k <= ib[2]; ++k) grid_[index(i, j, k)].push_back(static_cast<int>(e));
    }
  }

  // false if `p` is outside the mesh.
  bool sample(const Vec3& p, const Eigen::VectorXd& u, Vec3& out) const {
    const auto c = cell(p);
    const auto& x = mesh_.vertices();
    double best = -1e300;
    int best_tet = -1;
    Eigen::Vector4d best_w;
    for (int e : grid_[index(c[0], c[1], c[2])]) {
      const auto& t = mesh_.tets()[static_cast<std::size_t>(e)];
      Eigen::Matrix3d m;
      m << x[t[1]] - x[t[0]], x[t[2]] - x[t[0]], x[t[3]] - x[t[0]];
      const Vec3 l = m.partialPivLu().solve(p - x[t[0]]);
      const Eigen::Vector4d w(1.0 - l.sum(), l.x(), l.y(), l.z());
      if (w.minCoeff() > best) {
        best = w.minCoeff();
        best_tet = e;
        best_w = w;
      }
    }
    if (best_tet < 0 || best < -0.05) return false;
    const auto& t = mesh_.tets()[static_cast<std::size_t>(best_tet)];
    out.setZero();
    for (int k = 0; k < 4; ++k) out += best_w[k] * u.segment<3>(3 * t[k]);
    return true;
  }

 private:
  std::array<int, 3> cell(const Vec3& p) const {
    std::array<int, 3> c{};
    for (int d = 0; d < 3; ++d)
      c[d] = std::clamp(static_cast<int>(std::floor((p[d] - lo_[d]) / h_[d])), 0, n_ - 1);
    return c;
  }
  std::size_t index(int i, int j, int k) const {
    return static_cast<std::size_t>(i + n_ * (j + n_ * k));
  }
  const neurosim::mesh::TetMesh& mesh_;
  Vec3 lo_, hi_, h_;
  int n_{1};
  std::vector<std::vector<int>> grid_;
};

// RMS |u - u_ref| / RMS |u_ref| over the reference mesh's nodes inside the run's mesh.
double field_error(const Reference& ref, const neurosim::mesh::TetMesh& mesh,
                   const Eigen::VectorXd& u) {
  const FieldProbe probe(mesh);
  double num = 0.0, den = 0.0;
  const auto& x = ref.mesh->vertices();
  for (std::size_t v = 0; v < x.size(); ++v) {
    Vec3 s;
    if (!probe.sample(x[v], u, s)) continue;
    const Vec3 r = ref.host_u_m.segment<3>(3 * static_cast<Eigen::Index>(v));
    num += (s - r).squaredNorm();
    den += r.squaredNorm();
  }
  return den > 0.0 ? std::sqrt(num / den) : 0.0;
}

RunResult run_press(const std::shared_ptr<const ni::Model>& model, const neurosim::scene::Model& sm,
                    const std::string& recording, const RunOptions& opt) {
  std::unique_ptr<ni::Simulation> sim = ni::Simulation::from_model(model);
  std::vector<neurosim::replay::Station> stations{neurosim::replay::load_station(recording, sm)};
  RunResult r;
  std::ofstream trace;
  if (!opt.trace.empty()) {
    trace.open(opt.trace);
    if (!trace) throw std::runtime_error(opt.trace + ": cannot write");
    trace << "step,time_s,fx_n,fy_n,fz_n,force_n,tier_updated,tier_update_us,inverted_elements,barrier_elements\n";
    trace.precision(9);
  }
  std::vector<Vec3> forces;  // every step's
  auto record = [&](std::size_t index, double t, const ni::StepStats& st,
                    const std::vector<ni::ToolContact>& contacts) {
    // A step that touched a node for the first time computed its compliance columns (block
    // solves, milliseconds, once per node and run): not the steady cost of the loop.
    if (st.columns_computed == 0) r.step_us.push_back(st.solve_us - st.tier_update_us);
    else ++r.column_steps;
    if (st.tier_updated) r.update_us.push_back(st.tier_update_us);
    if (!st.converged) ++r.unconverged_steps;
    const auto& c = contacts[0];
    r.force_n = c.in_contact ? c.force_n : Vec3::Zero();
    if (!r.force_n.allFinite()) throw std::runtime_error(recording + ": non-finite force");
    forces.push_back(r.force_n);
    if (trace)
      trace << index << ',' << t << ',' << r.force_n.x() << ',' << r.force_n.y() << ','
            << r.force_n.z() << ',' << r.force_n.norm() << ',' << (st.tier_updated ? 1 : 0) << ','
            << st.tier_update_us << ',' << st.inverted_elements << ','
            << st.barrier_elements << std::endl;  // watchable
  };
  // The largest |f - f_end| / |f_end| over the last kSettleSteps steps.
  auto spread = [&] {
    double m = 0.0;
    const std::size_t from = forces.size() > kSettleSteps ? forces.size() - kSettleSteps : 0;
    for (std::size_t k = from; k < forces.size(); ++k) m = std::max(m, (forces[k] - r.force_n).norm());
    return r.force_n.norm() > 0.0 ? m / r.force_n.norm() : (m > 0.0 ? 1.0 : 0.0);
  };
  std::vector<ni::ToolPose> last_poses;
  double last_t = 0.0;
  std::size_t steps = 0;
  neurosim::replay::run(*sim, stations, [&](const neurosim::replay::StepView& v) {
    record(v.index, v.time_s, *v.stats, *v.contacts);
    last_poses = *v.poses;
    last_t = v.time_s;
    steps = v.count;
  });
  // --max-hold: the tool held at its last pose, one step per sample period, until the force has
  // settled (the step/update fixed point reached) or max_hold_s more has passed.
  const auto extra_max = static_cast<std::size_t>(std::lround(opt.max_hold_s * kSampleHz));
  std::vector<ni::ToolContact> contacts;
  ni::StepStats st;
  for (std::size_t k = 0; k < extra_max && spread() > kSettledSpread; ++k) {
    const double t = last_t + static_cast<double>(k + 1) / kSampleHz;
    sim->step_at(t, last_poses, contacts, st);
    record(steps + k, t, st, contacts);
    ++r.extra_hold_steps;
  }
  r.unsettled = spread();
  for (int m = 0; m < sim->num_meshes(); ++m) {
    if (!sim->mesh_active(m)) continue;
    Eigen::VectorXd u;
    sim->displacements(m, u);
    const auto s = neurosim::fem::max_principal_strain(sim->mesh(m), u);
    r.max_strain = std::max(r.max_strain, s.max_strain);
    if (m == 0) r.host_u_m = std::move(u);
  }
  return r;
}

neurosim::scene::Model cube_at(const std::string& path, double factor) {
  neurosim::scene::Scene s = neurosim::scene::read_scene(path);
  for (int i = 0; i < s.meshes_size(); ++i) {
    auto* g = s.mutable_meshes(i)->mutable_generate();
    g->set_target_vertices(static_cast<int>(std::lround(g->target_vertices() * factor)));
  }
  return neurosim::scene::compile(s, path);
}

neurosim::scene::Model brain_at(double cell_mm, const fs::path& dir) {
  const std::string name = "brain_artery_c" + std::to_string(static_cast<int>(cell_mm * 10));
  const fs::path scene = dir / (name + ".scene");
  if (!fs::exists(scene)) {
    fs::create_directories(dir);
    std::ostringstream cmd;
    cmd << NEUROSIM_BIN_DIR << "/neurosim-model --out-dir '" << dir.string() << "' --name " << name
        << " --cell-size " << cell_mm << " > '" << (dir / (name + ".log")).string() << "' 2>&1";
    if (std::system(cmd.str().c_str()) != 0) {
      throw std::runtime_error("neurosim-model --cell-size " + std::to_string(cell_mm) +
                               " failed (log: " + (dir / (name + ".log")).string() + ")");
    }
  }
  return neurosim::scene::load_model(scene);
}

struct CalculixRow {
  std::string scene, tier, resolution, press;
  double disp_rel_error{0.0}, force_rel_error{0.0}, ccx_s{0.0};
};

// The cube alone, its footprint under the tool prescribed to the press depth along -up, bottom
// fixed: each tier's equilibrium against CalculiX NLGEOM on the same mesh.
std::vector<CalculixRow> calculix_rows(const SceneCase& sc, const std::vector<Press>& presses,
                                       const fs::path& dir) {
  std::vector<CalculixRow> rows;
  for (const auto& res : sc.resolutions) {
    const auto& host = res.model.meshes.at(0);
    const auto& mesh = host.mesh;
    std::vector<int> footprint;
    for (std::size_t v = 0; v < mesh.num_vertices(); ++v) {
      const Vec3 d = mesh.vertices()[v] - sc.origin;
      if (std::abs(d.dot(sc.up)) < 1e-6 && (d - d.dot(sc.up) * sc.up).norm() <= sc.tip_radius_m)
        footprint.push_back(static_cast<int>(v));
    }
    if (footprint.empty()) throw std::runtime_error(res.label + ": no node under the footprint");
    // C3D4 is linear-tet: both sides use it, whatever element the scene names (run_calculix
    // refuses the others).
    neurosim::fem::Material linear = host.material;
    linear.element = neurosim::fem::Element::kLinearTet;
    const neurosim::fem::MaterialMap mats = neurosim::fem::MaterialMap::uniform(linear);
    for (const auto& press : presses) {
      if (press.lateral) continue;
      neurosim::fem::CalculixLoads loads;
      loads.fixed_nodes = host.fixed_nodes;
      neurosim::fem::PrescribedDofs pressed;
      pressed.nodes = footprint;
      pressed.displacement_m = -press.depth_m * sc.up;
      loads.prescribed_sets = {pressed};
      loads.step.neo_hookean_nlgeom = true;
      loads.step.increments = 10;
      const auto t0 = std::chrono::steady_clock::now();
      const std::string job = "cube_" + std::to_string(res.host_vertices) + "_" + press.label;
      const auto ccx = neurosim::fem::run_calculix(dir / job, job, mesh, mats, loads);
      const double ccx_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      double ccx_force = 0.0;
      for (int v : footprint) ccx_force += ccx.reaction_n.segment<3>(3 * v).dot(sc.up);
      for (auto tier : {neurosim::fem::Tier::kLinear, neurosim::fem::Tier::kNonlinear}) {
        neurosim::fem::EquilibriumSolver solver(
            {&mesh, mats, tier, host.fixed_nodes, loads.prescribed_sets, {}});
        const auto sol = solver.solve(Eigen::VectorXd());
        double force = 0.0;
        for (int v : footprint) force += sol.reaction_n.segment<3>(3 * v).dot(sc.up);
        const double du =
            (sol.displacement_m - ccx.displacement_m).norm() / ccx.displacement_m.norm();
        rows.push_back({sc.name, neurosim::fem::tier_name(tier), std::to_string(res.host_vertices),
                        press.label, du, std::abs(force - ccx_force) / std::abs(ccx_force), ccx_s});
      }
    }
  }
  return rows;
}

constexpr double kPatchPressM = 0.002;  // the discretization check's patch displacement, unit m

// The discretization check's patch on `mesh` (see SceneCase::patch_radius_m).
std::vector<int> patch_nodes(const SceneCase& sc, const neurosim::mesh::TetMesh& mesh,
                             const std::string& label) {
  std::vector<int> patch;
  for (int v : mesh.surface_vertices()) {
    const Vec3 d = mesh.vertices()[static_cast<std::size_t>(v)] - sc.origin;
    if (sc.flat_face && std::abs(d.dot(sc.up)) > 1e-6) continue;
    if (d.norm() <= sc.patch_radius_m) patch.push_back(v);
  }
  std::sort(patch.begin(), patch.end());
  if (patch.size() < 3)
    throw std::runtime_error(sc.name + " " + label + ": fewer than 3 surface nodes in the patch");
  return patch;
}

// The patch force (the tissue pushing back along `up`) of `element` on the host mesh, LINEAR
// StaticSolver, unit N.
double element_patch_force(const SceneCase& sc, const neurosim::scene::LoadedMesh& host,
                           neurosim::fem::Element element, const std::vector<int>& patch) {
  neurosim::fem::MaterialMap mats = host.materials;
  for (auto& m : mats.materials) m.element = element;
  const neurosim::fem::StaticSolver solver(host.mesh, mats, host.fixed_nodes);
  Eigen::VectorXd values(3 * static_cast<Eigen::Index>(patch.size()));
  for (std::size_t i = 0; i < patch.size(); ++i)
    values.segment<3>(3 * static_cast<Eigen::Index>(i)) = -kPatchPressM * sc.up;
  const auto s = solver.solve_prescribed(patch, values);
  double f = 0.0;
  for (int v : patch) f -= s.reaction_n.segment<3>(3 * v).dot(sc.up);
  return f;
}

// Every material of `m` at Poisson ratio nu (the patch press and the --nu axis).
void set_poisson_ratio(neurosim::scene::LoadedMesh& m, double nu) {
  m.material.poisson_ratio = nu;
  for (auto& mat : m.materials.materials) mat.poisson_ratio = nu;
  for (auto& t : m.tissues) t.material.poisson_ratio = nu;
}

// One mesh's discretization error per element against the converged answer of the patch press.
struct Discretization {
  std::string reference;  // "table" (--converged-table's row), "splits" or "none" (too large)
  std::map<std::string, double> error;  // element name -> |F - F*| / F*
};

constexpr int kConvergedSplits = 2;  // three nested meshes: the fewest Richardson takes
// C3D10 on a level of at most this many tetrahedra (ccx on one thread: about 5 min at 100k).
constexpr std::size_t kC3d10MaxTets = 120000;
// The finest split solved, at most (smoothed-tet's factor: 13 GB at 540k tetrahedra; the cube's
// finest mesh split twice, 1.16M, ran out of memory): beyond, no converged answer computed.
constexpr std::size_t kSplitMaxTets = 600000;

// The converged answer computed (see the file's header): the sub-model of `host` within
// sc.region_m of the press point (the whole host when 0), smoothed-tet on it and on its
// kConvergedSplits nested splits extrapolated (Richardson), each element of `elements` on the
// unsplit sub-model against F*; with ccx, C3D10 on every level up to kC3d10MaxTets. F* is
// C3D10's limit when C3D10 ran on all three levels with an asymptotic range, else smoothed-tet's
// (press_refinement_bench's rule); both limits are printed. One converged.csv row per level and
// element (error_vs_limit = F / F* - 1, signed) and per limit (split "limit"). Throws when
// neither has an asymptotic range; reference "none" and no errors when the finest split would
// exceed kSplitMaxTets.
Discretization converged_by_splits(const SceneCase& sc, neurosim::scene::LoadedMesh host,
                                   const std::vector<std::string>& elements, bool ccx,
                                   const fs::path& dir, const std::string& label,
                                   std::ostream& conv_csv) {
  if (host.tissue_with_other_material() != nullptr)
    throw std::runtime_error(sc.name + ": host tissue '" + host.tissue_with_other_material()->name +
                             "' has its own material: the patch press takes one material");
  const bool region = sc.region_m > 0.0;
  std::vector<neurosim::mesh::Tri> cut_faces;
  if (region)
    cut_faces = neurosim::bench::cut_region(host, sc.origin, sc.region_m, /*keep_pinned=*/true);
  if (host.mesh.num_tets() << (3 * kConvergedSplits) > kSplitMaxTets) {
    std::fprintf(stderr, "  converged: %s %s: NOT computed: its finest split would have %zu "
                         "tetrahedra, over the %zu this bench solves (discretization_error nan; "
                         "--converged-table may have its row)\n",
                 sc.name.c_str(), label.c_str(), host.mesh.num_tets() << (3 * kConvergedSplits),
                 kSplitMaxTets);
    return Discretization{"none", {}};
  }
  std::vector<int> patch = patch_nodes(sc, host.mesh, label);
  for (int v : host.fixed_nodes)
    if (std::binary_search(patch.begin(), patch.end(), v))
      throw std::runtime_error(sc.name + " " + label + ": the patch holds a clamped node of the "
                               "sub-model or the scene (a larger region_m)");
  struct Force {
    int split;
    std::size_t tets, patch_nodes;
    std::string element;
    double force_n, solve_s;
  };
  std::vector<Force> forces;
  auto seconds_since = [](std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  std::vector<std::string> level0 = elements;
  if (std::find(level0.begin(), level0.end(), "smoothed-tet") == level0.end())
    level0.push_back("smoothed-tet");
  for (int sp = 0; sp <= kConvergedSplits; ++sp) {
    if (sp > 0) {
      patch = neurosim::bench::split_node_set(neurosim::bench::split_tets(host.mesh), patch);
      if (region) neurosim::bench::split_region(host, cut_faces);
      else neurosim::bench::split_loaded_mesh(host);
    }
    for (const auto& el : sp == 0 ? level0 : std::vector<std::string>{"smoothed-tet"}) {
      const auto t0 = std::chrono::steady_clock::now();
      const double f = element_patch_force(sc, host, *neurosim::fem::parse_element(el), patch);
      forces.push_back({sp, host.mesh.num_tets(), patch.size(), el, f, seconds_since(t0)});
    }
    if (ccx && host.mesh.num_tets() <= kC3d10MaxTets) {
      const auto q = neurosim::bench::quadratic_tets(host.mesh);
      const auto fixed_q = region ? neurosim::bench::clamp_of_faces(q, host.fixed_nodes, cut_faces)
                                  : q.with_mid(host.fixed_nodes);
      const auto patch_q = q.with_mid(patch);
      const auto t0 = std::chrono::steady_clock::now();
      const auto r = neurosim::bench::run_c3d10_press(
          dir, sc.name + "_" + label + "_s" + std::to_string(sp), "accuracy_bench patch press", q,
          host.material, fixed_q, patch_q, -kPatchPressM * sc.up);
      double f = 0.0;
      for (int v : patch_q) f -= r.reaction_n.segment<3>(3 * v).dot(sc.up);
      forces.push_back({sp, host.mesh.num_tets(), patch.size(), "C3D10", f, seconds_since(t0)});
    }
  }
  auto limit_of = [&](const std::string& el) {
    std::vector<double> f;
    for (const auto& x : forces)
      if (x.element == el) f.push_back(x.force_n);
    return f.size() == 3 ? neurosim::bench::richardson(f[0], f[1], f[2])
                         : neurosim::bench::Limit{NAN, NAN, "C3D10 on fewer than three levels"};
  };
  const neurosim::bench::Limit st = limit_of("smoothed-tet"), c3 = limit_of("C3D10");
  const neurosim::bench::ConvergedAnswer answer = neurosim::bench::converged_answer(c3, st);
  const double f_star = answer.force_n;
  if (!std::isfinite(f_star))
    throw std::runtime_error(sc.name + " " + label + ": no converged answer from the splits ("
                             "smoothed-tet: " + st.why + "; C3D10: " + c3.why + ")");
  std::fprintf(stderr,
               "  converged: %s %s nu %.3g: F* = %.6g N, %s (C3D10's limit %.6g N order %.2f%s%s; "
               "smoothed-tet's %.6g N order %.2f%s%s)\n",
               sc.name.c_str(), label.c_str(), host.material.poisson_ratio, f_star,
               answer.by, c3.force_n, c3.order,
               c3.why.empty() ? "" : ": ", c3.why.c_str(), st.force_n, st.order,
               st.why.empty() ? "" : ": ", st.why.c_str());
  for (const auto& [el, l] : {std::make_pair(std::string("C3D10"), c3),
                              std::make_pair(std::string("smoothed-tet"), st)})
    if (std::isfinite(l.force_n))
      forces.push_back({-1, 0, 0, el + " limit", l.force_n, 0.0});
  Discretization d;
  d.reference = "splits";
  for (const auto& f : forces) {
    char line[320];
    std::snprintf(line, sizeof line, "%s,%s,%.6g,splits,%s,%zu,%zu,%s,%.6g,%.4g,%.1f",
                  sc.name.c_str(), label.c_str(), host.material.poisson_ratio,
                  f.split < 0 ? "limit" : std::to_string(f.split).c_str(), f.tets, f.patch_nodes,
                  f.element.c_str(), f.force_n, f.force_n / f_star - 1.0, f.solve_s);
    conv_csv << line << '\n';
    std::fprintf(stderr, "  converged: %s\n", line);
    if (f.split == 0 && f.element != "C3D10" &&
        std::find(elements.begin(), elements.end(), f.element) != elements.end())
      d.error[f.element] = std::abs(f.force_n / f_star - 1.0);
  }
  conv_csv.flush();
  return d;
}

bool have_program(const char* name) {
  return std::system((std::string("command -v ") + name + " >/dev/null 2>&1").c_str()) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  bool csv = false;
  bool exact_only = false;
  bool finest_only = false;
  bool trace = false;
  double max_hold_s = 0.0;
  int tier_update_steps = -1;
  std::string out_dir, table_path, disc_table_path, brain_scene;
  std::string converged_table = std::string(NEUROSIM_SOURCE_DIR) +
                                "/share/accuracy/discretization_error.csv";
  std::vector<std::string> elements, press_filter;
  std::vector<double> nus;
  std::vector<std::string> scenes{"cube_cylinder", "brain_artery"};
  neurosim::cli::Parser cli("accuracy_bench",
                            "What accuracy costs in time: tiers x resolutions x coupling over "
                            "recorded presses, errors against the finest nonlinear run and, split "
                            "into discretization and model, against the converged answer.");
  cli.add_flag("--csv", csv, "print only the CSV table");
  cli.add_option("--out", out_dir, "output folder DIR (accuracy.csv, calculix.csv, pareto.png)")
      ->required();
  cli.add_option("--scene", scenes, "scenes to run (cube_cylinder, brain_artery)")
      ->capture_default_str();
  cli.add_option("--element", elements,
                 "smoothed-tet | anp-tet | linear-tet, repeatable: the element axis (every "
                 "mesh's element per run; default: the scenes' material.element)")
      ->check(neurosim::cli::one_of({"smoothed-tet", "anp-tet", "linear-tet"}));
  cli.add_option("--nu", nus,
                 "the hosts' Poisson ratio, repeatable: the nu axis (default: the scenes' own)")
      ->check(neurosim::cli::in_range(0.0, 0.4999));
  cli.add_option("--converged-table", converged_table,
                 "discretization errors against the converged answer taken by host (element, nu, "
                 "mesh) where it has the row; the others computed by nested splits; none: "
                 "compute every one")
      ->capture_default_str();
  cli.add_option("--press", press_filter, "presses to run: 5, 10, 20, L10 (default all)")
      ->check(neurosim::cli::one_of({"5", "10", "20", "L10"}));
  cli.add_flag("--exact-only", exact_only, "leave out the ITERATIVE coupling runs");
  cli.add_flag("--finest-only", finest_only,
               "only the finest mesh, no C3D10 and no CalculiX: the tier table's runs");
  cli.add_option("--max-hold", max_hold_s,
                 "hold the tool at its last pose up to S seconds longer until the force has "
                 "settled (moved at most 0.1 % over 20 steps; default 0: the recording's 0.3 s)")
      ->check(neurosim::cli::range(0.0, 600.0));
  cli.add_option("--tier-update-steps", tier_update_steps,
                 "Newton steps per NONLINEAR equilibrium update (SimulationOptions::"
                 "tier_update_steps; 0: each update converges; default: the server's)")
      ->check(neurosim::cli::range(0, 1000));
  cli.add_flag("--trace", trace, "per-step tool force of every run in DIR/traces/*.csv");
  cli.add_option("--brain-scene", brain_scene,
                 "the brain's finest mesh: this scene (a neurosim-model brain_artery of another "
                 "cell size; default scenes/brain_artery.scene)");
  cli.add_option("--table", table_path,
                 "measured force-error table for the server (default DIR/force_error.csv)");
  cli.add_option("--disc-table", disc_table_path,
                 "measured discretization-error table for the server (default "
                 "DIR/discretization_error.csv)");
  if (auto rc = cli.parse(argc, argv)) return *rc;
  try {
    const fs::path out(out_dir);
    fs::create_directories(out);
    if (table_path.empty()) table_path = (out / "force_error.csv").string();
    if (disc_table_path.empty()) disc_table_path = (out / "discretization_error.csv").string();
    const std::string src = NEUROSIM_SOURCE_DIR;
    std::vector<Press> presses;
    for (const Press& p : {Press{"5", 0.005, false}, Press{"10", 0.010, false},
                           Press{"20", 0.020, false}, Press{"L10", kLateralDepthM, true}})
      if (press_filter.empty() ||
          std::find(press_filter.begin(), press_filter.end(), p.label) != press_filter.end())
        presses.push_back(p);

    std::vector<SceneCase> cases;
    for (const auto& name : scenes) {
      SceneCase sc;
      sc.name = name;
      if (name == "cube_cylinder") {
        // The right face's centre (the paper's Figure 10 push), a 10 mm probe.
        const std::string path = src + "/scenes/cube_cylinder.scene";
        sc.origin = Vec3(0.1, 0.05, 0.05);
        sc.up = Vec3::UnitX();
        sc.side = Vec3::UnitY();
        sc.tip_radius_m = 0.010;
        sc.patch_radius_m = 0.020;  // 3 or more face nodes on the coarse mesh
        sc.flat_face = true;
        sc.region_m = 0.0;  // the whole cube: a 35 mm cut clamps a 20 mm patch too near
        for (double f : {0.5, 1.0, 2.0})
          if (!finest_only || f == 2.0) sc.resolutions.push_back({"", cube_at(path, f), 0});
      } else if (name == "brain_artery") {
        // The demo's press point on the right lateral surface, a 6 mm probe.
        sc.origin = Vec3(0.1605, 0.1125, 0.0787);
        sc.up = Vec3(0.963, 0.176, 0.202).normalized();
        sc.side = sc.up.cross(Vec3::UnitZ()).normalized();
        sc.tip_radius_m = 0.006;
        sc.patch_radius_m = 0.012;
        sc.region_m = 0.060;  // press_refinement_bench's sub-model size
        const fs::path models = out / "models";
        if (!finest_only) {
          sc.resolutions.push_back({"", brain_at(11.0, models), 0});
          sc.resolutions.push_back({"", brain_at(9.0, models), 0});
          sc.resolutions.push_back({"", brain_at(7.0, models), 0});
        }
        sc.resolutions.push_back(
            {"", neurosim::scene::load_model(brain_scene.empty() ? src + "/scenes/brain_artery.scene"
                                                                 : brain_scene),
             0});
      } else {
        throw std::runtime_error("--scene " + name + ": unknown (cube_cylinder, brain_artery)");
      }
      for (auto& r : sc.resolutions) {
        r.host_vertices = static_cast<int>(r.model.meshes.at(0).mesh.num_vertices());
        r.label = std::to_string(r.host_vertices);
        r.model.tools.at(0).tip_radius_m = sc.tip_radius_m;
      }
      cases.push_back(std::move(sc));
    }

    const char* header =
        "scene,tier,resolution,coupling,iterations,press_mm,step_p50_us,step_p99_us,update_hz,"
        "disp_rel_error,force_rel_error,max_strain,element,discretization_error,model_error,"
        "total_error,poisson_ratio,discretization_reference";
    std::ofstream table_csv(out / "accuracy.csv");
    table_csv << header << '\n';
    std::printf("%s\n", header);
    if (!csv) std::fprintf(stderr, "# accuracy_bench: runs on stderr, table on stdout\n");

    struct Row {
      std::string scene, tier, coupling;
      int resolution, iterations;
      std::string press;
      double p50, p99, update_hz, disp_err, force_err, strain;
      std::string element;
      double disc_err, model_err, total_err;
      double nu;  // the host's Poisson ratio
      std::string disc_ref;  // "table", "splits" (Discretization::reference) or "none"
      // The run's force and (other tiers) NONLINEAR's on the same mesh settled by the end of the
      // hold (kSettledSpread); the tier table takes only such rows.
      bool settled;
    };
    const bool ccx = !finest_only && have_program("ccx");
    if (finest_only)
      std::fprintf(stderr, "accuracy_bench: --finest-only: no C3D10 and no CalculiX\n");
    else if (!ccx)
      std::fprintf(stderr, "accuracy_bench: note: ccx (calculix-ccx) not installed: no C3D10 "
                           "check of the converged answer\n");
    std::optional<neurosim::service::DiscretizationTable> conv_table;
    if (converged_table != "none") {
      conv_table = neurosim::service::DiscretizationTable::read(converged_table);
      std::fprintf(stderr, "accuracy_bench: discretization errors from %s where it has the host's "
                           "row, the others by nested splits\n", converged_table.c_str());
    }
    std::ofstream conv_csv(out / "converged.csv");
    conv_csv << "scene,resolution,poisson_ratio,reference,split,tets,patch_nodes,element,"
                "patch_force_n,error_vs_limit,solve_s\n";
    std::vector<Row> rows;
    std::vector<std::string> disc_rows;  // the server's discretization table (splits rows)
    using neurosim::fem::Tier;
    for (auto& sc : cases) {
      std::vector<std::string> recordings;
      for (const auto& p : presses) recordings.push_back(write_press(sc, p, out / "recordings"));
      std::vector<std::string> scene_elements = elements;
      if (scene_elements.empty())
        scene_elements.push_back(
            neurosim::fem::element_name(sc.resolutions.back().model.meshes.at(0).material.element));
      std::vector<double> scene_nus = nus;
      if (scene_nus.empty())
        scene_nus.push_back(sc.resolutions.back().model.meshes.at(0).material.poisson_ratio);
      const std::vector<Resolution> as_given = sc.resolutions;
      for (const double nu : scene_nus) {
      for (std::size_t ri = 0; ri < sc.resolutions.size(); ++ri) {
        sc.resolutions[ri].model = as_given[ri].model;
        set_poisson_ratio(sc.resolutions[ri].model.meshes.at(0), nu);
      }
      // The discretization part: each element on each mesh against the converged answer.
      std::vector<Discretization> disc(sc.resolutions.size());  // per resolution
      for (std::size_t ri = 0; ri < sc.resolutions.size(); ++ri) {
        const auto& res = sc.resolutions[ri];
        const auto& host = res.model.meshes.at(0);
        // The table's rows when it has every element's (their errors are |F / F* - 1|).
        Discretization d;
        d.reference = "table";
        std::vector<std::string> table_lines;
        for (const auto& el_name : scene_elements) {
          const auto row = conv_table ? conv_table->find(*neurosim::fem::parse_element(el_name), nu,
                                                         host.mesh.num_vertices(),
                                                         host.mesh.num_tets())
                                      : std::nullopt;
          if (!row) {
            d.error.clear();
            break;
          }
          d.error[el_name] = row->discretization_error;
          char line[256];
          std::snprintf(line, sizeof line, "%s,%s,%.6g,table,,%zu,,%s,,%.4g,", sc.name.c_str(),
                        res.label.c_str(), nu, host.mesh.num_tets(), el_name.c_str(),
                        row->discretization_error);
          table_lines.emplace_back(line);
        }
        if (!d.error.empty())
          for (const auto& line : table_lines) conv_csv << line << '\n';
        if (d.error.empty()) {
          d = converged_by_splits(sc, host, scene_elements, ccx, out / "c3d10", res.label,
                                  conv_csv);
          for (const auto& [el_name, e] : d.error) {
            char drow[256];
            std::snprintf(drow, sizeof drow, "%s,%s,%.6g,%zu,%zu,%.4g", sc.name.c_str(),
                          el_name.c_str(), nu, host.mesh.num_vertices(), host.mesh.num_tets(), e);
            disc_rows.emplace_back(drow);
          }
        } else {
          std::fprintf(stderr, "  converged: %s %s nu %.3g: from %s\n", sc.name.c_str(),
                       res.label.c_str(), nu, converged_table.c_str());
        }
        disc[ri] = std::move(d);
      }
      for (const auto& el_name : scene_elements) {
      const auto element = *neurosim::fem::parse_element(el_name);
      // References first: NONLINEAR on the finest mesh, EXACT coupling.
      std::vector<Reference> refs(presses.size());
      std::vector<RunResult> ref_runs(presses.size());
      // Runs: finest first so the references exist when the others are compared.
      for (int ri = static_cast<int>(sc.resolutions.size()) - 1; ri >= 0; --ri) {
        const auto& res = sc.resolutions[static_cast<std::size_t>(ri)];
        const bool finest = ri + 1 == static_cast<int>(sc.resolutions.size());
        struct Config {
          Tier tier;
          int iterations;  // 0: EXACT
        };
        // COROTATIONAL is withdrawn (fem/served_tiers.hpp).
        std::vector<Config> configs{{Tier::kNonlinear, 0}, {Tier::kLinear, 0}};
        if (!res.model.couplings.empty() && !exact_only)
          for (int it : {1, 3, 10, 30}) configs.push_back({Tier::kLinear, it});
        const Discretization& dz = disc[static_cast<std::size_t>(ri)];
        const auto dz_el = dz.error.find(el_name);
        const double disc_err =
            dz_el != dz.error.end() ? dz_el->second : std::numeric_limits<double>::quiet_NaN();
        std::vector<Vec3> nl_force(presses.size(), Vec3::Zero());  // NONLINEAR, this mesh
        std::vector<char> nl_settled(presses.size(), 0);
        for (const auto& cfg : configs) {
          neurosim::scene::Model sm = res.model;
          sm.set_element(element);
          sm.effects.tier = cfg.tier;
          ni::SimulationOptions opt;
          opt.tier_worker_thread = false;
          if (tier_update_steps >= 0) opt.tier_update_steps = tier_update_steps;
          if (cfg.iterations > 0) {
            for (auto& c : sm.couplings) c.method = neurosim::scene::CouplingMethod::kIterative;
            // Exactly `iterations` iterations (the smallest tolerance the option takes).
            opt.iterative_tolerance = std::numeric_limits<double>::min();
            opt.iterative_max_iterations = cfg.iterations;
          }
          const auto t0 = std::chrono::steady_clock::now();
          const std::shared_ptr<const ni::Model> model = ni::build_model(sm, opt);
          const double build_s =
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          for (std::size_t pi = 0; pi < presses.size(); ++pi) {
            const auto t1 = std::chrono::steady_clock::now();
            RunOptions ro;
            ro.max_hold_s = max_hold_s;
            if (trace) {
              fs::create_directories(out / "traces");
              ro.trace = (out / "traces" /
                          (sc.name + "_" + el_name + "_" + neurosim::fem::tier_name(cfg.tier) + "_" +
                           std::to_string(res.host_vertices) + "_" +
                           (nus.empty() ? std::string()
                                        : "nu" + std::to_string(nu).substr(0, 5) + "_") +
                           (cfg.iterations ? "it" + std::to_string(cfg.iterations) : "exact") +
                           "_" + presses[pi].label + ".csv"))
                             .string();
            }
            RunResult r = run_press(model, sm, recordings[pi], ro);
            const bool is_ref = finest && cfg.tier == Tier::kNonlinear && cfg.iterations == 0;
            if (is_ref) {
              refs[pi] = {&res.model.meshes.at(0).mesh, r.host_u_m, r.force_n};
              ref_runs[pi] = r;
            }
            const Reference& ref = refs[pi];
            if (ref.mesh == nullptr) throw std::logic_error("reference run missing");
            const double fe = ref.force_n.norm() > 0.0
                                  ? (r.force_n - ref.force_n).norm() / ref.force_n.norm()
                                  : 0.0;
            const double de = field_error(ref, res.model.meshes.at(0).mesh, r.host_u_m);
            if (cfg.tier == Tier::kNonlinear && cfg.iterations == 0) {
              nl_force[pi] = r.force_n;
              nl_settled[pi] = r.unsettled <= kSettledSpread;
            }
            const double me = nl_force[pi].norm() > 0.0
                                  ? (r.force_n - nl_force[pi]).norm() / nl_force[pi].norm()
                                  : std::numeric_limits<double>::quiet_NaN();
            double update_hz = 0.0;
            if (!r.update_us.empty()) {
              double sum = 0.0;
              for (double u : r.update_us) sum += u;
              update_hz = 1e6 * static_cast<double>(r.update_us.size()) / sum;
            }
            Row row{sc.name, neurosim::fem::tier_name(cfg.tier),
                    cfg.iterations ? "iterative" : "exact", res.host_vertices, cfg.iterations,
                    presses[pi].label, neurosim::common::percentile(r.step_us, 0.5),
                    neurosim::common::percentile(r.step_us, 0.99),
                    update_hz, de, fe, r.max_strain, el_name, disc_err, me, disc_err + me,
                    res.model.meshes.at(0).material.poisson_ratio, dz.reference,
                    r.unsettled <= kSettledSpread && nl_settled[pi] != 0};
            char line[512];
            std::snprintf(line, sizeof line,
                          "%s,%s,%d,%s,%d,%s,%.1f,%.1f,%.1f,%.4g,%.4g,%.4g,%s,%.4g,%.4g,%.4g,%.6g,%s",
                          row.scene.c_str(), row.tier.c_str(), row.resolution, row.coupling.c_str(),
                          row.iterations, row.press.c_str(), row.p50, row.p99, row.update_hz,
                          row.disp_err, row.force_err, row.strain, row.element.c_str(),
                          row.disc_err, row.model_err, row.total_err, row.nu,
                          row.disc_ref.c_str());
            std::printf("%s\n", line);
            std::fflush(stdout);
            table_csv << line << '\n';
            {  // per run, on stderr (also with --csv)
              std::fprintf(stderr, "  %s %s %s res %d %s %d press %s: |f| %.4g N, build %.1f s, run %.1f s, %d column steps%s%s%s\n",
                           row.scene.c_str(), el_name.c_str(), row.tier.c_str(), row.resolution, row.coupling.c_str(),
                           row.iterations, row.press.c_str(), r.force_n.norm(), build_s,
                           std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count(),
                           r.column_steps, r.unconverged_steps ? " (some contact LCPs did not converge)" : "",
                           (r.extra_hold_steps > 0 ? ", held " + std::to_string(r.extra_hold_steps) +
                                                         " steps beyond the recording"
                                                   : std::string())
                               .c_str(),
                           r.unsettled > kSettledSpread
                               ? (", force NOT settled: moved " + std::to_string(100.0 * r.unsettled) +
                                  " % over the hold's last steps").c_str()
                               : "");
            }
            rows.push_back(row);
          }
        }
      }
      }  // element
      }  // nu
      sc.resolutions = as_given;
    }
    table_csv.close();
    conv_csv.close();

    // The measured table the server reads: per scene and tier, the force error against the
    // strain it was measured at (finest mesh, EXACT coupling, every press).
    {
      std::ofstream t(table_path);
      if (!t) throw std::runtime_error(table_path + ": cannot write");
      t << "# Expected tool-force error of each elasticity tier against the largest strain in the\n"
           "# field, measured by accuracy_bench (finest mesh, exact coupling, errors against the\n"
           "# nonlinear tier on the same mesh and element). Read by neurosim-server for\n"
           "# SimStatus.expected_force_error (rows of the running element and host nu).\n"
           "scene,tier,max_strain,force_rel_error,element,poisson_ratio\n";
      for (const auto& r : rows) {
        const int finest = [&] {
          int m = 0;
          for (const auto& q : rows)
            if (q.scene == r.scene) m = std::max(m, q.resolution);
          return m;
        }();
        if (r.resolution != finest || r.coupling != "exact") continue;
        if (!r.settled) {
          std::fprintf(stderr, "accuracy_bench: %s %s %s press %s: not in %s (its force or "
                               "NONLINEAR's did not settle; --max-hold)\n", r.scene.c_str(),
                       r.element.c_str(), r.tier.c_str(), r.press.c_str(), table_path.c_str());
          continue;
        }
        char line[256];
        std::snprintf(line, sizeof line, "%s,%s,%.4g,%.4g,%s,%.6g\n", r.scene.c_str(),
                      r.tier.c_str(), r.strain, r.force_err, r.element.c_str(), r.nu);
        t << line;
      }
    }
    // The discretization table the server reads: the rows computed here (the --converged-table
    // rows taken are that table's already).
    {
      std::ofstream t(disc_table_path);
      if (!t) throw std::runtime_error(disc_table_path + ": cannot write");
      t << "# Discretization error (element + mesh) of each scene's host mesh against the\n"
           "# converged answer: accuracy_bench's small-strain patch press on the host's sub-model\n"
           "# around the press point (the whole cube), against the Richardson limit of it and two\n"
           "# nested 1 -> 8 splits (C3D10's where ccx ran on all three, else smoothed-tet's;\n"
           "# docs/accuracy.md). Read by neurosim-server for\n"
           "# SimStatus.discretization_error_estimate: the row of the host's element, nu, vertex and\n"
           "# tetrahedron counts, none: unknown.\n"
           "scene,element,poisson_ratio,host_vertices,host_tetrahedra,discretization_error\n";
      for (const auto& line : disc_rows) t << line << '\n';
    }

    // CalculiX on the cube.
    if (ccx) {
      std::ofstream c(out / "calculix.csv");
      c << "scene,tier,resolution,press_mm,disp_rel_error_ccx,force_rel_error_ccx,ccx_s\n";
      for (const auto& sc : cases) {
        if (sc.name != "cube_cylinder") continue;
        for (const auto& r : calculix_rows(sc, presses, out / "calculix")) {
          char line[256];
          std::snprintf(line, sizeof line, "%s,%s,%s,%s,%.4g,%.4g,%.1f", r.scene.c_str(),
                        r.tier.c_str(), r.resolution.c_str(), r.press.c_str(), r.disp_rel_error,
                        r.force_rel_error, r.ccx_s);
          c << line << '\n';
          if (!csv) std::printf("# calculix: %s\n", line);
        }
      }
    } else if (!finest_only) {
      std::fprintf(stderr, "accuracy_bench: note: ccx (calculix-ccx) not installed: no CalculiX "
                           "comparison\n");
    }

    // pareto.png: total error (discretization against the converged answer + the tier's), left
    // against the contact step's p99, right against the tier's update rate (tiers that update:
    // LINEAR has no update), one series per element, tier and nu, the front per nu (a tissue
    // has one nu: fronts across two would mix two problems).
    {
      const fs::path data = out / "pareto.dat";
      std::ofstream d(data);
      auto plotted = [](const Row& r) { return std::isfinite(r.total_err) && r.total_err > 0.0; };
      struct Block {
        std::string element, tier;
        double nu;
        bool operator==(const Block& o) const {
          return element == o.element && tier == o.tier && nu == o.nu;
        }
      };
      std::vector<Block> blocks;
      std::vector<double> block_nus;
      for (const auto& r : rows) {
        if (std::find(blocks.begin(), blocks.end(), Block{r.element, r.tier, r.nu}) == blocks.end())
          blocks.push_back({r.element, r.tier, r.nu});
        if (std::find(block_nus.begin(), block_nus.end(), r.nu) == block_nus.end())
          block_nus.push_back(r.nu);
      }
      auto nu_text = [](double nu) {
        char t[32];
        std::snprintf(t, sizeof t, "nu %.3g", nu);
        return std::string(t);
      };
      for (const auto& b : blocks) {
        d << "# " << b.element << " " << b.tier << " " << nu_text(b.nu)
          << ": step_p99_us total_error update_hz\n";
        int n = 0;
        for (const auto& r : rows)
          if (Block{r.element, r.tier, r.nu} == b && plotted(r)) {
            d << r.p99 << ' ' << r.total_err << ' ' << (r.update_hz > 0.0 ? r.update_hz : NAN)
              << '\n';
            ++n;
          }
        if (n == 0) d << "NaN NaN NaN\n";  // keeps the block (gnuplot index)
        d << "\n\n";
      }
      // The fronts per nu: the least error at no more step time; at no lower update rate.
      auto front = [&](bool by_rate, double nu) {
        std::vector<std::pair<double, double>> pts;
        for (const auto& r : rows)
          if (r.nu == nu && plotted(r) && (!by_rate || r.update_hz > 0.0))
            pts.emplace_back(by_rate ? -r.update_hz : r.p99, r.total_err);
        std::sort(pts.begin(), pts.end());
        d << "# pareto front " << nu_text(nu) << (by_rate ? " (update rate)" : " (step time)")
          << "\n";
        double best = 1e300;
        for (const auto& p : pts)
          if (p.second < best) {
            best = p.second;
            d << (by_rate ? -p.first : p.first) << ' ' << p.second << '\n';
          }
        if (pts.empty()) d << "NaN NaN\n";
        d << "\n\n";
      };
      for (double nu : block_nus) front(false, nu);
      for (double nu : block_nus) front(true, nu);
      d.close();
      if (have_program("gnuplot")) {
        const fs::path script = out / "pareto.gp";
        std::ofstream g(script);
        const char* colours[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"};
        // One colour per element and tier, filled points for the first nu, open for others.
        std::vector<std::pair<std::string, std::string>> pairs;  // (element, tier), in order
        for (const auto& b : blocks)
          if (std::find(pairs.begin(), pairs.end(), std::make_pair(b.element, b.tier)) ==
              pairs.end())
            pairs.emplace_back(b.element, b.tier);
        auto series = [&](const char* columns) {
          for (std::size_t k = 0; k < blocks.size(); ++k) {
            const std::size_t c = static_cast<std::size_t>(
                std::find(pairs.begin(), pairs.end(),
                          std::make_pair(blocks[k].element, blocks[k].tier)) -
                pairs.begin());
            const std::size_t nu_index = static_cast<std::size_t>(
                std::find(block_nus.begin(), block_nus.end(), blocks[k].nu) - block_nus.begin());
            g << "'" << data.string() << "' index " << k << " using " << columns
              << " with points pt " << (nu_index == 0 ? 5 + 2 * (c % 4) : 4 + 2 * (c % 4))
              << " ps 1.3 lc rgb '" << colours[c % 6] << "' title '" << blocks[k].element << " "
              << blocks[k].tier << " " << nu_text(blocks[k].nu) << "', ";
          }
        };
        auto fronts = [&](std::size_t first, const char* style) {
          for (std::size_t i = 0; i < block_nus.size(); ++i)
            g << (i ? ", " : "") << "'" << data.string() << "' index " << first + i << " with "
              << style << " lw 2 dt " << i + 1 << " lc rgb '" << (i % 2 ? "#888888" : "black")
              << "' title 'Pareto front "
              << nu_text(block_nus[i]) << "'";
          g << "\n";
        };
        g << "set terminal png size 1500,700\nset termoption noenhanced\nset output '"
          << (out / "pareto.png").string()
          << "'\nset multiplot layout 1,2 title 'What accuracy costs in time (accuracy_bench): "
             "total force error against the converged answer = element+mesh + tier; errors > 10 "
             "off scale'\nset logscale xy\nset yrange [1e-2:10]\nset grid\n"
             "set key top right font ',9'\n"
             "set ylabel 'total force error vs the converged answer'\n"
             "set xlabel 'contact step p99, without the tier update (us)'\nplot ";
        series("1:2");
        fronts(blocks.size(), "steps");
        g << "set xlabel 'tier update rate (Hz; LINEAR has no update)'\nplot ";
        series("3:2");
        fronts(blocks.size() + block_nus.size(), "fsteps");
        g << "unset multiplot\n";
        g.close();
        if (std::system(("gnuplot '" + script.string() + "'").c_str()) != 0)
          throw std::runtime_error("gnuplot failed on " + script.string());
      } else {
        throw std::runtime_error("gnuplot not installed: cannot write pareto.png");
      }
    }
    if (!csv) std::fprintf(stderr, "results in %s\n", fs::absolute(out).string().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "accuracy_bench: error: %s\n", e.what());
    return 1;
  }
}
