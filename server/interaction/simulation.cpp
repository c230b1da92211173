// Simulation: scene -> coupled bodies (exact tie, coupled_body.hpp; frictionless sliding pairs,
// sliding_coupling.hpp) -> per-step LCP of the tool contact rows and the sliding rows together.
#include "server/interaction/simulation.hpp"

#include "common/clock.hpp"
#include "server/fusion/carve.hpp"
#include "server/fusion/coupling_map.hpp"
#include "server/fusion/inclusion.hpp"
#include "server/fusion/triangle_surface.hpp"
#include "server/interaction/contact_columns.hpp"
#include "server/interaction/contact_lcp.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/sliding_coupling.hpp"
#include "server/interaction/tier_worker.hpp"
#include "server/interaction/tool_geometry.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

namespace {

using common::Clock;
using common::seconds_since;

// One unilateral contact row: a contactable node of a body against one tool.
struct Row {
  int body{-1};
  int slot{-1};  // contact slot in the body
  int tool{-1};
  double depth_m{0.0};   // penetration along the node's inward normal, unit m
  double height_m{0.0};  // the tool centre's depth below the node's surface patch, unit m
  bool shaft{false};     // pushed by the shaft (else by the tip)
};

bool deeper(const Row& a, const Row& b) {
  if (a.depth_m != b.depth_m) return a.depth_m > b.depth_m;
  if (a.body != b.body) return a.body < b.body;
  return a.slot < b.slot;
}

}  // namespace

// A scene mesh in the physics: the loaded (possibly carved) mesh and its place in a body.
struct MeshEntry {
  std::unique_ptr<scene::LoadedMesh> loaded;  // stable address: bodies point into it
  int body{-1};                               // body it belongs to (host or tied), -1: inert
  int tie{-1};                                // tie index in that body when embedded (TIE)
  int slide{-1};                              // slide index in that body (SLIDING)
};

// A body (host + tied and sliding meshes), constant after build.
struct BodyModel {
  std::unique_ptr<CoupledBody> body;
  PointGrid grid;
  std::vector<mesh::Vec3> rest_m;  // per contact slot
  double max_penetration_m{0.0};
  double validity_radius_m{0.0};
  // SLIDING couplings hosted by the body: B's part, and where its rows start among the body's
  // sliding rows (CoupledBody::sliding_rows); the body's rows start at sliding_offset in the LCP.
  std::vector<std::unique_ptr<SlidingCoupling>> slides;
  std::vector<int> slide_first_row;
  int sliding_offset{0};
  // The host's material and supports (for the COROTATIONAL and NONLINEAR tiers' equilibrium).
  fem::Material host_material;
  std::vector<int> host_fixed_nodes;
};

// What a step changes on a body.
struct BodyState {
  std::unique_ptr<ContactColumns> columns;  // filled on first touch (or when the state is made)
  std::vector<long long> stamp;  // per contact slot: last tool query that saw it
  std::vector<int> row_of_slot;  // per contact slot: row in this step or -1
  // Last good step's contact forces on the body, per slot (unit N), and sliding row forces.
  std::vector<int> force_slots;
  std::vector<mesh::Vec3> forces_n;
  Eigen::VectorXd sliding_lambda;
};

// The constant physics model: meshes, bodies (factorizations, coupling operators, contact
// geometry), tool shapes. Built once from the scene's Model; never written by a step.
class Model {
 public:
  Model(const scene::Model& model, const SimulationOptions& options);

  const MeshEntry& entry(int m) const {
    if (m < 0 || m >= static_cast<int>(meshes_.size())) {
      throw std::invalid_argument("Simulation: mesh index " + std::to_string(m) + " out of range");
    }
    return meshes_[m];
  }
  // Host field (ties included) for contact forces on slots, sliding row forces and other nodal
  // forces (may be empty); from cached full columns when `columns` has them (stepping thread).
  // `ws`: the caller's solve scratch (the field thread's), so no lock in the Model is taken.
  void host_field(const BodyModel& b, const std::vector<int>& slots,
                  const std::vector<Vec3>& forces_n, const Eigen::VectorXd& sliding_lambda_n,
                  const Eigen::VectorXd& nodal_forces_n, const ContactColumns* columns,
                  Eigen::VectorXd& u_host_m, fem::SolveWorkspace* ws = nullptr) const;
  // Field of mesh `m` (entry e) from its body's host field.
  void mesh_field(const MeshEntry& e, const Eigen::VectorXd& sliding_lambda_n,
                  const Eigen::VectorXd& u_host_m, Eigen::VectorXd& u_m) const;
  // COROTATIONAL and NONLINEAR: field of mesh entry e from its body's stacked equilibrium
  // (host, then the tied meshes in the order of CoupledBody::ties()).
  void tier_mesh_field(const MeshEntry& e, const Eigen::VectorXd& stacked_u_m,
                       Eigen::VectorXd& u_m) const;

  SimulationOptions options_;
  std::string source_;
  std::vector<MeshEntry> meshes_;
  std::vector<BodyModel> bodies_;
  std::vector<ToolShape> tools_;
  SetupStats setup_;
  int num_sliding_{0};  // sliding rows, first in the LCP
  scene::Tier tier_{scene::Tier::kLinear};
};

// Everything a step changes (MuJoCo's mjData): per body the contact-compliance cache and the
// last good forces; the rows, the Delassus operator and the LCP with its warm start; the last
// good answer per tool. Sized at construction and per tool count, no allocation once warmed up.
class State {
 public:
  // The compliance columns of every contactable node when options.precompute_contact_columns,
  // and, with sliding rows, the step workspace and the inverse of their constant block.
  explicit State(const Model& m);
  void step(const Model& m, const std::vector<ToolPose>& poses,
            std::vector<ToolContact>& contacts, StepStats& stats);
  // Host field for the last good step (stepping thread: may use the cached full columns).
  void host_field(const Model& m, int body, Eigen::VectorXd& u_host_m) const {
    if (tier_) {
      u_host_m = tier_->linearization(body).u_m.head(
          3 * static_cast<Eigen::Index>(m.bodies_[body].body->host().num_vertices()));
      return;
    }
    const BodyState& bs = bodies_[body];
    m.host_field(m.bodies_[body], bs.force_slots, bs.forces_n, bs.sliding_lambda,
                 Eigen::VectorXd(), bs.columns.get(), u_host_m);
  }

  std::vector<BodyState> bodies_;
  double columns_s_{0.0};  // compliance columns computed at construction, unit s
  double sliding_s_{0.0};  // step workspace and constant sliding block at construction, unit s
  // COROTATIONAL and NONLINEAR: every body's equilibrium, following the contact forces
  // (tier_worker.hpp); null for LINEAR.
  std::unique_ptr<TierWorker> tier_;
  double tier_s_{0.0};  // tier solvers (pattern, symbolic analysis) at construction, unit s

 private:
  void reserve_workspace(const Model& m, int tools);
  void collect_rows(const Model& m, int tool, const ToolPose& pose, const Vec3& axis);

  long long stamp_counter_{0};
  std::vector<int> candidates_;
  std::vector<Row> tool_rows_;
  std::vector<Row> rows_;
  std::vector<std::vector<int>> missing_;
  Eigen::MatrixXd w_;
  Eigen::VectorXd delta_, lambda_;
  std::vector<char> sliding_active_;  // per sliding row: carried a force in the last good step
  std::vector<char> warm_;            // LCP warm start
  ContactLcp lcp_;
  bool lcp_constant_block_{false};  // set_constant_block done
  std::vector<ToolContact> last_good_;
  std::vector<TierLoad> tier_loads_;  // per body, the step's contact forces for the worker
};

std::shared_ptr<const Model> build_model(const scene::Model& model,
                                         const SimulationOptions& options) {
  return std::make_shared<const Model>(model, options);
}
void StateDeleter::operator()(State* state) const { delete state; }
StatePtr make_state(const Model& model) { return StatePtr(new State(model)); }
void step(const Model& model, State& state, const std::vector<ToolPose>& poses,
          std::vector<ToolContact>& contacts, StepStats& stats) {
  state.step(model, poses, contacts, stats);
}

namespace {

class SimulationImpl final : public Simulation {
 public:
  SimulationImpl(const scene::Model& model, const SimulationOptions& options)
      : SimulationImpl(build_model(model, options)) {}
  explicit SimulationImpl(std::shared_ptr<const Model> model)
      : model_(std::move(model)), state_(make_state(*model_)) {
    setup_ = model_->setup_;
    setup_.columns_s += state_->columns_s_;
    setup_.sliding_s += state_->sliding_s_;
    setup_.total_s += state_->columns_s_ + state_->sliding_s_ + state_->tier_s_;
  }

  int num_meshes() const override { return static_cast<int>(model_->meshes_.size()); }
  const std::string& mesh_id(int m) const override { return model_->entry(m).loaded->id; }
  const mesh::TetMesh& mesh(int m) const override { return model_->entry(m).loaded->mesh; }
  bool mesh_active(int m) const override { return model_->entry(m).body >= 0; }
  const SetupStats& setup_stats() const override { return setup_; }
  const std::vector<int>& fixed_nodes(int m) const override {
    return model_->entry(m).loaded->fixed_nodes;
  }
  int num_tools() const override { return static_cast<int>(model_->tools_.size()); }

  void step(const std::vector<ToolPose>& poses, std::vector<ToolContact>& contacts,
            StepStats& stats) override {
    interaction::step(*model_, *state_, poses, contacts, stats);
  }
  void displacements(int mesh, Eigen::VectorXd& u_m) const override;
  double tie_residual_m() const override;
  const CoupledBody* body_of(int m) const override {
    const int b = model_->entry(m).body;
    return b < 0 ? nullptr : model_->bodies_[b].body.get();
  }
  void last_contact_forces(int m, std::vector<int>& slots,
                           std::vector<Vec3>& forces_n) const override {
    slots.clear();
    forces_n.clear();
    const int b = model_->entry(m).body;
    if (b < 0) return;
    slots = state_->bodies_[b].force_slots;
    forces_n = state_->bodies_[b].forces_n;
  }
  void sliding_pairs(int m, std::vector<SlidingPairState>& pairs) const override;
  double sliding_penetration_m() const override;
  void snapshot(FieldSnapshot& s) const override;
  void displacements(FieldSnapshot& s, int mesh, Eigen::VectorXd& u_m) const override;
  int body_index(int m) const override { return model_->entry(m).body; }
  IterativeReport iterative_report(int m) const override {
    const int b = model_->entry(m).body;
    if (b < 0 || !state_->bodies_[static_cast<std::size_t>(b)].columns) return {};
    return state_->bodies_[static_cast<std::size_t>(b)].columns->iterative_report();
  }
  scene::Tier tier() const override { return model_->tier_; }
  double tier_update_rate_hz() const override {
    return state_->tier_ ? state_->tier_->rate_hz() : 0.0;
  }
  std::uint64_t tier_update_failures() const override {
    return state_->tier_ ? state_->tier_->failures() : 0;
  }
  std::string tier_last_error() const override {
    return state_->tier_ ? state_->tier_->last_error() : std::string();
  }

 private:
  std::shared_ptr<const Model> model_;
  StatePtr state_;
  SetupStats setup_;
};

}  // namespace

Model::Model(const scene::Model& model, const SimulationOptions& options)
    : options_(options), source_(model.source) {
  const auto t_start = Clock::now();
  if (options_.max_contact_nodes_per_tool < 1 || options_.lcp_max_iterations < 1 ||
      !(options_.lcp_tolerance > 0.0) || !(options_.max_penetration_m >= 0.0) ||
      !std::isfinite(options_.max_penetration_m) || !(options_.candidate_margin >= 0.0)) {
    throw std::invalid_argument(source_ + ": invalid SimulationOptions");
  }
  tier_ = model.effects.tier;
  if (!(options_.tier_newton_tolerance > 0.0) || !(options_.tier_newton_tolerance < 1e-2) ||
      options_.tier_update_steps < 0) {
    throw std::invalid_argument(source_ + ": invalid SimulationOptions.tier_newton_tolerance or "
                                "tier_update_steps");
  }

  // Meshes, in scene order (copies: a host is carved below).
  auto t0 = Clock::now();
  for (const auto& lm : model.meshes) {
    MeshEntry e;
    e.loaded = std::make_unique<scene::LoadedMesh>(lm);
    meshes_.push_back(std::move(e));
  }
  setup_.load_meshes_s = seconds_since(t0);

  // Roles from the couplings (only when the scene asks for coupling; checked by the scene
  // compiler: priorities, one host per embedded mesh, no nesting).
  std::vector<int> host_of(meshes_.size(), -1);
  std::vector<char> is_host(meshes_.size(), 0);
  std::vector<char> iterative_host(meshes_.size(), 0);  // a coupling asks for the baseline
  std::vector<char> sliding(meshes_.size(), 0);         // embedded by a SLIDING coupling
  if (model.effects.coupling) {
    for (const auto& cp : model.couplings) {
      // The corotational and nonlinear tiers solve ties exactly in their own Newton system;
      // sliding pairs and the paper's iterative baseline exist in the linear tier only.
      if (tier_ != scene::Tier::kLinear && (cp.kind == scene::CouplingKind::kSliding ||
                                            cp.method == scene::CouplingMethod::kIterative)) {
        throw std::runtime_error(
            source_ + ": coupling " + model.meshes[cp.host].id + " / " +
            model.meshes[cp.embedded].id + ": " +
            (cp.kind == scene::CouplingKind::kSliding ? "SLIDING" : "method ITERATIVE") +
            " is implemented in the LINEAR tier only, not in effects.tier " +
            scene::tier_name(tier_) + " (use a TIE coupling with method EXACT)");
      }
      host_of[cp.embedded] = cp.host;
      if (cp.method == scene::CouplingMethod::kIterative) iterative_host[cp.host] = 1;
      sliding[cp.embedded] = cp.kind == scene::CouplingKind::kSliding;
      is_host[cp.host] = 1;
    }
  }

  // Inclusion decision (Algorithm 1) and coupling map (paper 2.6) per coupled pair, on the
  // host's full mesh; then the host is carved: the embedded mesh has the higher priority and
  // keeps its volume (paper 2.4), so the host's tetrahedra inside S' are removed and S' becomes
  // the host's boundary there. Vertex ids do not change (nodes left without a tetrahedron are
  // fixed: they are inside the embedded mesh and carry nothing).
  struct PendingTie {
    std::vector<int> embedded_nodes;
    std::vector<std::array<int, 3>> tris;
    std::vector<std::array<double, 3>> weights;
    std::vector<mesh::Vec3> points_m;  // closest points on S'
    double max_distance_m{0.0};
  };
  std::vector<PendingTie> pending(meshes_.size());
  std::vector<std::vector<char>> carve(meshes_.size());
  for (std::size_t m = 0; m < meshes_.size(); ++m) {
    if (host_of[m] < 0) continue;
    const int h = host_of[m];
    auto& host = *meshes_[h].loaded;
    auto& emb = *meshes_[m].loaded;
    const std::string what = source_ + ": coupling " + host.id + " / " + emb.id;
    t0 = Clock::now();
    const auto surface = fusion::TriangleSurface::of(emb.mesh, emb.id);
    fusion::NewBoundary boundary;
    fusion::CouplingMap map;
    try {
      boundary = fusion::find_new_boundary(host.mesh, surface);
      map = fusion::build_coupling_map(host.mesh.vertices(), boundary, surface);
    } catch (const std::exception& ex) {
      throw std::runtime_error(what + ": " + ex.what());
    }
    setup_.fusion_s += seconds_since(t0);
    PendingTie& p = pending[m];
    p.embedded_nodes = map.embedded_nodes;
    p.tris.resize(map.embedded_nodes.size());
    p.weights.resize(map.embedded_nodes.size());
    p.points_m.resize(map.embedded_nodes.size());
    for (std::size_t k = 0; k < map.embedded_nodes.size(); ++k) {
      const auto& sp = map.embedded_on_boundary[k];
      const auto& tri = boundary.triangles.at(sp.triangle);
      p.tris[k] = {tri[0], tri[1], tri[2]};
      p.weights[k] = sp.weights;
      p.points_m[k] = sp.point_m;
    }
    p.max_distance_m = map.embedded_to_boundary.max_m;
    if (options_.carve_host) {
      const auto inside = fusion::tets_inside(host.mesh, boundary.triangles);
      if (carve[h].empty()) carve[h].assign(host.mesh.num_tets(), 0);
      for (std::size_t t = 0; t < inside.size(); ++t)
        if (inside[t]) carve[h][t] = 1;
    }
  }
  for (std::size_t h = 0; h < meshes_.size(); ++h) {
    if (carve[h].empty()) continue;
    auto& host = *meshes_[h].loaded;
    std::vector<mesh::Tet> kept;
    std::vector<int> labels;
    for (std::size_t t = 0; t < host.mesh.num_tets(); ++t) {
      if (carve[h][t]) continue;
      kept.push_back(host.mesh.tets()[t]);
      labels.push_back(host.mesh.tet_labels().empty() ? 0 : host.mesh.tet_labels()[t]);
    }
    setup_.carved_tets += static_cast<int>(host.mesh.num_tets() - kept.size());
    if (kept.size() == host.mesh.num_tets()) continue;
    if (kept.empty())
      throw std::runtime_error(source_ + ": host " + host.id +
                               " lies entirely inside its embedded mesh");
    mesh::BuildOptions bo;
    bo.drop_unused_vertices = false;
    bo.source = host.mesh.source() + " (carved around embedded meshes)";
    std::vector<char> used(host.mesh.num_vertices(), 0);
    for (const auto& t : kept)
      for (int v : t) used[v] = 1;
    mesh::TetMesh carved = mesh::TetMesh::build(host.mesh.vertices(), kept, bo);
    carved.set_tet_labels(std::move(labels));
    host.mesh = std::move(carved);
    for (std::size_t v = 0; v < used.size(); ++v)
      if (!used[v]) host.fixed_nodes.push_back(static_cast<int>(v));
    std::sort(host.fixed_nodes.begin(), host.fixed_nodes.end());
    host.fixed_nodes.erase(std::unique(host.fixed_nodes.begin(), host.fixed_nodes.end()),
                           host.fixed_nodes.end());
  }

  // Bodies: every host and every mesh with fixed nodes that is not embedded.
  for (std::size_t m = 0; m < meshes_.size(); ++m) {
    const auto& lm = *meshes_[m].loaded;
    if (host_of[m] >= 0) continue;
    if (lm.fixed_nodes.empty()) {
      if (is_host[m])
        throw std::runtime_error(source_ + ": host mesh " + lm.id + " has no fixed nodes");
      continue;  // floating and untied: inert (cannot carry a contact force)
    }
    BodyModel b;
    try {
      b.body =
          std::make_unique<CoupledBody>(static_cast<int>(m), lm.mesh, lm.material, lm.fixed_nodes);
    } catch (const std::exception& ex) {
      throw std::runtime_error(source_ + ": mesh " + lm.id + ": " + ex.what());
    }
    setup_.factor_s += b.body->timing().factor_s;
    b.host_material = lm.material;
    b.host_fixed_nodes = lm.fixed_nodes;
    b.body->set_cache_dir(options_.compliance_cache_dir);
    if (iterative_host[m])
      b.body->set_iterative(IterativeOptions{options_.iterative_max_iterations,
                                             options_.iterative_tolerance, 0.0});
    meshes_[m].body = static_cast<int>(bodies_.size());
    bodies_.push_back(std::move(b));
  }
  // Ties: each embedded mesh condensed onto its tied nodes and attached to its host's body.
  for (std::size_t m = 0; m < meshes_.size(); ++m) {
    if (host_of[m] < 0) continue;
    const int h = host_of[m];
    auto& emb = *meshes_[m].loaded;
    const PendingTie& p = pending[m];
    auto& body = bodies_[meshes_[h].body];
    if (sliding[m]) {
      // Frictionless unilateral pairs: B's surface node, its closest point on S', B's normal.
      const std::string what =
          source_ + ": SLIDING coupling " + meshes_[h].loaded->id + " / " + emb.id;
      const auto normals = surface_vertex_normals(emb.mesh);
      std::vector<SlidingPair> pairs;
      std::vector<HostSlidingRow> rows;
      for (std::size_t k = 0; k < p.embedded_nodes.size(); ++k) {
        const int v = p.embedded_nodes[k];
        const Vec3& n = normals.at(v);
        if (n.squaredNorm() == 0.0) {
          throw std::runtime_error(what + ": surface node " + std::to_string(v) + " of " + emb.id +
                                   " has no normal (degenerate faces)");
        }
        const double g0 = options_.sliding_geometric_gap
                              ? std::max(0.0, n.dot(p.points_m[k] - emb.mesh.vertices()[v]))
                              : 0.0;
        pairs.push_back(SlidingPair{v, p.tris[k], p.weights[k], n, g0});
        rows.push_back(HostSlidingRow{p.tris[k], p.weights[k], n});
      }
      t0 = Clock::now();
      try {
        const int first = body.body->add_sliding_rows(rows, what);
        body.slides.push_back(std::make_unique<SlidingCoupling>(SlidingDefinition{
            static_cast<int>(m), &emb.mesh, emb.material, emb.fixed_nodes, std::move(pairs),
            options_.sliding_anchor_ratio, what + ": mesh " + emb.id}));
        body.slide_first_row.push_back(first);
      } catch (const std::invalid_argument& ex) {
        throw std::runtime_error(ex.what());
      }
      setup_.sliding_s += seconds_since(t0);
      meshes_[m].body = meshes_[h].body;
      meshes_[m].slide = static_cast<int>(body.slides.size()) - 1;
      continue;
    }
    try {
      body.body->add_tie(TieDefinition{static_cast<int>(m), &emb.mesh, emb.material,
                                       emb.fixed_nodes, p.embedded_nodes, p.tris, p.weights,
                                       p.max_distance_m});
    } catch (const std::exception& ex) {
      throw std::runtime_error(source_ + ": coupling " + meshes_[h].loaded->id + " / " + emb.id +
                               ": " + ex.what());
    }
    meshes_[m].body = meshes_[h].body;
    meshes_[m].tie = static_cast<int>(body.body->ties().size()) - 1;
  }
  for (auto& b : bodies_) {
    b.body->finalize();
    const auto& tm = b.body->timing();
    setup_.condense_s += tm.condense_s;
    setup_.boundary_s += tm.boundary_s;
    setup_.operator_s += tm.operator_s;
    setup_.sliding_s += tm.sliding_s;
    b.sliding_offset = num_sliding_;
    num_sliding_ += b.body->sliding().size();
    if (b.body->cache_hit()) ++setup_.cache_hits;
    setup_.boundary_nodes += static_cast<int>(b.body->boundary_nodes().size());
    for (const auto& tie : b.body->ties())
      setup_.tied_nodes += static_cast<int>(tie.tied_nodes().size());
    // Contact geometry: rest positions of contactable nodes on a grid.
    const auto& host = b.body->host();
    for (int v : b.body->contact_nodes()) b.rest_m.push_back(host.vertices()[v]);
    const double edge = host.mean_edge_length();
    b.grid = PointGrid(b.rest_m, 2.0 * edge);
    Vec3 lo, hi;
    host.bounds(lo, hi);
    b.max_penetration_m =
        options_.max_penetration_m > 0.0 ? options_.max_penetration_m : 0.45 * (hi - lo).minCoeff();
    b.validity_radius_m = 0.5 * edge;
  }

  if (model.effects.tool_contact) {
    for (const auto& tool : model.tools)
      tools_.push_back(ToolShape{tool.tip_radius_m, tool.shaft_radius_m, tool.shaft_length_m});
  }
  setup_.sliding_rows = num_sliding_;
  setup_.total_s = seconds_since(t_start);
}

State::State(const Model& m) {
  bodies_.resize(m.bodies_.size());
  for (std::size_t i = 0; i < m.bodies_.size(); ++i) {
    const BodyModel& b = m.bodies_[i];
    BodyState& bs = bodies_[i];
    bs.columns = std::make_unique<ContactColumns>(*b.body, m.options_.cache_full_field_columns);
    bs.stamp.assign(b.rest_m.size(), -1);
    bs.row_of_slot.assign(b.rest_m.size(), -1);
    bs.sliding_lambda.setZero(b.body->sliding().size());
    if (m.options_.precompute_contact_columns) {
      const auto t0 = Clock::now();
      std::vector<int> all(b.rest_m.size());
      for (std::size_t s = 0; s < all.size(); ++s) all[s] = static_cast<int>(s);
      bs.columns->ensure(all);
      columns_s_ += seconds_since(t0);
    }
  }
  missing_.resize(m.bodies_.size());
  sliding_active_.assign(m.num_sliding_, 0);
  tier_loads_.resize(m.bodies_.size());
  if (m.tier_ != scene::Tier::kLinear && !m.bodies_.empty()) {
    const auto t0 = Clock::now();
    std::vector<std::unique_ptr<TierEquilibrium>> eq;
    for (const BodyModel& b : m.bodies_) {
      TierEquilibriumDefinition d;
      d.body = b.body.get();
      d.host_material = b.host_material;
      d.host_fixed_nodes = b.host_fixed_nodes;
      d.tier = m.tier_;
      d.newton.tolerance = m.options_.tier_newton_tolerance;
      d.newton.step_limit = m.options_.tier_update_steps;
      try {
        eq.push_back(std::make_unique<TierEquilibrium>(d));
      } catch (const std::exception& ex) {
        throw std::runtime_error(m.source_ + ": mesh " +
                                 m.meshes_[b.body->host_index()].loaded->id + ": " + ex.what());
      }
    }
    tier_ = std::make_unique<TierWorker>(
        std::move(eq), m.options_.tier_worker_thread,
        std::max<int>(1, static_cast<int>(m.tools_.size())) *
            m.options_.max_contact_nodes_per_tool);
    tier_s_ = seconds_since(t0);
  }
  // Sliding rows: the step workspace and the inverse of their block at load, not in step 1.
  if (m.num_sliding_ > 0) {
    const auto t0 = Clock::now();
    reserve_workspace(m, std::max<int>(1, static_cast<int>(m.tools_.size())));
    sliding_s_ += seconds_since(t0);
  }
}

void State::reserve_workspace(const Model& m, int tools) {
  const int max_contact = std::max(1, tools * m.options_.max_contact_nodes_per_tool);
  const int max_rows = m.num_sliding_ + max_contact;
  if (max_rows <= lcp_.capacity()) return;
  lcp_.reserve(max_rows);
  w_.setZero(max_rows, max_rows);
  delta_.setZero(max_rows);
  lambda_.setZero(max_rows);
  warm_.assign(max_rows, 0);
  rows_.reserve(max_contact);
  // The sliding rows' block of W is constant: W_A (host, coupled) + W_B (embedded), per body.
  for (const auto& b : m.bodies_) {
    const int o = b.sliding_offset, ns = b.body->sliding().size();
    if (ns == 0) continue;
    w_.block(o, o, ns, ns) = b.body->sliding().compliance();
    for (std::size_t i = 0; i < b.slides.size(); ++i) {
      const auto& sl = *b.slides[i];
      const int f = o + b.slide_first_row[i];
      w_.block(f, f, sl.size(), sl.size()) += sl.compliance();
      for (int k = 0; k < sl.size(); ++k) delta_[f + k] = -sl.pairs()[k].initial_gap_m;
    }
  }
  std::size_t surface = 0;
  for (const auto& b : m.bodies_) surface += b.rest_m.size();
  candidates_.reserve(2 * surface);  // tip and shaft queries may both list a node
  tool_rows_.reserve(surface);
  for (auto& b : bodies_) {
    b.force_slots.reserve(max_rows);
    b.forces_n.reserve(max_rows);
  }
  for (auto& list : missing_) list.reserve(max_rows);
  for (auto& l : tier_loads_) {
    l.slots.reserve(max_rows);
    l.forces_n.reserve(max_rows);
  }
  last_good_.resize(tools);
  for (auto& c : last_good_) c.nodes.reserve(m.options_.max_contact_nodes_per_tool);
  // The inverse of the constant sliding block, once (its size does not depend on the tools).
  if (m.num_sliding_ > 0 && !lcp_constant_block_) {
    lcp_constant_block_ = true;
    if (m.options_.sliding_inactive_set) lcp_.set_constant_block(w_, m.num_sliding_);
  }
}

void State::collect_rows(const Model& m, int tool, const ToolPose& pose, const Vec3& axis) {
  const ToolShape& shape = m.tools_[pose.tool];
  const Vec3 p0 = pose.tip_m, p1 = pose.tip_m + shape.shaft_length_m * axis;
  const bool shaft = shape.shaft_radius_m > 0.0 && shape.shaft_length_m > 0.0;
  const double margin = m.options_.candidate_margin * shape.tip_radius_m;
  tool_rows_.clear();
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi) {
    const auto& b = m.bodies_[bi];
    auto& bs = bodies_[bi];
    const long long stamp = ++stamp_counter_;
    candidates_.clear();
    const double reach = shape.tip_radius_m + b.max_penetration_m;
    b.grid.query(p0 - Vec3::Constant(reach), p0 + Vec3::Constant(reach), candidates_);
    if (shaft) {
      const double sreach = shape.shaft_radius_m + b.max_penetration_m;
      b.grid.query(p0.cwiseMin(p1) - Vec3::Constant(sreach),
                   p0.cwiseMax(p1) + Vec3::Constant(sreach), candidates_);
    }
    const auto& normals = b.body->contact_normals();
    const std::size_t first = tool_rows_.size();
    for (int s : candidates_) {
      if (bs.stamp[s] == stamp) continue;
      bs.stamp[s] = stamp;
      const Vec3& x = b.rest_m[s];
      const Vec3& n = normals[s];
      // Depth along the node's inward normal to the tip sphere, or to the shaft capsule.
      // A part whose centre is deeper than max_penetration below the node's patch does not
      // push it (bounded force when the tool jumps through the body).
      double height = height_above(x, n, p0);
      double depth = height <= b.max_penetration_m ? normal_line_depth(x, n, p0, shape.tip_radius_m)
                                                   : -std::numeric_limits<double>::infinity();
      bool by_shaft = false;
      if (shaft) {
        const Vec3 q = closest_on_segment(x, p0, p1);
        const double hs = height_above(x, n, q);
        const double ds = hs <= b.max_penetration_m
                              ? normal_line_depth(x, n, q, shape.shaft_radius_m)
                              : -std::numeric_limits<double>::infinity();
        if (ds > depth) {
          depth = ds;
          height = hs;
          by_shaft = true;
        }
      }
      if (!(depth > -margin)) continue;
      tool_rows_.push_back(Row{static_cast<int>(bi), s, tool, depth, height, by_shaft});
    }
    if (tool_rows_.size() == first) continue;
    // The tool pushes the surface it is least deep under (where it entered): drop candidates on
    // other sides of the body (a face the tip is far below, or one facing another way).
    // The entry is chosen among the tip's rows when there are any (the shaft crossing the
    // surface elsewhere must not hide what the tip pushes); shaft rows only need the same side.
    const Row* entry = nullptr;
    bool tip_rows = false;
    for (std::size_t k = first; k < tool_rows_.size(); ++k)
      tip_rows = tip_rows || !tool_rows_[k].shaft;
    for (std::size_t k = first; k < tool_rows_.size(); ++k) {
      const Row& r = tool_rows_[k];
      if (tip_rows && r.shaft) continue;
      if (!entry || r.height_m < entry->height_m ||
          (r.height_m == entry->height_m && deeper(r, *entry)))
        entry = &r;
    }
    const double limit = entry->height_m + shape.tip_radius_m;
    const Vec3 n_entry = normals[entry->slot];
    auto other_side = [&](const Row& r) {
      return (!r.shaft && r.height_m > limit) || normals[r.slot].dot(n_entry) < 0.5;
    };
    tool_rows_.erase(std::remove_if(tool_rows_.begin() + first, tool_rows_.end(), other_side),
                     tool_rows_.end());
  }
  // The deepest rows of this tool, deterministic order.
  const std::size_t keep =
      std::min<std::size_t>(tool_rows_.size(), m.options_.max_contact_nodes_per_tool);
  std::partial_sort(tool_rows_.begin(), tool_rows_.begin() + keep, tool_rows_.end(), deeper);
  for (std::size_t k = 0; k < keep; ++k) {
    const Row& r = tool_rows_[k];
    auto& bs = bodies_[r.body];
    const int existing = bs.row_of_slot[r.slot];
    if (existing >= 0) {
      // Two tools on one node: one row (same normal); the deeper tool carries it.
      if (r.depth_m > rows_[existing].depth_m) rows_[existing] = r;
      continue;
    }
    bs.row_of_slot[r.slot] = static_cast<int>(rows_.size());
    rows_.push_back(r);
  }
}

void State::step(const Model& m, const std::vector<ToolPose>& poses,
                 std::vector<ToolContact>& contacts, StepStats& stats) {
  const auto t0 = Clock::now();
  const int nt = static_cast<int>(poses.size());
  // Inputs first: nothing changes on a bad pose.
  for (int t = 0; t < nt; ++t) {
    const auto& p = poses[t];
    if (!p.tip_m.allFinite() || !p.axis.allFinite()) {
      throw std::invalid_argument("Simulation::step: tool " + std::to_string(t) +
                                  " pose is not finite");
    }
    if (p.axis.norm() < 1e-12)
      throw std::invalid_argument("Simulation::step: tool " + std::to_string(t) + " axis is zero");
    if (p.tool < 0 || p.tool >= static_cast<int>(m.tools_.size())) {
      if (!m.tools_.empty() || p.tool != 0) {
        throw std::invalid_argument("Simulation::step: tool " + std::to_string(t) +
                                    " refers to scene tool " + std::to_string(p.tool) + " of " +
                                    std::to_string(m.tools_.size()));
      }
    }
  }
  reserve_workspace(m, nt);
  stats.tier_updated = false;
  stats.tier_update_us = 0.0;
  stats.inverted_elements = 0;
  if (tier_) {
    tier_->begin_step();
    for (std::size_t bi = 0; bi < bodies_.size(); ++bi)
      stats.inverted_elements += tier_->linearization(static_cast<int>(bi)).inverted_elements;
  }
  if (static_cast<int>(contacts.size()) != nt) contacts.resize(nt);
  rows_.clear();
  if (!m.tools_.empty()) {
    for (int t = 0; t < nt; ++t) collect_rows(m, t, poses[t], poses[t].axis.normalized());
  }
  const int nc = static_cast<int>(rows_.size());
  const int ns = m.num_sliding_;  // sliding rows first (constant block of W), then contact rows
  const int n = ns + nc;
  for (const Row& r : rows_) bodies_[r.body].row_of_slot[r.slot] = -1;

  // Coupled compliance columns of new contact nodes (cached after the first touch).
  for (auto& list : missing_) list.clear();
  for (const Row& r : rows_)
    if (!bodies_[r.body].columns->has(r.slot)) missing_[r.body].push_back(r.slot);
  stats.columns_computed = 0;
  for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
    if (missing_[bi].empty()) continue;
    const std::size_t before = bodies_[bi].columns->size();
    bodies_[bi].columns->ensure(missing_[bi]);
    stats.columns_computed += static_cast<int>(bodies_[bi].columns->size() - before);
  }

  // Delassus operator on the contact rows: W_rs = n_r^T L(r, s) n_s (coupled compliance, unit
  // m/N); against the sliding rows of the same body, W_kr = -J_A,k L[:, r] n_r (the tool
  // pushes along -n_r, the row measures the inward motion of the node). COROTATIONAL and
  // NONLINEAR: L warped by the nodes' rotations (n -> R^T n) and the depth taken at the offset
  // u0 of the latest equilibrium (tier_equilibrium.hpp).
  for (int r = 0; r < nc; ++r) {
    const Row& a = rows_[r];
    const int i = ns + r;
    const auto& body_a = *m.bodies_[a.body].body;
    const TierLinearization* lin = tier_ ? &tier_->linearization(a.body) : nullptr;
    const auto& normals_a = lin ? lin->warped_normal : body_a.contact_normals();
    const Vec3& na = normals_a[a.slot];
    delta_[i] = a.depth_m;
    if (lin) delta_[i] += body_a.contact_normals()[a.slot].dot(lin->offset_m[a.slot]);
    for (int s = r; s < nc; ++s) {
      const Row& c = rows_[s];
      double v = 0.0;
      if (c.body == a.body) {
        const Vec3& nc_ = normals_a[c.slot];
        const auto& cols = *bodies_[a.body].columns;
        v = 0.5 * (na.dot(cols.block(a.slot, c.slot) * nc_) +
                   nc_.dot(cols.block(c.slot, a.slot) * na));
      }
      w_(i, ns + s) = v;
      w_(ns + s, i) = v;
    }
    if (ns == 0) continue;
    w_.col(i).head(ns).setZero();
    const int rows_a = body_a.sliding().size();
    if (rows_a > 0) {
      const int o = m.bodies_[a.body].sliding_offset;
      const Vec3 push = -na;
      w_.col(i).segment(o, rows_a).noalias() = bodies_[a.body].columns->sliding_block(a.slot) * push;
    }
    w_.row(i).head(ns) = w_.col(i).head(ns).transpose();
  }
  // Warm start: the sliding rows active in the last good step, the contact rows that penetrate.
  for (int k = 0; k < ns; ++k) warm_[k] = sliding_active_[k];
  for (int r = 0; r < nc; ++r) warm_[ns + r] = delta_[ns + r] > 0.0 ? 1 : 0;
  const int max_iterations =
      m.options_.lcp_max_iterations + m.options_.lcp_iterations_per_sliding_row * ns;
  // The sliding block of W never changes: its active (or inactive) set and factor carry over
  // between steps; with m.options_.sliding_inactive_set its inverse was computed at load.
  LcpOptions lcp_options;
  lcp_options.tolerance = m.options_.lcp_tolerance;
  lcp_options.max_iterations = max_iterations;
  lcp_options.path = !m.options_.sliding_inactive_set        ? LcpPath::reference
                     : m.options_.sliding_inactive_set_always ? LcpPath::inactive_set
                                                              : LcpPath::automatic;
  const LcpResult lcp = lcp_.solve(LcpProblem{&w_, &delta_, n, ns, &warm_}, lcp_options, lambda_);

  stats.contact_rows = nc;
  stats.sliding_rows = ns;
  stats.converged = lcp.converged;
  if (!lcp.converged) {
    // Keep the last good answer (contact and sliding forces), say that this step did not
    // converge.
    for (int t = 0; t < nt; ++t) {
      contacts[t] = last_good_[t];
      contacts[t].converged = false;
      contacts[t].iterations = lcp.iterations;
    }
    stats.solve_us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
    return;
  }
  stats.sliding_active = 0;
  for (int k = 0; k < ns; ++k) {
    sliding_active_[k] = lambda_[k] > 0.0 ? 1 : 0;
    stats.sliding_active += sliding_active_[k];
  }
  for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi) {
    const auto& b = m.bodies_[bi];
    auto& bs = bodies_[bi];
    bs.force_slots.clear();
    bs.forces_n.clear();
    const int rows_b = b.body->sliding().size();
    if (rows_b > 0) bs.sliding_lambda = lambda_.segment(b.sliding_offset, rows_b);
  }
  for (int r = 0; r < nc; ++r) {
    const double l = lambda_[ns + r];
    if (l <= 0.0) continue;
    auto& bs = bodies_[rows_[r].body];
    bs.force_slots.push_back(rows_[r].slot);
    bs.forces_n.push_back(-l * m.bodies_[rows_[r].body].body->contact_normals()[rows_[r].slot]);  // inward on the tissue
  }

  for (int t = 0; t < nt; ++t) {
    ToolContact& c = contacts[t];
    c.force_n.setZero();
    c.stiffness_n_per_m.setZero();
    c.normal.setZero();
    c.reference_tip_m = poses[t].tip_m;
    c.converged = true;
    c.iterations = lcp.iterations;
    c.nodes.clear();
    c.mesh = -1;
    // Main body: the one carrying most of this tool's force.
    int main_body = -1;
    double best = 0.0;
    for (std::size_t bi = 0; bi < m.bodies_.size(); ++bi) {
      double sum = 0.0;
      for (int r = 0; r < nc; ++r)
        if (rows_[r].tool == t && rows_[r].body == static_cast<int>(bi)) sum += lambda_[ns + r];
      if (sum > best) {
        best = sum;
        main_body = static_cast<int>(bi);
      }
    }
    for (int r = 0; r < nc; ++r) {
      if (rows_[r].tool != t || !(lambda_[ns + r] > 0.0)) continue;
      const auto& body = *m.bodies_[rows_[r].body].body;
      c.force_n += lambda_[ns + r] * body.contact_normals()[rows_[r].slot];
      if (rows_[r].body == main_body) c.nodes.push_back(body.contact_nodes()[rows_[r].slot]);
    }
    // Contact stiffness dF/dx = -N (W_AA^-1)_cc N^T over this tool's active rows (flat-contact
    // linearization: the depth changes by -n.dx per row; active sliding rows stay active, so
    // the contact block of the inverse of the whole active block is the stiffness).
    c.stiffness_n_per_m = lcp_.contact_stiffness(ns, [&](int row) -> const Vec3* {
      const Row& r = rows_[row - ns];
      return r.tool == t ? &m.bodies_[r.body].body->contact_normals()[r.slot] : nullptr;
    });
    c.in_contact = main_body >= 0;
    if (c.in_contact) {
      c.mesh = m.bodies_[main_body].body->host_index();
      c.validity_radius_m = m.bodies_[main_body].validity_radius_m;
      const double f = c.force_n.norm();
      if (f > 0.0) c.normal = c.force_n / f;
    } else {
      c.validity_radius_m = 0.0;
    }
    if (!c.force_n.allFinite() || !c.stiffness_n_per_m.allFinite()) {
      throw std::runtime_error("Simulation::step: non-finite contact result for tool " +
                               std::to_string(t));
    }
    last_good_[t] = c;
  }
  // The tier's equilibrium follows these forces (worker thread; or now, deterministic).
  if (tier_) {
    for (std::size_t bi = 0; bi < bodies_.size(); ++bi) {
      tier_loads_[bi].slots = bodies_[bi].force_slots;
      tier_loads_[bi].forces_n = bodies_[bi].forces_n;
      tier_loads_[bi].linearization = tier_->linearization(static_cast<int>(bi)).count;
    }
    const auto u0 = Clock::now();
    stats.tier_updated = tier_->post(tier_loads_);
    if (stats.tier_updated) {
      stats.tier_update_us = std::chrono::duration<double, std::micro>(Clock::now() - u0).count();
      stats.inverted_elements = 0;  // of the equilibrium just made
      for (std::size_t bi = 0; bi < bodies_.size(); ++bi)
        stats.inverted_elements += tier_->linearization(static_cast<int>(bi)).inverted_elements;
    }
  }
  stats.solve_us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
}

void Model::host_field(const BodyModel& b, const std::vector<int>& slots,
                       const std::vector<Vec3>& forces_n, const Eigen::VectorXd& sliding_lambda_n,
                       const Eigen::VectorXd& nodal_forces_n, const ContactColumns* columns,
                       Eigen::VectorXd& u_host_m, fem::SolveWorkspace* ws) const {
  const bool sliding_force = sliding_lambda_n.size() > 0 && sliding_lambda_n.maxCoeff() > 0.0;
  const int n3 = 3 * static_cast<int>(b.body->host().num_vertices());
  if (nodal_forces_n.size() != 0 && nodal_forces_n.size() != n3) {
    throw std::invalid_argument(source_ + ": nodal forces of host " +
                                meshes_[b.body->host_index()].loaded->id + ": " +
                                std::to_string(nodal_forces_n.size()) + " values for " +
                                std::to_string(n3) + " dofs");
  }
  if (!sliding_force && nodal_forces_n.size() == 0) {
    if (columns == nullptr || !columns->full_field(slots, forces_n, u_host_m))
      b.body->host_displacement(slots, forces_n, u_host_m, ws);
    return;
  }
  // Contact forces at their nodes, the sliding forces J_A^T lambda on S', other nodal forces.
  Eigen::VectorXd f = nodal_forces_n.size() == n3 ? nodal_forces_n : Eigen::VectorXd::Zero(n3);
  for (std::size_t k = 0; k < slots.size(); ++k)
    f.segment<3>(3 * b.body->contact_nodes()[slots[k]]) += forces_n[k];
  const auto& rows = b.body->sliding().rows();
  for (std::size_t k = 0; k < rows.size() && sliding_force; ++k) {
    const double l = sliding_lambda_n[static_cast<int>(k)];
    if (l == 0.0) continue;
    for (int a = 0; a < 3; ++a)
      f.segment<3>(3 * rows[k].nodes[a]) += (l * rows[k].weights[a]) * rows[k].normal;
  }
  b.body->coupled_displacement(f, u_host_m);
}

void Model::mesh_field(const MeshEntry& e, const Eigen::VectorXd& sliding_lambda_n,
                       const Eigen::VectorXd& u_host_m, Eigen::VectorXd& u_m) const {
  const BodyModel& b = bodies_[e.body];
  if (e.slide >= 0) {
    const auto& sl = *b.slides[e.slide];
    const Eigen::VectorXd lambda =
        sliding_lambda_n.size() > 0
            ? Eigen::VectorXd(sliding_lambda_n.segment(b.slide_first_row[e.slide], sl.size()))
            : Eigen::VectorXd(Eigen::VectorXd::Zero(sl.size()));
    sl.displacement(lambda, u_m);
    return;
  }
  if (e.tie < 0) {
    u_m = u_host_m;
    return;
  }
  b.body->ties().at(static_cast<std::size_t>(e.tie)).displacement(u_host_m, u_m);
}

void Model::tier_mesh_field(const MeshEntry& e, const Eigen::VectorXd& stacked_u_m,
                            Eigen::VectorXd& u_m) const {
  const CoupledBody& body = *bodies_[e.body].body;
  Eigen::Index first = 0;
  for (int t = 0; t < e.tie; ++t)
    first += 3 * static_cast<Eigen::Index>(body.ties()[t].geometry().num_vertices());
  if (e.tie >= 0) first += 3 * static_cast<Eigen::Index>(body.host().num_vertices());
  const Eigen::Index n = 3 * static_cast<Eigen::Index>(e.loaded->mesh.num_vertices());
  if (stacked_u_m.size() < first + n) {
    throw std::invalid_argument(source_ + ": tier field of mesh " + e.loaded->id + " has " +
                                std::to_string(stacked_u_m.size()) + " values, needs " +
                                std::to_string(first + n));
  }
  u_m = stacked_u_m.segment(first, n);
}

namespace {

void SimulationImpl::displacements(int m, Eigen::VectorXd& u_m) const {
  const MeshEntry& e = model_->entry(m);
  if (e.body < 0) {
    u_m.setZero(3 * static_cast<int>(e.loaded->mesh.num_vertices()));
    return;
  }
  if (state_->tier_) {  // the tier's own field: the latest equilibrium
    model_->tier_mesh_field(e, state_->tier_->linearization(e.body).u_m, u_m);
    return;
  }
  const BodyState& bs = state_->bodies_[e.body];
  if (e.slide >= 0) {  // B's field depends on the sliding forces only
    model_->mesh_field(e, bs.sliding_lambda, Eigen::VectorXd(), u_m);
    return;
  }
  if (e.tie < 0) {
    state_->host_field(*model_, e.body, u_m);
    return;
  }
  Eigen::VectorXd u_host;
  state_->host_field(*model_, e.body, u_host);
  model_->mesh_field(e, bs.sliding_lambda, u_host, u_m);
}

void SimulationImpl::snapshot(FieldSnapshot& s) const {
  const auto& bodies = state_->bodies_;
  s.bodies.resize(bodies.size());
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    auto& out = s.bodies[i];
    out.slots = bodies[i].force_slots;
    out.forces_n = bodies[i].forces_n;
    out.sliding_lambda_n = bodies[i].sliding_lambda;
    out.nodal_forces_n.resize(0);
    if (state_->tier_) {
      out.tier_u_m = state_->tier_->linearization(static_cast<int>(i)).u_m;
    } else {
      out.tier_u_m.resize(0);
    }
    out.host_done = false;
  }
}

void SimulationImpl::displacements(FieldSnapshot& s, int m, Eigen::VectorXd& u_m) const {
  const MeshEntry& e = model_->entry(m);
  if (e.body < 0) {
    u_m.setZero(3 * static_cast<int>(e.loaded->mesh.num_vertices()));
    return;
  }
  if (s.bodies.size() != model_->bodies_.size()) {
    throw std::invalid_argument(model_->source_ + ": field snapshot has " +
                                std::to_string(s.bodies.size()) + " bodies, the model " +
                                std::to_string(model_->bodies_.size()));
  }
  auto& sb = s.bodies[e.body];
  if (sb.tier_u_m.size() > 0) {
    model_->tier_mesh_field(e, sb.tier_u_m, u_m);
    return;
  }
  if (e.slide < 0 && !sb.host_done) {
    // Never the step's column cache: this may run on another thread than step(); the
    // snapshot's own solve scratch, so the step's solves and this one share no lock.
    if (!sb.workspace) sb.workspace = std::make_shared<fem::SolveWorkspace>();
    model_->host_field(model_->bodies_[e.body], sb.slots, sb.forces_n, sb.sliding_lambda_n,
                       sb.nodal_forces_n, nullptr, sb.u_host_m, sb.workspace.get());
    sb.host_done = true;
  }
  model_->mesh_field(e, sb.sliding_lambda_n, sb.u_host_m, u_m);
}

void SimulationImpl::sliding_pairs(int m, std::vector<SlidingPairState>& pairs) const {
  pairs.clear();
  const MeshEntry& e = model_->entry(m);
  if (e.slide < 0) return;
  const BodyModel& b = model_->bodies_[e.body];
  const auto& lambda = state_->bodies_[e.body].sliding_lambda;
  const auto& sl = *b.slides[e.slide];
  const int first = b.slide_first_row[e.slide];
  for (int k = 0; k < sl.size(); ++k) {
    const auto& p = sl.pairs()[k];
    pairs.push_back(SlidingPairState{p.embedded_node, p.host_nodes, p.weights, p.normal,
                                     p.initial_gap_m, lambda[first + k]});
  }
}

double SimulationImpl::sliding_penetration_m() const {
  double worst = 0.0;
  Eigen::VectorXd u_host, u_emb;
  for (std::size_t bi = 0; bi < model_->bodies_.size(); ++bi) {
    const BodyModel& b = model_->bodies_[bi];
    if (b.slides.empty()) continue;
    const auto& lambda = state_->bodies_[bi].sliding_lambda;
    state_->host_field(*model_, static_cast<int>(bi), u_host);
    for (std::size_t i = 0; i < b.slides.size(); ++i) {
      const auto& sl = *b.slides[i];
      sl.displacement(lambda.segment(b.slide_first_row[i], sl.size()), u_emb);
      for (int k = 0; k < sl.size(); ++k) worst = std::max(worst, -sl.gap(k, u_host, u_emb));
    }
  }
  return worst;
}

double SimulationImpl::tie_residual_m() const {
  double worst = 0.0;
  Eigen::VectorXd u_host, u_emb;
  for (std::size_t bi = 0; bi < model_->bodies_.size(); ++bi) {
    const BodyModel& b = model_->bodies_[bi];
    if (b.body->ties().empty()) continue;
    state_->host_field(*model_, static_cast<int>(bi), u_host);
    for (const auto& tie : b.body->ties()) {
      if (state_->tier_) {
        model_->tier_mesh_field(model_->entry(tie.mesh()),
                                state_->tier_->linearization(static_cast<int>(bi)).u_m, u_emb);
      } else {
        tie.displacement(u_host, u_emb);
      }
      worst = std::max(worst, tie.residual(u_host, u_emb));
    }
  }
  return worst;
}

}  // namespace

std::unique_ptr<Simulation> Simulation::build(const scene::Model& model,
                                              const SimulationOptions& options) {
  return std::make_unique<SimulationImpl>(model, options);
}

std::unique_ptr<Simulation> Simulation::from_model(std::shared_ptr<const Model> model) {
  if (!model) throw std::invalid_argument("Simulation::from_model: no model");
  return std::make_unique<SimulationImpl>(std::move(model));
}

}  // namespace neurosim::interaction
