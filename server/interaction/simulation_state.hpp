// Inside the Simulation (not part of its contract): the constant physics Model, the per-step
// State and the contact rows a step builds. simulation.cpp builds the Model and serves the
// fields; contact_step.cpp is the step, in named phases.
#pragma once

#include "server/interaction/column_worker.hpp"
#include "server/interaction/contact_columns.hpp"
#include "server/interaction/contact_lcp.hpp"
#include "server/interaction/contact_surface.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/loaded_blocks.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/sliding_coupling.hpp"
#include "server/interaction/tier_worker.hpp"
#include "server/interaction/tool_geometry.hpp"
#include "server/interaction/tool_proxy.hpp"
#include "server/interaction/viscoelastic_history.hpp"

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::interaction {

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
  ContactSurface surface;          // contactable triangles of the host, grid over them
  std::vector<mesh::Vec3> rest_m;  // per contact slot
  double max_penetration_m{0.0};
  // How far behind the surface a tool part still pushes it: max_penetration_m, at most three
  // mean edges of the contactable surface (the candidate box, the same for every history), unit m.
  double behind_reach_m{0.0};
  // SLIDING couplings hosted by the body: B's part, and where its rows start among the body's
  // sliding rows (CoupledBody::sliding_rows); the body's rows start at sliding_offset in the LCP.
  std::vector<std::unique_ptr<SlidingCoupling>> slides;
  std::vector<int> slide_first_row;
  int sliding_offset{0};
  // The host's material and supports (for the COROTATIONAL and NONLINEAR tiers' equilibrium).
  fem::Material host_material;
  std::vector<int> host_fixed_nodes;
  // The body's creep function (the host material's kernel; no terms: elastic, no history).
  fem::CreepSpectrum creep;
};

// One unilateral contact row: a point of a contactable triangle (a face point, an edge point or
// a node) against one tool part. Gap g = n . (c - sum w x) - r >= 0 with c the part's centre
// (the tip centre, or the shaft axis point closest to the feature) and x the nodes' positions;
// the row's force lambda pushes the tool along +n and the nodes along -n with weights w.
struct Row {
  int body{-1};
  int tool{-1};
  bool shaft{false};           // pushed by the shaft (else by the tip)
  bool radial{false};          // a node or edge row along the part's radius (else a surface normal)
  std::uint64_t key{0};        // feature (contact_step.cpp: feature_key)
  // The nodes the row acts on: its triangle's three (barycentric weights), or with
  // SimulationOptions::contact_spread the nodes of the load spread around the point
  // (ContactSurface::spread, at most kSpreadNodes).
  int nodes{3};
  std::array<int, kSpreadNodes> slot{};   // contact slots (-1: a fixed node, or no node)
  std::array<double, kSpreadNodes> w{};   // weights (sum 1; on fixed nodes they carry nothing)
  std::array<Vec3, kSpreadNodes> m{};     // per node the normal as its compliance sees it (R^T n; LINEAR n)
  Vec3 normal{Vec3::Zero()};   // unit, out of the tissue towards the tool
  Vec3 point_m{Vec3::Zero()};  // the contact point on the deformed surface, unit m
  double height_m{0.0};        // the centre's height above the point along n (deformed), unit m
  double depth_m{0.0};         // -gap on the deformed surface (current answer), unit m
  double rest_depth_m{0.0};    // -gap with the nodes at rest, unit m
  double spread_radius_m{0.0};  // SimulationOptions::contact_spread: the load's radius, unit m
  // SimulationOptions::contact_spread: the spread is made only for the rows the step keeps
  // (contact_step.cpp, spread_row); until then the row holds its triangle's nodes, the point at
  // rest and the surface normal the load is spread about, and rest_depth_m without the tiers'
  // offset along the spread nodes.
  bool spread_pending{false};
  Vec3 spread_at_m{Vec3::Zero()};
  Vec3 spread_normal{Vec3::Zero()};
  // SimulationOptions::contact_near_field: the tip's near-field compliance, shared in series by
  // the tip's rows on this body (contact_step.cpp, near_field), unit m/N; on a shaft row the
  // shaft's, shared by the shaft's rows (contact_shaft_near_field, near_field_of_shaft).
  double near_field_m_per_n{0.0};
  // The row is one of its tool's kept rows (rows_of_tool: within the per-tool limit, its spread
  // made, not on fixed nodes only): the near field is taken at the deepest kept row, with the
  // spread radius its spread ended with.
  bool kept{false};
  // The part's deepest row on this body (the depth the near field is taken at): d c / d depth
  // (unit 1/N; 0 where the near field is constant), for the tangent stiffness (answer).
  bool near_field_deepest{false};
  double near_field_slope_per_n{0.0};
  // LINEAR, the shaft's deepest row: d c / d x of the tool's translation x (unit 1/N), the depth's
  // whole gradient (the centre's and the point's slide, the normal's turn) and the tilt's
  // (contact_step.cpp near_field_of_shaft); zero elsewhere (there d c / d x = -slope n).
  Vec3 near_field_gradient{Vec3::Zero()};
  // d normal / d x of the tool's translation x (unit 1/m): a node or edge row against the part's
  // sphere or capsule turns as the tool moves (contact_step.cpp merge_features), and LINEAR's
  // smooth tip's projected face row (the interpolated normal at the sliding point); zero for a
  // flat face row and a row along a surface's mean normal. The answer adds lambda * turn to K.
  Mat3 turn{Mat3::Zero()};
  Vec3 turn_depth{Vec3::Zero()};  // turn^T d, d the part's centre less the point at rest
  // G^T n - n, G = d (centre - point) / d x: where the depth's gradient in x is not -n with the
  // normal held (a shaft row: its centre slides along the axis, an edge's point along the edge;
  // contact_step.cpp merge_features; the smooth tip's projected face row, whose depth is the
  // centre's distance to the flat surface and whose normal turns); zero for the tip's other rows.
  // The answer takes it as W's right-hand side changes (normal_turn).
  Vec3 depth_slide{Vec3::Zero()};
  // d point / d x (LINEAR, a face or edge row of the shaft or the tip: the point slides over the
  // surface as the tool moves; zero for a node row and in the tiers): a row's weights follow it
  // (the spread's or the triangle's), and W with them (normal_turn).
  Mat3 point_slide{Mat3::Zero()};
  // A row on its triangle's nodes (barycentric weights: no spread, or the spread found none) with
  // a point_slide: column k (k < 3) is d w_k / d x, the weights' gradient (normal_turn).
  Mat3 weight_slide{Mat3::Zero()};
};

// A candidate feature of one tool part on one triangle, before merging (contact_step.cpp).
struct FeatureHit {
  std::uint64_t key{0};
  int triangle{-1};
  bool shaft{false};
  bool at_rest{false};          // found on the rest surface (else on the deformed one)
  // SimulationOptions::contact_smooth_normals, the tip: a flat face row of a triangle whose
  // projection along the interpolated normals fails (contact_step.cpp, part_features), kept only
  // where the tip has no projected face row on the body.
  bool flat_fallback{false};
  TrianglePoint at;             // closest point of the deformed triangle, its weights
  Vec3 centre_m{Vec3::Zero()};  // the tool part's centre for this feature
  // The shaft: the centre's derivative in the tool's translation t, d centre / dt =
  // (I - u u^T) + u centre_slide^T (u the unit axis; contact_step.cpp part_features).
  Vec3 centre_slide{Vec3::Zero()};
  // The triangle's outward unit normal; a node hit: the sum over the node's reporting triangles.
  Vec3 face_normal{Vec3::Zero()};
  int normals{1};  // unit normals summed in face_normal
};

// What a step changes on a body.
struct BodyState {
  std::unique_ptr<ContactColumns> columns;  // filled on first touch (or when the state is made)
  std::size_t capacity_slots{0};  // column worker: at most this many ready at once (0: no bound)
  std::vector<long long> triangle_stamp;    // per triangle: last tool query that listed it
  std::vector<long long> position_stamp;    // per contact slot: step of position_m
  std::vector<mesh::Vec3> position_m;       // per contact slot: deformed position, unit m
  std::vector<int> force_index;             // per contact slot: index in force_slots or -1
  // Per contact slot and (rest surface, shaft): the node test of the last triangle search that
  // made it (its stamp) and whether the node was inside the part (each node tested once).
  // (one entry per slot and (rest, shaft), the four of a slot in one cache line)
  struct NodeTest {
    long long stamp{-1};
    int hit{-1};  // its hit in State::hits_ (tested in)
    bool in{false};
  };
  std::vector<NodeTest> node_tests;
  // Largest displacement at the loaded slots of the last geometry followed by another (LINEAR:
  // within one step; 0 at a step's start) or of the last good step (the tiers), unit m.
  double max_displacement_m{0.0};
  // Last good step's contact forces on the body, per slot (unit N), and sliding row forces.
  std::vector<int> force_slots;
  std::vector<mesh::Vec3> forces_n;
  Eigen::VectorXd sliding_lambda;
  // Viscoelastic body: the hereditary integral's internal variables; forces_n above are then the
  // creep-equivalent forces (the elastic forces giving the displacement, viscoelastic_history.hpp).
  std::unique_ptr<ViscoelasticHistory> history;
  // Phase "relaxation": one tool's force per slot (tissue side, unit N) and the stamp that says
  // which entries belong to the current tool (sized with the history).
  std::vector<mesh::Vec3> tool_force_n;
  std::vector<long long> relax_stamp;
  // Phase "Delassus" (delassus_fill): per contact slot the history's displacement C h_n at the
  // rows' nodes (unit m) and the geometry (State::geometry_counter_) that formed it; normal_turn's
  // U_k reads it (sized with the history).
  std::vector<mesh::Vec3> history_u_m;
  std::vector<long long> history_u_stamp;
  // store_forces: the step's history forces h_n, first in forces_n (history_count of them;
  // sized with the history), kept for normal_turn after commit_history.
  int history_count{0};
  std::vector<mesh::Vec3> history_forces_n;
  // SimulationOptions::contact_near_field on a relaxing body (its host material has Prony terms;
  // LINEAR or NONLINEAR tier): the near field's own hereditary integral, one slot per tool (the
  // tip's total force on the body), with the host's kernel, so the compliance in series creeps
  // and relaxes as the mesh does (contact_step.cpp, near_field). The last good step's loaded
  // tools and their creep-equivalent forces (tissue side, unit N), committed with the history.
  std::unique_ptr<ViscoelasticHistory> near_field_history;
  int near_field_slots{0};  // tools (pose indices) it follows; a later one's near field is elastic
  std::vector<int> near_field_tools;
  std::vector<mesh::Vec3> near_field_forces_n;
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
  // Field of mesh `m` (entry e) from its body's host field; ws as in host_field (the tied
  // mesh's interior and the sliding mesh's compliance solve on it). slots/forces_n (optional):
  // the body's contact forces, of which those on an exposed tied mesh's slots load its nodes.
  void mesh_field(const MeshEntry& e, const Eigen::VectorXd& sliding_lambda_n,
                  const Eigen::VectorXd& u_host_m, Eigen::VectorXd& u_m,
                  fem::SolveWorkspace* ws = nullptr, const std::vector<int>* slots = nullptr,
                  const std::vector<Vec3>* forces_n = nullptr) const;
  // COROTATIONAL and NONLINEAR: field of mesh entry e from its body's stacked equilibrium
  // (host, then the tied meshes in the order of CoupledBody::ties()).
  void tier_mesh_field(const MeshEntry& e, const Eigen::VectorXd& stacked_u_m,
                       Eigen::VectorXd& u_m) const;

  SimulationOptions options_;
  std::string source_;
  std::vector<MeshEntry> meshes_;
  std::vector<BodyModel> bodies_;
  std::vector<ToolShape> tools_;
  // The scene's rigid obstacles (the skull), with tool contact only; null: none. The step holds
  // each station's tool outside them (State: a ToolProxy per station, with these options).
  std::unique_ptr<const RigidObstacle> rigid_;
  ToolProxyOptions proxy_options_;
  std::vector<scene::RigidOpening> openings_;  // of the rigid meshes (the skull's craniotomy)
  SetupStats setup_;
  int num_sliding_{0};  // sliding rows, first in the LCP
  double step_period_s_{1e-3};  // 1 / rates.step_hz: the time of a step given none, unit s
  bool viscoelastic_{false};    // some body has a relaxation kernel
  scene::Tier tier_{scene::Tier::kLinear};
};

// Everything a step changes (MuJoCo's mjData): per body the contact-compliance cache, the
// deformed surface positions and the last good forces; the rows, the Delassus operator and the
// LCP with its warm start; the last good answer per tool. Sized at construction and per tool
// count, no allocation once warmed up.
class State {
 public:
  // The compliance columns of every contactable node when options.precompute_contact_columns,
  // and, with sliding rows, the step workspace and the inverse of their constant block.
  explicit State(const Model& m);
  // The step (contact_step.cpp): pose, history, candidates, rows, columns, Delassus, near field,
  // LCP, forces, answer per tool, relaxation, normals' turn, tier post.
  // time_s: the step's time (the poses' sample time, unit s); only a viscoelastic body uses it
  // (the time since the last converged step; an earlier time counts as none passed).
  void step(const Model& m, const std::vector<ToolPose>& poses, double time_s,
            std::vector<ToolContact>& contacts, StepStats& stats);
  // Forget a station's proxy (Simulation::reset_station).
  void reset_station(int station) {
    if (station >= 0 && station < static_cast<int>(proxies_.size()) && proxies_[station])
      proxies_[station]->reset();
  }
  // The time of the last step (for steps given no time: one step period later), unit s.
  double time_s() const { return time_s_; }
  // Host field for the last good step (stepping thread: may use the cached full columns).
  void host_field(const Model& m, int body, Eigen::VectorXd& u_host_m) const {
    if (tier_) {
      u_host_m = tier_->linearization(body).u_m.head(
          3 * static_cast<Eigen::Index>(m.bodies_[body].body->host().num_vertices()));
      return;
    }
    const BodyState& bs = bodies_[body];
    m.host_field(m.bodies_[body], bs.force_slots, bs.forces_n, bs.sliding_lambda,
                 Eigen::VectorXd(), bs.columns.get(), u_host_m, field_workspace.get());
  }
  // Solve scratch of the fields asked on the stepping thread (Simulation::displacements and the
  // diagnostics): a pointer, so the const field queries solve on it and never on a solver's own
  // locked workspace in the Model.
  std::unique_ptr<fem::SolveWorkspace> field_workspace = std::make_unique<fem::SolveWorkspace>();

  std::vector<BodyState> bodies_;
  // SimulationOptions::column_worker: solves the columns ahead of the tools (declared after
  // bodies_: stopped before the caches it fills are destroyed); null otherwise.
  std::unique_ptr<ColumnWorker> column_worker_;
  std::uint64_t columns_not_ready_{0};  // StepStats::columns_not_ready summed over the steps
  std::uint64_t steps_with_rows_dropped_{0};  // steps with StepStats::contact_rows_dropped > 0
  std::uint64_t steps_not_converged_{0};      // steps whose contact LCP did not converge
  int geometry_rows_dropped_{0};  // this geometry's touching rows beyond the per-tool limit
  double columns_s_{0.0};  // compliance columns computed at construction, unit s
  double sliding_s_{0.0};  // step workspace and constant sliding block at construction, unit s
  // COROTATIONAL and NONLINEAR: every body's equilibrium, following the contact forces
  // (tier_worker.hpp); null for LINEAR.
  std::unique_ptr<TierWorker> tier_;
  double tier_s_{0.0};  // tier solvers (pattern, symbolic analysis) at construction, unit s

 private:
  // Phases of step() (contact_step.cpp).
  void check_poses(const Model& m, const std::vector<ToolPose>& poses) const;
  void hold_poses(const Model& m, const std::vector<ToolPose>& poses);
  void restore_proxies();
  void solve_held_poses(const Model& m, double time_s, std::vector<ToolContact>& contacts,
                        StepStats& stats, std::chrono::steady_clock::time_point t0);
  void begin_step(const Model& m, int tools, StepStats& stats);
  void reserve_workspace(const Model& m, int tools);
  void candidate_triangles(const Model& m, int body, int tool, const ToolPose& pose,
                           const Vec3& axis);
  struct StepCandidates;
  void reusable_candidates(const Model& m, int body, int tool_index, const Vec3& p0,
                           const Vec3& p1, double slack, double reuse_m, StepCandidates& sc);
  int reusable_parts(const Model& m, int body, int t, const ToolShape& shape, const Vec3& p0,
                     const Vec3& p1, double w, bool& flat) const;
  void rest_candidate_list(const Model& m, int body, int tool_index, const Vec3& p0,
                           const Vec3& p1, double slack, StepCandidates& sc);
  void full_candidate_list(const Model& m, int body, int tool_index, const Vec3& p0,
                           const Vec3& p1, double slack, StepCandidates& sc);
  void search_verdicts(const Model& m, int body, const Vec3& p0, const Vec3& p1, double search_m,
                       StepCandidates& sc);
  void triangle_features(const Model& m, int body, int tool, const ToolPose& pose,
                         const Vec3& axis);
  bool triangle_geometry(const Model& m, int body, int t, bool deformed,
                         std::array<Vec3, 3>& moved, const std::array<Vec3, 3>*& x, Vec3& n,
                         Vec3& centre, double& rho);
  void rows_of_tool(const Model& m, int tool, const ToolPose& pose, const Vec3& axis);
  void merge_tool_row(const Row& r);
  void part_features(int t, const SurfaceTriangle& tri, const std::array<Vec3, 3>& x,
                     const Vec3& n, const Vec3& centre, double rho, bool shaft, bool at_rest,
                     const ToolShape& shape,
                     const Vec3& p0, const Vec3& p1, double margin, double max_penetration_m,
                     const std::vector<Vec3>& node_normals, BodyState& bs, long long memo,
                     const std::array<Vec3, 3>* smooth_normals, int search, int node_mask,
                     const TierLinearization* lin);
  // part_features' steps (contact_step.cpp).
  void node_hits(const SurfaceTriangle& tri, const std::array<Vec3, 3>& x,
                 const ToolShape& shape, const Vec3& p0, const Vec3& p1, double reach,
                 double max_penetration_m, const std::vector<Vec3>& node_normals, BodyState& bs,
                 long long memo, int node_mask, const TierLinearization* lin, FeatureHit& h);
  bool smooth_projection_hit(const std::array<Vec3, 3>& x,
                             const std::array<Vec3, 3>& smooth_normals, const Vec3& p0,
                             double reach, double max_penetration_m, FeatureHit& h);
  void edge_or_face_hit(const SurfaceTriangle& tri, const std::array<Vec3, 3>& x, const Vec3& n,
                        const ToolShape& shape, const Vec3& p0, const Vec3& p1, double reach,
                        double max_penetration_m, FeatureHit& h);
  Vec3 shaft_centre(const std::array<Vec3, 3>& x, const Vec3& n, const Vec3& p0,
                    const Vec3& p1, TrianglePoint& at, Vec3& centre_slide);
  // shaft_centre: the last segment's axis p1 - p0, its squared length and unit axis (formed again
  // when the segment differs bit for bit)
  struct AxisMemo {
    Vec3 p0{Vec3::Zero()}, p1{Vec3::Zero()}, e{Vec3::Zero()}, u{Vec3::Zero()};
    double len2{0.0};
    bool valid{false};
  };
  AxisMemo shaft_axis_;
  void merge_features(const Model& m, int body, int tool, const ToolShape& shape,
                      const Vec3& tip, const Vec3& axis);
  // merge_features' steps: one feature's row as they form it (contact_step.cpp).
  struct FeatureRow {
    Vec3 normal_sum{Vec3::Zero()};  // the reporting hits' face normals, summed
    int reports{0};                 // hits reporting the feature (on the first hit's geometry)
    int normals{0};                 // unit normals summed in normal_sum
    double cos_alpha{0.0};          // a node or edge: |normal_sum| / normals
    // The triangle's nodes, deformed where the hit was found, else at rest (unit m; an edge or
    // face hit), and an edge hit's unit direction.
    std::array<Vec3, 3> x{};
    Vec3 edge{Vec3::Zero()};
    Vec3 d{Vec3::Zero()};  // the part's centre less the point, unit m
    double dn{0.0};        // |d|, unit m
    Vec3 depth_centre{Vec3::Zero()};  // the depth is r - n . (depth_centre - point), unit m
    Vec3 n{Vec3::Zero()};             // the row's normal
    Mat3 turn{Mat3::Zero()};          // Row::turn, unit 1/m
    Vec3 depth_slide{Vec3::Zero()};   // Row::depth_slide
    Mat3 point_slide{Mat3::Zero()};   // Row::point_slide
    // The smooth tip's projected face row: J^-1, the height parameter s, N(u, v) and its
    // derivatives dN/du, dN/dv (face_row_geometry), for the depth's gradient (smooth_lift).
    bool smooth_row{false};
    Mat3 smooth_inverse{Mat3::Zero()};
    double smooth_scale{0.0};
    Vec3 smooth_n{Vec3::Zero()};
    std::array<Vec3, 2> smooth_dn{};
    bool weights_kink{false};  // the barycentric weights have no derivative (a flat edge)
    bool radial{false};
    bool exit_row{false};          // LINEAR's node or edge row (exit_row_geometry)
    Vec3 plane_n{Vec3::Zero()};    // exit_row: the surface's plane for the entry rule
    double plane_h{0.0};           // and the centre's height above it, unit m
    // The multirate tiers' tip node and edge rows: added to the rest depth, so that at the tier's
    // fixed point the depth is the part's radius less the distance to the carried point (unit m;
    // carried_row_geometry).
    double depth_add{0.0};
  };
  void sort_hits();
  std::size_t feature_hits(std::size_t i0, FeatureRow& fr) const;
  void feature_nodes(const Model& m, int body, const FeatureHit& h, FeatureRow& fr);
  void face_row_geometry(const BodyModel& b, const FeatureHit& h, const Vec3& axis,
                         bool smooth_tip, FeatureRow& fr);
  void exit_row_geometry(const ToolShape& shape, const FeatureHit& h, const Vec3& tip,
                         const Vec3& axis, FeatureRow& fr);
  void radial_row_geometry(const ToolShape& shape, const FeatureHit& h, const Vec3& axis,
                           FeatureRow& fr);
  void edge_slide(FeatureRow& fr) const;
  void carried_row_geometry(const Model& m, int body, const ToolShape& shape,
                            const FeatureHit& h, FeatureRow& fr) const;
  bool feature_row(const Model& m, int body, int tool, const ToolShape& shape,
                   const FeatureHit& h, const FeatureRow& fr, Row& r);
  static void row_weight_slide(const FeatureRow& fr, Row& r);
  static void row_spread_inputs(const Model& m, const BodyModel& b, const ToolShape& shape,
                                const FeatureHit& h, const FeatureRow& fr,
                                const Vec3& rest_point, Row& r);
  double smooth_lift(const Model& m, int body, int tool, const FeatureHit& h,
                     const FeatureRow& fr, Row& r);
  void drop_fallback_rows(std::size_t first);
  void drop_behind_rows(std::size_t first, const ToolShape& shape, const Vec3& axis);
  void drop_shared_projections(double tip_radius_m);
  double flat_distance(const Model& m, int body, int tool, const Vec3& c, const Vec3& facing,
                       bool at_rest, double at_most_m, Vec3* closest = nullptr);
  void near_field_of_tool(const Model& m, const ToolShape& shape);
  void near_field_of_shaft(const Model& m, const ToolShape& shape, const Vec3& axis);
  bool spread_row(const Model& m, Row& r);
  void near_field(int ns);
  void compliance_columns(StepStats& stats);
  void columns_fallback(StepStats& stats);
  void grant_evictions();
  void preload_columns(const Model& m);
  void delassus(const Model& m, int ns);
  // delassus's parts (contact_step.cpp): the rows' nodes, the match with the last W's rows, y per
  // row and node, W and delta, a row's column against the sliding rows.
  void delassus_nodes();
  bool delassus_match();
  void delassus_y();
  void delassus_fill(const Model& m, int ns);
  void delassus_sliding(const Model& m, int ns, int r);
  void delassus_cache_lookup(bool reuse);
  void store_forces(const Model& m, int ns);
  void largest_displacement(const Model& m);
  void answer(const Model& m, int tool, const ToolPose& pose, int ns, int iterations, int tools,
              ToolContact& c);
  Mat3 own_stiffness(int ns, int tool);
  void near_field_tangent(int tool, int ns, int tools, Mat3& k);
  void normal_turn(const Model& m, int tool, int ns, int tools, ToolContact& c);
  // normal_turn's parts (contact_step.cpp): the rows' turn on a body (the depth's and W's terms
  // of V), the rows' sliding weights, W's change as they slide on a body, and -N^T W^-1 V.
  void turn_rows(int tool, int ns, int body);
  // turn_rows' steps: the parts' near-field sums on a relaxing body, the node sums U_k and Y_q.
  void turn_parts_relaxed(int tool, int body, Vec3 part_force[2], Mat3 part_turn[2]) const;
  void turn_node_sums(int body, double coupling);
  bool slide_weights(const Model& m, int tool, int ns);
  void slide_rows(int tool, int ns, int body);
  void list_u_nodes();
  void node_displacements(int body, bool compact);
  void loaded_displacements(int body);
  void column_displacements(int body);
  bool loaded_indices(int body);
  void slide_node_sums(int body, bool compact);
  void turn_stiffness(int tool, int ns, int tools, ToolContact& c);
  // A relaxing body's factor on W's terms of V (contact_step.cpp): its alpha / turn_scale_.
  double turn_coupling(int body) const;
  // normal_turn's U_k on a relaxing body from the history's displacement (false: not formed here).
  bool relaxing_displacement(int body);
  Vec3 part_response(int tool, int ns, int tools, const Row& d, const Vec3& f);
  // The near field's history of `body` when it follows `tool` (else nullptr: elastic).
  const ViscoelasticHistory* near_field_history(int body, int tool) const {
    const BodyState& bs = bodies_[body];
    return tool < bs.near_field_slots ? bs.near_field_history.get() : nullptr;
  }
  // The step's creep-equivalent force of the near field is alpha F + h (F the tip's force on
  // the tissue): h returned, alpha set (1 and 0 without a history; contact_step.cpp near_field).
  Vec3 near_field_creep(int body, int tool, double& alpha) const;
  int main_body_of(const Model& m, int tool, int ns, double& sum_n) const;
  void relaxation(const Model& m, int tool, int ns, ToolContact& c);
  void tier_post(StepStats& stats);
  LcpResult solve_geometry(const Model& m, const std::vector<ToolPose>& poses, StepStats& stats);
  void save_forces();
  void restore_forces(bool to_rest);
  bool same_rows_as_before();
  const mesh::Vec3& position(const Model& m, int body, int slot);

  void begin_history(const Model& m, double time_s);
  static void add_history_forces(BodyState& bs);
  void commit_history();

  double time_s_{0.0};        // time of the last converged step, unit s
  bool timed_{false};         // a step converged (else the first step is a jump: dt = 0)
  double step_time_s_{0.0};   // this step's time
  long long stamp_counter_{0};
  long long geometry_counter_{0};  // rows found on a new geometry (positions cached per value)
  std::vector<FeatureHit> hits_;   // features of one body and tool, before merging
  std::vector<std::size_t> boundary_hits_;  // drop_shared_projections: hits on an edge or vertex
  // sort_hits: per hit its key, (geometry, triangle) and index; the hits in that order.
  struct HitOrder {
    std::uint64_t key;
    std::uint64_t then;
    std::size_t index;
  };
  std::vector<HitOrder> hit_order_;
  std::vector<FeatureHit> sorted_hits_;
  // Per tool and body (index tool * bodies + body), kept through the geometries of one step: the
  // candidate triangles (and the slack they were found with) and, LINEAR, the hits of the first
  // geometry, which is the rest surface (the later geometries' rest hits, not searched again).
  struct StepCandidates {
    long long step{-1};
    double slack_m{0.0};
    double moved_m{0.0};  // the surface displacement the list allows for, unit m
    std::vector<int> triangles;
    // Per listed triangle, the parts whose bound its rest bounding sphere meets (1 the tip, 2 the
    // shaft): the other part cannot have a hit on it and is not searched. On a list made from
    // `reusable` also kSearchKnown and, shifted by 2, the parts whose edge or face search can
    // find a hit (Reusable::search).
    std::vector<std::uint8_t> parts;
    static constexpr std::uint8_t kSearchKnown = 128;
    std::vector<std::uint8_t> nodes;  // with kSearchKnown: Reusable::nodes
    // A list made from `reusable` for these query cells (candidate_triangles), valid until
    // `reusable` or its search verdicts change: the next pose with the same cells keeps it.
    bool list_valid{false};
    PointGrid::CellRange list_tip_cells, list_shaft_cells;
    bool rest_hits_valid{false};
    std::vector<FeatureHit> rest_hits;
    // The list is the rest surface's (no force on the body, flat rows): made from `reusable`.
    bool rest_only{false};
    // On the rest surface, kept across steps (contact_step.cpp, reusable_candidates): the
    // triangles a part of the tool can have a hit on while its tip and shaft end stay within
    // reuse of reuse_p0 / reuse_p1 (unit m), in the grid's query order (rank), with those parts.
    struct Reusable {
      int triangle{-1};
      int rank{0};
      std::uint8_t parts{0};
      std::array<int, 3> cell{};  // its grid cell (ContactSurface::query_cell): scanned per pose
      // The parts (bits as `parts`) whose edge or face search on this triangle can find a hit
      // while the tip and shaft end stay within search_m of search_p0 / search_p1 (contact_step.cpp,
      // search_verdicts): the plane tests of part_features, made once for those poses; and
      // kNoProjection: the smooth tip's projection along the node normals has no hit here.
      std::uint8_t search{0};
      static constexpr std::uint8_t kNoProjection = 4;
      // Per part (bits 3 part + k) whether vertex k can be the part's node hit for those poses
      // (search_verdicts): the others' node tests are skipped.
      std::uint8_t nodes{0};
    };
    std::vector<Reusable> reusable;
    bool reuse_valid{false};
    int reuse_tool{-1};
    double reuse_slack_m{0.0};
    Vec3 reuse_p0{Vec3::Zero()}, reuse_p1{Vec3::Zero()};
    bool search_valid{false};  // Reusable::search holds for search_p0 / search_p1
    double search_m{0.0};
    Vec3 search_p0{Vec3::Zero()}, search_p1{Vec3::Zero()};
  };
  std::vector<StepCandidates> step_candidates_;
  int candidate_tests_{0};  // of this step (StepStats::candidate_tests)
  long long step_counter_{0};
  long long node_memo_counter_{0};
  const StepCandidates* candidates_{nullptr};  // of the body and tool being searched
  std::vector<Row> tool_rows_;     // rows of one tool, before the per-tool limit
  std::vector<int> tool_order_;    // indices of tool_rows_ within the margin, deepest first
  // Per row of tool_rows_ appended by merge_features: its part's centre, unit m (the entry rule).
  std::vector<mesh::Vec3> tool_row_centre_;
  // Per row as tool_row_centre_: the surface's plane at its point (normal, the centre's height
  // above it) for the entry rule; the row's own normal and height but for LINEAR's tip node and
  // edge rows (their normal the tip's at the point's exit along the surface normal).
  std::vector<mesh::Vec3> tool_row_plane_;
  std::vector<double> tool_row_plane_h_;
  std::vector<char> tool_row_fallback_;  // per row from the body's first: a flat fallback row
  // (copied field by field: contact_step.cpp copy_spread)
  struct SpreadMemo {  // a spread (spread_row) by its inputs: body, point, normal, radius
    int body{-1};
    Vec3 at_m{Vec3::Zero()};
    Vec3 normal{Vec3::Zero()};
    double radius_m{0.0};
    bool found{false};
    SpreadLoad load;
    // A LINEAR shaft face or edge row's spread (Row::point_slide): d weight / d point per node
    // of `load` (ContactSurface::spread's gradient), for normal_turn; false: not computed.
    bool has_gradient{false};
    std::array<Vec3, kSpreadNodes> gradient;
  };
  // Phase "rows", reuse (rows_of_tool): per pose index, the rows the tool kept (spread, near field
  // set; before the merge with the other tools' rows) on the rest surface, and the pose they are
  // of. LINEAR's rest surface (no force on any body, no tier) is constant, so the kept rows are a
  // function of the pose's tip, axis and tool shape alone: a pose equal to the last one bit for
  // bit takes them (a server stepping on each station's pose repeats three of four). valid false
  // until a search on the rest surface completes.
  struct ToolRowsMemo {
    bool valid{false};
    int tool{-1};  // ToolPose::tool
    Vec3 tip_m{Vec3::Zero()};
    Vec3 axis{Vec3::Zero()};  // ToolPose::axis as given
    std::vector<Row> rows;
    // The spreads of those rows (spread_row's memo entries): carried into each geometry's memo
    // that takes the rows, so the tool's next move finds those of its rows that repeat.
    std::vector<SpreadMemo> spreads;
    int dropped{0};  // touching rows beyond the per-tool limit
  };
  std::vector<ToolRowsMemo> tool_rows_memo_;
  bool rest_geometry_{false};  // this geometry is the rest surface (solve_geometry)
  std::vector<int> spread_triangles_;  // ContactSurface::spread's candidates (capacity: triangles)
  SpreadLoad spread_load_;             // one row's spread load
  std::array<Vec3, kSpreadNodes> spread_gradient_;  // its weights' gradient (sliding rows)
  std::vector<Row> rows_;          // the step's contact rows
  // While the tools' rows merge (merge_tool_row): per row of rows_ its main slot, formed once.
  std::vector<int> row_main_slot_;
  std::vector<std::vector<int>> missing_;
  std::vector<std::vector<long long>> not_ready_stamp_;  // per body and slot: geometry counted
  Eigen::MatrixXd w_;
  Eigen::VectorXd delta_, lambda_;
  std::vector<char> sliding_active_;  // per sliding row: carried a force in the last good step
  std::vector<char> warm_;            // LCP start (the problem's: the rows that penetrate)
  // SimulationOptions::lcp_warm_start: per row, active in the last converged LCP (its key in
  // active_keys_: row_key, sorted).
  std::vector<char> warm_active_;
  std::vector<std::uint64_t> active_keys_;
  // Per contact row, kSpreadNodes terms: its column against the sliding rows by node (the LCP keeps
  // W_ss^-1 times each node's sliding block, so a row whose weights change costs O(sliding rows)).
  std::vector<LcpColumnTerm> column_terms_;
  // Phase "Delassus": the step's distinct row nodes (per body and slot their index, -1 outside
  // the phase), per row node its index, the last row on each node, and per row r and node j
  // y_rj = sum_p w_rp L(slot_rp, j)^T m_rp (rows share nodes: computed once, not per row pair).
  std::vector<std::vector<int>> delassus_node_;
  std::vector<std::pair<int, int>> delassus_nodes_;  // (body, slot)
  std::vector<int> delassus_last_row_;
  std::vector<std::array<int, kSpreadNodes>> delassus_row_node_;
  std::vector<mesh::Vec3> delassus_y_;
  // Phase "Delassus", reuse: the rows of the last W and their block of it before alpha and the
  // row compliance (v_rs, a function of the two rows and the body's ready columns alone); a row
  // equal bit for bit (body, nodes, slots, weights, normals) to one of them is matched, and a
  // pair of matched rows gets its v back. Per node the last unmatched row on it (-1: none), so
  // y_rj of a matched row r is formed only for the nodes of unmatched rows s >= r. Forgotten when
  // a body's columns lose slots (eviction) since.
  std::vector<Row> delassus_prev_rows_;
  Eigen::MatrixXd delassus_v_, delassus_prev_v_;
  std::vector<int> delassus_match_;
  std::vector<int> delassus_fresh_;  // the rows forming y_rj fresh for one node j
  std::vector<int> delassus_last_fresh_row_;
  std::vector<int> delassus_unmatched_;  // the rows of this W matched to none, ascending
  std::vector<int> delassus_row_body_;   // per row of this W: its body (the node loop's test)
  std::vector<std::uint64_t> delassus_evicted_;  // per body: its columns' evicted() at the last W
  // Phase "Delassus", y cache: y_rj is a function of row r's content (body, nodes, slots, weights,
  // normals m) and node j's ready column alone, so it is kept across steps by content and node:
  // rows by entry (at most delassus_cache_rows_, the least recently used given up), nodes by a
  // cache index (at most kDelassusCacheNodes, all given up when full), per entry and node the
  // value and the entry's generation that formed it (a recycled entry, a flush: a new generation).
  // Four held probes (one station's pose new per step) need y of the held rows against the moving
  // rows' nodes: the last W's alone had them every fourth step.
  static constexpr int kDelassusCacheNodes = 512;
  struct DelassusCacheEntry {
    std::uint64_t key{0};
    int body{-1};
    int nodes{-1};
    long long used{-1};        // the Delassus (delassus_counter_) that last read it
    long long generation{-1};  // its values' generation
  };
  int delassus_cache_rows_{0};
  std::vector<DelassusCacheEntry> delassus_cache_;
  std::vector<Row> delassus_cache_content_;
  std::vector<std::vector<int>> delassus_cache_node_;  // per body and slot: cache index or -1
  std::vector<std::pair<int, int>> delassus_cache_nodes_;  // (body, slot) per cache index
  // Node-major (cache index x entries), each value beside the generation that formed it (one
  // cache line per lookup: the lookups are mostly misses of a few MB).
  struct DelassusY {
    mesh::Vec3 y{mesh::Vec3::Zero()};
    long long stamp{-2};  // -2: no generation
  };
  std::vector<DelassusY> delassus_cache_y_;
  std::vector<int> delassus_row_entry_;   // per row of this W: its entry or -1
  // per row of this W: its entry's generation where the entry may hold values (-1: no entry, or
  // an entry given a new generation by this W's lookup, which no value has yet)
  std::vector<long long> delassus_row_generation_;
  std::vector<int> delassus_node_entry_;  // per node of this W: its cache index or -1
  std::vector<int> delassus_prev_entry_;  // per row of the last W: its entry or -1
  std::vector<long long> delassus_prev_generation_;  // and that entry's generation then
  long long delassus_counter_{0};
  long long delassus_generation_{0};
  // Phase "rows", spread reuse (spread_row): the spreads of the last and of this geometry (made
  // or taken from the memo) by their inputs (body, point, normal, radius); ContactSurface::spread
  // is a function of these and the constant rest surface, so an equal input (bit for bit) takes
  // the stored load.
  std::vector<SpreadMemo> spread_memo_, spread_prev_memo_;
  // Per entry of spread_memo_ / spread_prev_memo_: its inputs' key (contact_step.cpp spread_key),
  // which find_spread scans.
  std::vector<std::uint64_t> spread_keys_, spread_prev_keys_;
  void add_spread(const SpreadMemo& e);
  static void copy_spread(SpreadMemo& d, const SpreadMemo& e);
  const SpreadMemo* last_spread_{nullptr};  // spread_row: the memo entry of its row's spread
  // The memo entry of a spread with the row's inputs (bit for bit), this geometry's or the last's.
  const SpreadMemo* find_spread(const Row& r, bool* from_last) const;
  ContactLcp lcp_;
  bool lcp_constant_block_{false};  // set_constant_block done
  std::vector<ToolContact> last_good_;
  // Phase "pose": a proxy per station (index ToolPose::station; made on the station's first
  // pose), the poses the physics steps (held on the free side of the rigid obstacles), each
  // tool's planes, and each proxy's memory before this step (put back if the step throws).
  std::vector<std::unique_ptr<ToolProxy>> proxies_;
  std::vector<ToolPose> held_;
  std::vector<ObstaclePlanes> planes_;
  std::vector<std::pair<int, ToolProxy::Memory>> proxy_before_;
  std::vector<TierLoad> tier_loads_;  // per body, the step's contact forces for the worker
  // The last good forces while a LINEAR step iterates its geometry (restored if it fails).
  struct ForceBackup {
    std::vector<int> slots;
    std::vector<mesh::Vec3> forces_n;
    Eigen::VectorXd sliding_lambda;
    double max_displacement_m{0.0};
  };
  std::vector<ForceBackup> backup_;
  std::vector<char> sliding_active_backup_;
  std::vector<std::uint64_t> row_keys_, previous_row_keys_;  // rows of the last two geometries
  long long relax_counter_{0};
  bool relaxing_near_field_{false};  // a body has a near_field_history (time is kept for it)
  std::vector<int> relax_slots_;  // relaxation: the slots of one tool's rows on its main body
  std::vector<int> own_rows_;  // own_stiffness: one tool's active rows, its factor and N
  Eigen::MatrixXd own_factor_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> own_y_;
  std::vector<double> own_z_;  // near_field_tangent: L z = N_b^T f (part_response)
  std::vector<Vec3> turn_v_;   // normal_turn: per contact row, v_i (the depth's and W's turn)
  // relaxation: the factor it scaled this tool's K by (the relaxing body's alpha, else 1), which
  // normal_turn's -N^T W^-1 V takes too (turn_coupling).
  double turn_scale_{1.0};
  // normal_turn: per contact row, d w_k / d x of its spread weights (Row::point_slide)
  std::vector<std::array<Vec3, kSpreadNodes>> weight_slide_;
  std::vector<char> weight_slides_;  // per contact row: weight_slide_ holds its gradients
  // normal_turn, W's change as the points slide, per distinct node k of one tool's active rows on
  // a body: its slot, U_k (the displacement by the step's forces; rows that slide only) and
  // Y_k = sum_{j sliding} lambda_j sum_q (C_kq n_j) (d w_jq / d x)^T; turn_node_[body][slot]: the
  // node's index there, else -1 (restored after each use).
  std::vector<int> turn_nodes_;
  std::vector<Vec3> turn_u_;
  std::vector<char> turn_needs_u_;
  // list_u_nodes: the indices into turn_nodes_ of the nodes that need U_k, ascending (one list
  // per node set: relaxing_displacement, node_displacements and turn_node_sums read it)
  std::vector<int> turn_u_at_;
  std::vector<int> turn_u_todo_;  // node_displacements: the nodes of turn_u_at_ not formed yet
  // slide_rows: a sliding row's term of Y_k per node q, its column of C (node k's block at 9 k),
  // its normal and lambda_j dw_jq / dx
  struct SlideTerm {
    const double* column;
    int index;  // the node's index in the body's LoadedBlocks (-1: not there)
    const Vec3* normal;
    Vec3 dw;
  };
  std::vector<SlideTerm> slide_terms_;
  std::vector<Mat3> turn_y_;
  std::vector<Mat3> turn_a_;  // normal_turn, the rows' turn: per node A_k (contact_step.cpp)
  std::vector<std::vector<int>> turn_node_;
  // node_displacements: per body the loaded nodes' compliance blocks (kept across steps), and
  // this use's indices there per force slot and per node of turn_nodes_ (loaded_indices)
  std::vector<LoadedBlocks> loaded_blocks_;
  std::vector<int> loaded_force_index_;
  std::vector<int> loaded_node_index_;
  // node_displacements: per body and slot U_k as last formed, and the turn_u_stamp_ it was formed
  // under (the forces do not change while normal_turn runs over the tools: one U_k per node and
  // step, however many tools' rows and phases have the node)
  std::vector<std::vector<Vec3>> turn_u_memo_;
  std::vector<std::vector<std::uint64_t>> turn_u_memo_stamp_;
  std::uint64_t turn_u_stamp_{0};
  Eigen::Matrix<double, Eigen::Dynamic, 3> turn_z_;  // normal_turn, several tools: L Z = V
};

}  // namespace neurosim::interaction
