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
// Against the outside answer (columns after max_strain; needs `ccx`, else they print nan):
// discretization_error = the error of the run's element on the run's mesh in a small-strain
// patch press against CalculiX C3D10 (quadratic tetrahedra, mid-edge nodes added) on the finest
// mesh: the host alone, its fixed nodes as in the scene, the surface nodes within the patch
// radius of the press point (brain 12 mm, cube 20 mm on the face) held and moved 2 mm
// along -up, linear elastic (the element's LINEAR StaticSolver); |F - F_c3d10| / F_c3d10 with F
// the patch force. C3D10 on the finest mesh is the best outside answer here, not the continuum
// limit (DIR/converged.csv lists C3D10 on every mesh, so its own mesh trend is visible).
// model_error = |f - f_nl| / |f_nl| with f_nl the NONLINEAR tier's force on the same mesh, element
// and press (the tier's error; 0 for NONLINEAR, which is the model). total_error =
// discretization_error + model_error (the two parts may also cancel).
// The cube is also compared with CalculiX (NLGEOM, neo-Hookean, C3D4 on the same mesh, against
// the tiers with linear-tet, the element C3D4 is, whatever --element says): the
// tool's footprint prescribed to the press depth, DIR/calculix.csv.
//
// Writes DIR/accuracy.csv (the table printed), DIR/converged.csv, DIR/calculix.csv,
// DIR/pareto.png (total error against step time, log-log, one colour per element and tier, the
// Pareto front drawn), and the two measured tables the server reads for its live estimate
// (SimStatus expected_force_error, discretization_error_estimate, total_error_estimate): the
// tier's error (--table, default DIR/force_error.csv: finest mesh, exact coupling, every
// element, with the element and the host's nu) and the discretization error (--disc-table,
// default DIR/discretization_error.csv: every element and mesh, keyed by the host's element, nu,
// vertex and tetrahedron counts). The committed ones are in share/accuracy/.
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
// patch press (no discretization rows, those columns nan) and no CalculiX comparison: the runs
// the tier table takes (its rows are the finest mesh's), at a fraction of the time.
#include "c3d10_press.hpp"
#include "common/cli.hpp"
#include "common/stats.hpp"
#include "idl/wire/recording_io.hpp"
#include "server/cli/replay.hpp"
#include "server/fem/calculix.hpp"
#include "server/fem/element.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/static_solver.hpp"
#include "server/fem/strain.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"

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
    trace << "step,time_s,fx_n,fy_n,fz_n,force_n,tier_updated,tier_update_us,inverted_elements\n";
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
            << st.tier_update_us << ',' << st.inverted_elements << std::endl;  // watchable
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

// The same press solved by CalculiX with C3D10 (a node added at the middle of every edge; the
// fixed and pressed sets take the mid-nodes of their edges), linear elastic, unit N.
double c3d10_patch_force(const SceneCase& sc, const neurosim::scene::LoadedMesh& host,
                         const std::vector<int>& patch, const fs::path& dir,
                         const std::string& job) {
  if (host.tissue_with_other_material() != nullptr)
    throw std::runtime_error(sc.name + ": host tissue '" + host.tissue_with_other_material()->name +
                             "' has its own material: the C3D10 check takes one material");
  const auto q = neurosim::bench::quadratic_tets(host.mesh);
  const std::vector<int> fixed_q = q.with_mid(host.fixed_nodes), patch_q = q.with_mid(patch);
  const auto r = neurosim::bench::run_c3d10_press(dir, job, "accuracy_bench patch press", q,
                                                  host.material, fixed_q, patch_q,
                                                  -kPatchPressM * sc.up);
  double f = 0.0;
  for (int v : patch_q) f -= r.reaction_n.segment<3>(3 * v).dot(sc.up);
  return f;
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
  std::vector<std::string> elements, press_filter;
  std::vector<std::string> scenes{"cube_cylinder", "brain_artery"};
  neurosim::cli::Parser cli("accuracy_bench",
                            "What accuracy costs in time: tiers x resolutions x coupling over "
                            "recorded presses, errors against the finest nonlinear run and, split "
                            "into discretization and model, against CalculiX C3D10.");
  cli.add_flag("--csv", csv, "print only the CSV table");
  cli.add_option("--out", out_dir, "output folder DIR (accuracy.csv, calculix.csv, pareto.png)")
      ->required();
  cli.add_option("--scene", scenes, "scenes to run (cube_cylinder, brain_artery)")
      ->capture_default_str();
  cli.add_option("--element", elements,
                 "smoothed-tet | anp-tet | linear-tet, repeatable: the element axis (every "
                 "mesh's element per run; default: the scenes' material.element)")
      ->check(neurosim::cli::one_of({"smoothed-tet", "anp-tet", "linear-tet"}));
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
        for (double f : {0.5, 1.0, 2.0})
          if (!finest_only || f == 2.0) sc.resolutions.push_back({"", cube_at(path, f), 0});
      } else if (name == "brain_artery") {
        // The demo's press point on the right lateral surface, a 6 mm probe.
        sc.origin = Vec3(0.1605, 0.1125, 0.0787);
        sc.up = Vec3(0.963, 0.176, 0.202).normalized();
        sc.side = sc.up.cross(Vec3::UnitZ()).normalized();
        sc.tip_radius_m = 0.006;
        sc.patch_radius_m = 0.012;
        const fs::path models = out / "models";
        if (!finest_only) {
          sc.resolutions.push_back({"", brain_at(11.0, models), 0});
          sc.resolutions.push_back({"", brain_at(9.0, models), 0});
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
        "total_error";
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
      // The run's force and (other tiers) NONLINEAR's on the same mesh settled by the end of the
      // hold (kSettledSpread); the tier table takes only such rows.
      bool settled;
    };
    const bool ccx = !finest_only && have_program("ccx");
    if (finest_only)
      std::fprintf(stderr, "accuracy_bench: --finest-only: no C3D10 and no CalculiX: "
                           "discretization_error and total_error print nan\n");
    else if (!ccx)
      std::fprintf(stderr, "accuracy_bench: note: ccx (calculix-ccx) not installed: "
                           "discretization_error and total_error print nan\n");
    std::ofstream conv_csv(out / "converged.csv");
    conv_csv << "scene,resolution,element,patch_nodes,patch_force_n,rel_error_vs_c3d10_finest,"
                "solve_s\n";
    std::vector<Row> rows;
    std::vector<std::string> disc_rows;  // the server's discretization table
    using neurosim::fem::Tier;
    for (const auto& sc : cases) {
      std::vector<std::string> recordings;
      for (const auto& p : presses) recordings.push_back(write_press(sc, p, out / "recordings"));
      std::vector<std::string> scene_elements = elements;
      if (scene_elements.empty())
        scene_elements.push_back(
            neurosim::fem::element_name(sc.resolutions.back().model.meshes.at(0).material.element));
      // The discretization check: C3D10 on every mesh, each element on every mesh, against
      // C3D10 on the finest.
      std::map<std::pair<std::string, int>, double> disc;  // (element, resolution index)
      if (ccx) {
        std::vector<double> f_c3d10(sc.resolutions.size());
        std::vector<std::vector<int>> patches(sc.resolutions.size());
        for (std::size_t ri = sc.resolutions.size(); ri-- > 0;) {
          const auto& res = sc.resolutions[ri];
          const auto& host = res.model.meshes.at(0);
          patches[ri] = patch_nodes(sc, host.mesh, res.label);
          const auto t0 = std::chrono::steady_clock::now();
          f_c3d10[ri] = c3d10_patch_force(sc, host, patches[ri], out / "c3d10",
                                          sc.name + "_" + res.label);
          const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          char line[256];
          std::snprintf(line, sizeof line, "%s,%d,C3D10,%zu,%.6g,%.4g,%.1f", sc.name.c_str(),
                        res.host_vertices, patches[ri].size(), f_c3d10[ri],
                        std::abs(f_c3d10[ri] - f_c3d10.back()) / f_c3d10.back(), dt);
          conv_csv << line << '\n';
          std::fprintf(stderr, "  converged: %s\n", line);
        }
        for (const auto& el_name : scene_elements) {
          const auto el = *neurosim::fem::parse_element(el_name);
          for (std::size_t ri = 0; ri < sc.resolutions.size(); ++ri) {
            const auto& res = sc.resolutions[ri];
            const auto t0 = std::chrono::steady_clock::now();
            const double f = element_patch_force(sc, res.model.meshes.at(0), el, patches[ri]);
            const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            const double e = std::abs(f - f_c3d10.back()) / f_c3d10.back();
            disc[{el_name, static_cast<int>(ri)}] = e;
            {
              const auto& host = res.model.meshes.at(0);
              char drow[256];
              std::snprintf(drow, sizeof drow, "%s,%s,%.6g,%zu,%zu,%.4g", sc.name.c_str(),
                            el_name.c_str(), host.material.poisson_ratio, host.mesh.num_vertices(),
                            host.mesh.num_tets(), e);
              disc_rows.emplace_back(drow);
            }
            char line[256];
            std::snprintf(line, sizeof line, "%s,%d,%s,%zu,%.6g,%.4g,%.1f", sc.name.c_str(),
                          res.host_vertices, el_name.c_str(), patches[ri].size(), f, e, dt);
            conv_csv << line << '\n';
            std::fprintf(stderr, "  converged: %s\n", line);
          }
        }
        conv_csv.flush();
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
        const auto d_it = disc.find({el_name, ri});
        const double disc_err =
            d_it != disc.end() ? d_it->second : std::numeric_limits<double>::quiet_NaN();
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
                    res.model.meshes.at(0).material.poisson_ratio,
                    r.unsettled <= kSettledSpread && nl_settled[pi] != 0};
            char line[512];
            std::snprintf(line, sizeof line,
                          "%s,%s,%d,%s,%d,%s,%.1f,%.1f,%.1f,%.4g,%.4g,%.4g,%s,%.4g,%.4g,%.4g",
                          row.scene.c_str(), row.tier.c_str(), row.resolution, row.coupling.c_str(),
                          row.iterations, row.press.c_str(), row.p50, row.p99, row.update_hz,
                          row.disp_err, row.force_err, row.strain, row.element.c_str(),
                          row.disc_err, row.model_err, row.total_err);
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
    // The discretization table the server reads (only with ccx: no outside answer, no rows).
    {
      std::ofstream t(disc_table_path);
      if (!t) throw std::runtime_error(disc_table_path + ": cannot write");
      t << "# Discretization error (element + mesh) of each scene's host mesh against\n"
           "# CalculiX C3D10 on the finest mesh of the scene's series (not the converged answer\n"
           "# where that mesh is coarse: press_refinement_bench --disc-table extrapolates nested\n"
           "# refinements), in accuracy_bench's small-strain patch press (docs/accuracy.md). Read by\n"
           "# neurosim-server for SimStatus.discretization_error_estimate: the row of the host's\n"
           "# element, nu, vertex and tetrahedron counts, none: unknown.\n"
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

    // pareto.png: total error (discretization against C3D10 + the tier's) against step p99, one
    // colour per element and tier, the front over all runs. Without ccx the total is unknown:
    // force_rel_error (against our own reference) is plotted and the axis says so.
    {
      const fs::path data = out / "pareto.dat";
      std::ofstream d(data);
      auto y_of = [&](const Row& r) { return ccx ? r.total_err : r.force_err; };
      std::vector<std::pair<std::string, std::string>> blocks;  // (element, tier)
      for (const auto& r : rows)
        if (std::find(blocks.begin(), blocks.end(), std::make_pair(r.element, r.tier)) ==
            blocks.end())
          blocks.emplace_back(r.element, r.tier);
      for (const auto& [el, tier] : blocks) {
        d << "# " << el << " " << tier << "\n";
        int n = 0;
        for (const auto& r : rows)
          if (r.element == el && r.tier == tier && std::isfinite(y_of(r)) && y_of(r) > 0.0) {
            d << r.p99 << ' ' << y_of(r) << '\n';
            ++n;
          }
        if (n == 0) d << "NaN NaN\n";  // keeps the block (gnuplot index)
        d << "\n\n";
      }
      std::vector<std::pair<double, double>> pts;
      for (const auto& r : rows)
        if (std::isfinite(y_of(r)) && y_of(r) > 0.0) pts.emplace_back(r.p99, y_of(r));
      std::sort(pts.begin(), pts.end());
      d << "# pareto front\n";
      double best = 1e300;
      for (const auto& p : pts)
        if (p.second < best) {
          best = p.second;
          d << p.first << ' ' << p.second << '\n';
        }
      if (pts.empty()) d << "NaN NaN\n";
      d.close();
      if (have_program("gnuplot")) {
        const fs::path script = out / "pareto.gp";
        std::ofstream g(script);
        g << "set terminal png size 900,600\nset termoption noenhanced\nset output '"
          << (out / "pareto.png").string()
          << "'\nset logscale xy\nset xlabel 'contact step p99, without the tier update (us)'\n"
             "set yrange [1e-3:10]\n"
             "set ylabel '"
          << (ccx ? "total force error: element+mesh vs C3D10 (finest) + tier"
                  : "force error against the finest nonlinear run (no ccx)")
          << "'\nset title 'What accuracy costs in time (accuracy_bench; errors > 10 off scale)'\n"
             "set key top right\n"
             "set grid\nplot ";
        const char* colours[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"};
        for (std::size_t k = 0; k < blocks.size(); ++k)
          g << "'" << data.string() << "' index " << k << " with points pt " << 5 + 2 * (k % 4)
            << " lc rgb '" << colours[k % 6] << "' title '" << blocks[k].first << " "
            << blocks[k].second << "', ";
        g << "'" << data.string() << "' index " << blocks.size()
          << " with steps lw 2 lc rgb 'black' title 'Pareto front'\n";
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
