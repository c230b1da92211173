// Simulation: scene -> coupled bodies (exact tie, coupled_body.hpp; frictionless sliding pairs,
// sliding_coupling.hpp) -> per-step LCP of the tool contact rows and the sliding rows together.
#include "server/interaction/simulation.hpp"
#include "server/interaction/simulation_state.hpp"

#include "common/clock.hpp"
#include "server/fusion/carve.hpp"
#include "server/fusion/coupling_map.hpp"
#include "server/fusion/exposure.hpp"
#include "server/fusion/inclusion.hpp"
#include "server/fusion/triangle_surface.hpp"
#include "server/interaction/contact_columns.hpp"
#include "server/interaction/field_columns.hpp"
#include "server/interaction/contact_lcp.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/sliding_coupling.hpp"
#include "server/interaction/tier_worker.hpp"
#include "server/interaction/tool_geometry.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

namespace {

using common::Clock;
using common::seconds_since;

// An embedded surface node closer than this many host mean edges to the host's surface counts
// as inside it (see the exposure check in Model::Model).
constexpr double kExposureToleranceEdges = 0.1;

}  // namespace

std::shared_ptr<const Model> build_model(const scene::Model& model,
                                         const SimulationOptions& options) {
  return std::make_shared<const Model>(model, options);
}
void StateDeleter::operator()(State* state) const { delete state; }
StatePtr make_state(const Model& model) { return StatePtr(new State(model)); }
void step(const Model& model, State& state, const std::vector<ToolPose>& poses,
          std::vector<ToolContact>& contacts, StepStats& stats) {
  state.step(model, poses, state.time_s() + model.step_period_s_, contacts, stats);
}
void step_at(const Model& model, State& state, double time_s, const std::vector<ToolPose>& poses,
             std::vector<ToolContact>& contacts, StepStats& stats) {
  state.step(model, poses, time_s, contacts, stats);
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
  const RigidObstacle* rigid_obstacle() const override { return model_->rigid_.get(); }
  double proxy_reach_m() const override {
    return model_->rigid_ ? model_->proxy_options_.reach_m : 0.0;
  }
  void reset_station(int station) override { state_->reset_station(station); }

  void step(const std::vector<ToolPose>& poses, std::vector<ToolContact>& contacts,
            StepStats& stats) override {
    interaction::step(*model_, *state_, poses, contacts, stats);
  }
  void step_at(double time_s, const std::vector<ToolPose>& poses,
               std::vector<ToolContact>& contacts, StepStats& stats) override {
    interaction::step_at(*model_, *state_, time_s, poses, contacts, stats);
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
  std::uint64_t shared_workspace_uses() const override {
    std::uint64_t uses = 0;
    for (const BodyModel& b : model_->bodies_) {
      uses += b.body->host_solver().shared_workspace_uses();
      for (const auto& tie : b.body->ties()) uses += tie.shared_workspace_uses();
      for (const auto& sl : b.slides) uses += sl->shared_workspace_uses();
    }
    return uses;
  }
  void snapshot(FieldSnapshot& s) const override;
  void displacements(FieldSnapshot& s, int mesh, Eigen::VectorXd& u_m) const override;
  int body_index(int m) const override { return model_->entry(m).body; }
  IterativeReport iterative_report(int m) const override {
    const int b = model_->entry(m).body;
    if (b < 0 || !state_->bodies_[static_cast<std::size_t>(b)].columns) return {};
    return state_->bodies_[static_cast<std::size_t>(b)].columns->iterative_report();
  }
  std::uint64_t columns_not_ready() const override { return state_->columns_not_ready_; }
  std::uint64_t steps_with_rows_dropped() const override { return state_->steps_with_rows_dropped_; }
  std::uint64_t steps_not_converged() const override { return state_->steps_not_converged_; }
  std::uint64_t columns_solved_ahead() const override {
    return state_->column_worker_ ? state_->column_worker_->columns_solved() : 0;
  }
  bool wait_columns_ready(double timeout_s) const override {
    return state_->column_worker_ && state_->column_worker_->wait_ready(timeout_s);
  }
  ColumnCacheStats column_cache(int m) const override {
    const int b = model_->entry(m).body;
    if (b < 0) return {};
    const BodyState& bs = state_->bodies_[static_cast<std::size_t>(b)];
    return ColumnCacheStats{bs.columns->size(), bs.capacity_slots, bs.columns->bytes_per_slot(),
                            bs.columns->evicted(),
                            state_->column_worker_ ? state_->column_worker_->raised_capacity(b) : 0};
  }
  void pause_column_worker(bool paused) override {
    if (state_->column_worker_) state_->column_worker_->set_paused(paused);
  }
  scene::Tier tier() const override { return model_->tier_; }
  double tier_update_rate_hz() const override {
    return state_->tier_ ? state_->tier_->rate_hz() : 0.0;
  }
  TierUpdateTotals tier_update_totals() const override {
    if (!state_->tier_) return {};
    const TierWorker::Totals t = state_->tier_->totals();
    return {t.updates, t.busy_s};
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
      !std::isfinite(options_.max_penetration_m) || !(options_.candidate_margin >= 0.0) ||
      !(options_.contact_row_compliance >= 0.0) || !(options_.contact_row_compliance < 1.0) ||
      !(options_.contact_spread >= 0.0) || !(options_.contact_spread <= 4.0) ||
      options_.contact_geometry_iterations < 1) {
    throw std::invalid_argument(source_ + ": invalid SimulationOptions");
  }
  if (options_.contact_near_field && !(options_.contact_spread > 0.0)) {
    throw std::invalid_argument(source_ +
                                ": SimulationOptions.contact_near_field needs contact_spread > 0 "
                                "(the near field is the part the spread load does not carry)");
  }
  if (options_.column_worker_nice < 0 || options_.column_worker_nice > 19) {
    throw std::invalid_argument(source_ + ": SimulationOptions.column_worker_nice must be in 0..19");
  }
  if (!(options_.column_horizon_s >= 0.0) || !(options_.column_max_tool_speed_m_per_s >= 0.0) ||
      !std::isfinite(options_.column_horizon_s * options_.column_max_tool_speed_m_per_s) ||
      !(options_.column_preload_budget_mb >= 0.0) || !std::isfinite(options_.column_preload_budget_mb)) {
    throw std::invalid_argument(source_ +
                                ": invalid SimulationOptions.column_horizon_s, "
                                "column_max_tool_speed_m_per_s or column_preload_budget_mb "
                                "(finite, >= 0)");
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
  step_period_s_ = 1.0 / model.rates.step_hz;

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
    std::vector<mesh::Tri> cut;  // S': covered on the host (never contactable)
  };
  std::vector<PendingTie> pending(meshes_.size());
  std::vector<std::vector<char>> exposed(meshes_.size());  // per embedded mesh: contactable outside
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
    // B's surface nodes outside A (nodes within a fraction of the host's mean edge of its
    // surface count as inside: two meshes meshed separately never share a boundary exactly).
    // Only the nodes inside are tied: an exposed node's closest point of S' may lie far away
    // (at the rim where B leaves A), so it stays free and follows B's interior.
    fusion::ExposureOptions eo;
    eo.tolerance_m = kExposureToleranceEdges * host.mesh.mean_edge_length();
    fusion::Exposure ex;
    try {
      ex = fusion::embedded_outside_host(host.mesh, emb.mesh, eo);
    } catch (const std::exception& e) {
      throw std::runtime_error(what + ": " + e.what());
    }
    // Tool contact with B's exposed part is built for the LINEAR and NONLINEAR tiers with a TIE
    // coupling (method EXACT; in LINEAR also ITERATIVE, the paper's baseline iterating G in the
    // same coupled solves): B's exposed surface gets contact slots (CoupledBody::expose_tie;
    // in NONLINEAR they are B's nodes in the tier's stacked equilibrium, TierEquilibrium). The
    // tissue may relax in both: in LINEAR the body's hereditary integral lives on its contact
    // slots (ViscoelasticHistory, with the host's kernel), B's exposed slots among them; in
    // NONLINEAR each mesh of the stacked equilibrium relaxes with its own kernel (quasi-linear
    // viscoelasticity, TierEquilibrium), the forces on B's exposed slots loading B's dofs.
    // With a SLIDING coupling (LINEAR only, elastic: both refused above and below) B's exposed
    // surface gets contact slots whose columns are B's own compliance (CoupledBody::expose_slide),
    // reaching A through the sliding rows in the same LCP; the rows are found on the rest surface
    // only (the deformed positions would need the sliding forces' displacement of B).
    // Anything else would leave the exposed part without contact rows (the tool would pass
    // through it without force), so it is refused, naming what is not built.
    const bool tool_touch = model.effects.tool_contact && !model.tools.empty();
    std::string not_built;
    if (tier_ != scene::Tier::kLinear && tier_ != scene::Tier::kNonlinear)
      not_built = std::string("in effects.tier ") + scene::tier_name(tier_) +
                  " (built in the LINEAR and NONLINEAR tiers only)";
    else if (sliding[m] && options_.contact_geometry_iterations > 1)
      not_built =
          "with a SLIDING coupling and SimulationOptions.contact_geometry_iterations > 1 "
          "(built on the rest surface, contact_geometry_iterations = 1, only)";
    if (ex.nodes_outside > 0 && tool_touch && !not_built.empty()) {
      char buf[320];
      std::snprintf(buf, sizeof buf,
                    "%d of its %d surface nodes lie outside host %s (farthest: node %d, "
                    "%.2f mm outside; tolerance %.2f mm = %.2f x the host's mean edge)",
                    ex.nodes_outside, ex.surface_nodes, host.id.c_str(), ex.farthest_node,
                    1e3 * ex.max_distance_m, 1e3 * eo.tolerance_m, kExposureToleranceEdges);
      throw std::runtime_error(
          source_ + ": embedded mesh " + emb.id + ": " + buf +
          "; tool contact with an exposed embedded mesh is not implemented " + not_built +
          ": use a TIE coupling in the LINEAR or NONLINEAR tier or a SLIDING one in LINEAR with "
          "the rows on the rest surface, place the embedded mesh inside its host, or remove the "
          "tools or effects.tool_contact");
    }
    if (ex.nodes_outside > 0 && tool_touch) exposed[m] = ex.outside;
    setup_.fusion_s += seconds_since(t0);
    PendingTie& p = pending[m];
    for (std::size_t k = 0; k < map.embedded_nodes.size(); ++k) {
      const int v = map.embedded_nodes[k];
      if (ex.outside.at(v)) continue;
      const auto& sp = map.embedded_on_boundary[k];
      const auto& tri = boundary.triangles.at(sp.triangle);
      p.embedded_nodes.push_back(v);
      p.tris.push_back({tri[0], tri[1], tri[2]});
      p.weights.push_back(sp.weights);
      p.points_m.push_back(sp.point_m);
      p.max_distance_m = std::max(p.max_distance_m, sp.distance_m);
    }
    if (p.embedded_nodes.empty())
      throw std::runtime_error(what + ": every surface node of " + emb.id +
                               " lies outside the host: nothing to tie");
    setup_.exposed_nodes += ex.nodes_outside;
    p.cut = boundary.triangles;
    if (options_.carve_host) {
      const auto inside = fusion::tets_inside(host.mesh, boundary);
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
      fem::SolverOptions solver_options;
      solver_options.factor_cache_dir = options_.compliance_cache_dir;
      b.body = std::make_unique<CoupledBody>(static_cast<int>(m), lm.mesh, lm.material,
                                             lm.fixed_nodes, solver_options);
    } catch (const std::exception& ex) {
      throw std::runtime_error(source_ + ": mesh " + lm.id + ": " + ex.what());
    }
    setup_.factor_s += b.body->timing().factor_s;
    if (b.body->host_solver().factor_info().from_cache) ++setup_.factor_cache_hits;
    setup_.factor_bytes += static_cast<double>(b.body->host_solver().factor_info().factor_bytes);
    b.host_material = lm.material;
    b.host_fixed_nodes = lm.fixed_nodes;
    // LINEAR: the body relaxes with its host's kernel (a tied mesh with another one: compile()
    // warns). NONLINEAR: each mesh with its own, quasi-linear viscoelasticity in the tier's
    // equilibrium (TierEquilibrium; it refuses what it does not implement, naming the mesh).
    if (!lm.material.viscoelastic.empty()) {
      const std::string what = source_ + ": mesh " + lm.id + ": material.viscoelastic";
      if (tier_ == scene::Tier::kCorotational)
        throw std::runtime_error(what + ": the COROTATIONAL tier is elastic in this build "
                                 "(viscoelastic terms run in the LINEAR and NONLINEAR tiers; "
                                 "remove them or use --tier linear or --tier nonlinear)");
      if (tier_ == scene::Tier::kLinear) {
        b.creep = fem::creep_spectrum(lm.material.viscoelastic);
        viscoelastic_ = true;
      }
    }
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
    // S' is under B: the host's faces there (its carved cavity or groove) have no contact rows.
    body.body->cover_faces(p.cut);
    if (sliding[m]) {
      // Frictionless unilateral pairs: B's surface node, its closest point on S', B's normal.
      const std::string what =
          source_ + ": SLIDING coupling " + meshes_[h].loaded->id + " / " + emb.id;
      if (!body.creep.terms.empty() || !emb.material.viscoelastic.empty())
        throw std::runtime_error(what + ": viscoelastic terms with a SLIDING coupling are not "
                                 "implemented (the sliding forces have no history); use TIE or "
                                 "remove material.viscoelastic");
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
        // The tool on B's exposed part: slots with B's own columns (CoupledBody::expose_slide).
        if (!exposed[m].empty())
          body.body->expose_slide(static_cast<int>(body.slides.size()) - 1, *body.slides.back(),
                                  first, exposed[m]);
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
    if (!exposed[m].empty()) body.body->expose_tie(meshes_[m].tie, exposed[m]);
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
    // Contact geometry: the contactable surface triangles on a grid, rest positions per slot.
    // The host's, and an exposed tied mesh's (CoupledBody::contact_mesh: one vertex numbering).
    const auto& host = b.body->contact_mesh();
    for (int v : b.body->contact_nodes()) b.rest_m.push_back(host.vertices()[v]);
    std::vector<int> slot_of(host.num_vertices(), -1);
    for (std::size_t v = 0; v < slot_of.size(); ++v) slot_of[v] = b.body->contact_slot(static_cast<int>(v));
    b.surface = ContactSurface(ContactSurfaceDefinition{&host, &slot_of,
                                                        &b.body->contact_fixed_nodes(),
                                                        &b.body->contact_excluded_faces()});
    Vec3 lo, hi;
    b.body->host().bounds(lo, hi);
    b.max_penetration_m =
        options_.max_penetration_m > 0.0 ? options_.max_penetration_m : 0.45 * (hi - lo).minCoeff();
    b.behind_reach_m = std::min(b.max_penetration_m, 3.0 * b.surface.mean_edge_m());
  }

  if (model.effects.tool_contact) {
    for (const auto& tool : model.tools)
      tools_.push_back(ToolShape{tool.tip_radius_m, tool.shaft_radius_m, tool.shaft_length_m});
  }
  if (!tools_.empty() && !model.rigid.empty()) {
    rigid_ = RigidObstacle::build(model.rigid);
    // The proxy's planes must cover the fastest tool's travel in one step (with room: 1.5 x).
    for (const auto& tool : model.tools)
      proxy_options_.reach_m =
          std::max(proxy_options_.reach_m, 1.5 * tool.max_speed_m_per_s / model.rates.step_hz);
    proxy_options_.max_reach_m = std::max(proxy_options_.max_reach_m, proxy_options_.reach_m);
  }
  for (const auto& r : model.rigid)
    openings_.insert(openings_.end(), r.openings.begin(), r.openings.end());
  setup_.sliding_rows = num_sliding_;
  setup_.total_s = seconds_since(t_start);
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
  b.body->add_contact_loads(slots, forces_n, f, ws);
  const auto& rows = b.body->sliding().rows();
  for (std::size_t k = 0; k < rows.size() && sliding_force; ++k) {
    const double l = sliding_lambda_n[static_cast<int>(k)];
    if (l == 0.0) continue;
    for (int a = 0; a < 3; ++a)
      f.segment<3>(3 * rows[k].nodes[a]) += (l * rows[k].weights[a]) * rows[k].normal;
  }
  b.body->coupled_displacement(f, u_host_m, ws);
}

void Model::mesh_field(const MeshEntry& e, const Eigen::VectorXd& sliding_lambda_n,
                       const Eigen::VectorXd& u_host_m, Eigen::VectorXd& u_m,
                       fem::SolveWorkspace* ws, const std::vector<int>* slots,
                       const std::vector<Vec3>* forces_n) const {
  const BodyModel& b = bodies_[e.body];
  if (e.slide >= 0) {
    const auto& sl = *b.slides[e.slide];
    const Eigen::VectorXd lambda =
        sliding_lambda_n.size() > 0
            ? Eigen::VectorXd(sliding_lambda_n.segment(b.slide_first_row[e.slide], sl.size()))
            : Eigen::VectorXd(Eigen::VectorXd::Zero(sl.size()));
    // The tool's forces on an exposed sliding mesh's own nodes, with the sliding forces.
    Eigen::VectorXd f_b;
    if (slots != nullptr && forces_n != nullptr &&
        b.body->slide_contact_forces(e.slide, *slots, *forces_n, f_b)) {
      sl.displacement(lambda, f_b, u_m, ws);
      return;
    }
    sl.displacement(lambda, u_m, ws);
    return;
  }
  if (e.tie < 0) {
    u_m = u_host_m;
    return;
  }
  // The tool's forces on an exposed tied mesh's own nodes act on its interior too.
  Eigen::VectorXd f_b;
  if (slots != nullptr && forces_n != nullptr &&
      b.body->tie_contact_forces(e.tie, *slots, *forces_n, f_b)) {
    b.body->ties().at(static_cast<std::size_t>(e.tie)).displacement(u_host_m, f_b, u_m, ws);
    return;
  }
  b.body->ties().at(static_cast<std::size_t>(e.tie)).displacement(u_host_m, u_m, ws);
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
  if (e.slide >= 0) {  // B's field: the sliding forces and the tool's on its exposed part
    model_->mesh_field(e, bs.sliding_lambda, Eigen::VectorXd(), u_m, state_->field_workspace.get(),
                       &bs.force_slots, &bs.forces_n);
    return;
  }
  if (e.tie < 0) {
    state_->host_field(*model_, e.body, u_m);
    return;
  }
  Eigen::VectorXd u_host;
  state_->host_field(*model_, e.body, u_host);
  model_->mesh_field(e, bs.sliding_lambda, u_host, u_m, state_->field_workspace.get(),
                     &bs.force_slots, &bs.forces_n);
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
    const BodyModel& bm = model_->bodies_[e.body];
    // Contact forces alone: a sum of the loaded nodes' full columns (solved once per node).
    const bool contact_only =
        sb.nodal_forces_n.size() == 0 &&
        !(sb.sliding_lambda_n.size() > 0 && sb.sliding_lambda_n.maxCoeff() > 0.0);
    const double budget = model_->options_.field_column_budget_mb * 1e6;
    bool done = false;
    if (contact_only && budget > 0.0) {
      if (!sb.field_columns) {
        const double per_node = static_cast<double>(FieldColumns::bytes_per_slot(*bm.body));
        sb.field_columns = std::make_shared<FieldColumns>(
            *bm.body, static_cast<std::size_t>(std::max(1.0, std::floor(budget / per_node))));
      }
      done = sb.field_columns->field(sb.slots, sb.forces_n, sb.u_host_m, *sb.workspace);
    }
    if (!done) {
      model_->host_field(bm, sb.slots, sb.forces_n, sb.sliding_lambda_n, sb.nodal_forces_n,
                         nullptr, sb.u_host_m, sb.workspace.get());
    }
    sb.host_done = true;
  }
  if (!sb.workspace) sb.workspace = std::make_shared<fem::SolveWorkspace>();
  model_->mesh_field(e, sb.sliding_lambda_n, sb.u_host_m, u_m, sb.workspace.get(), &sb.slots,
                     &sb.forces_n);
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
    const BodyState& bs = state_->bodies_[bi];
    state_->host_field(*model_, static_cast<int>(bi), u_host);
    for (std::size_t i = 0; i < b.slides.size(); ++i) {
      const auto& sl = *b.slides[i];
      model_->mesh_field(model_->entry(sl.mesh()), bs.sliding_lambda, u_host, u_emb,
                         state_->field_workspace.get(), &bs.force_slots, &bs.forces_n);
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
        tie.displacement(u_host, u_emb, state_->field_workspace.get());
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
