// The physics the server steps: a constant Model (meshes, factorizations, coupling operators,
// contact geometry, tools) built once from a scene::Model, a State that each step changes, the
// step that solves every station's tool contact together, and the displacement fields.
// Simulation is the contract between this component and its callers (the service, the tools,
// the tests): extend it freely, keep the meaning of what is here.
#pragma once

#include "server/interaction/iterative_tie.hpp"
#include "server/interaction/rigid_obstacle.hpp"
#include "server/mesh/tet_mesh.hpp"
#include "server/model/model.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::fem {
class SolveWorkspace;  // server/fem/static_solver.hpp
}  // namespace neurosim::fem

namespace neurosim::interaction {

class CoupledBody;   // server/interaction/coupled_body.hpp
class FieldColumns;  // server/interaction/field_columns.hpp

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

// Pose of one tool (from a station's ToolState), unit m.
struct ToolPose {
  Vec3 tip_m{Vec3::Zero()};  // centre of the spherical tip
  Vec3 axis{Vec3::UnitZ()};  // unit vector from the tip towards the handle (shaft direction)
  int tool{0};               // index into the scene's tools (tip and shaft radii)
  // The station the pose comes from, the same in every step (the live server's slot, the replay's
  // recording): with rigid obstacles its proxy remembers where the tip was last free. -1: the
  // pose's index in the step's poses. At most kMaxStations - 1.
  int station{-1};
};

// Stations a Simulation tells apart (ToolPose::station), each with its own rigid proxy.
inline constexpr int kMaxStations = 4096;

// The part of a tool's force that relaxes with one time constant while the tool is held
// (viscoelastic tissue): held at the step's pose from its time on, the force is
// force_n + sum_i (exp(-s / tau_i) - 1) relaxing[i].force_n after s seconds.
struct RelaxingForce {
  Vec3 force_n{Vec3::Zero()};  // unit N
  double tau_s{0.0};           // relaxation time, unit s
};
inline constexpr int kMaxRelaxingForces = 8;  // fem::Viscoelastic::kMaxTerms

// What a step returns for one tool.
struct ToolContact {
  bool in_contact{false};
  Vec3 force_n{Vec3::Zero()};            // reaction force on the tool, unit N
  // d(force)/d(tip position) at this pose, unit N/m; viscoelastic tissue: the instantaneous one
  // (an increment of the tip changes the force by K dx at once, and relaxes afterwards).
  Mat3 stiffness_n_per_m{Mat3::Zero()};
  Vec3 normal{Vec3::Zero()};             // contact normal (unit, pointing out of the tissue)
  Vec3 reference_tip_m{Vec3::Zero()};    // the pose the force and stiffness refer to (x0)
  double validity_radius_m{0.0};         // the linear model holds within this distance of x0
  int mesh{-1};                          // mesh index of the (main) contact
  std::vector<int> nodes;                // contact nodes on that mesh
  bool converged{true};                  // the contact LCP met its tolerance
  int iterations{0};
  // With rigid obstacles (the skull): the station's proxy held the tip the physics stepped on the
  // free side of the bone (reference_tip_m is that tip); these are its constraint planes around
  // it, each with the penetration of the device's (raw) tip behind it. count 0 without obstacles.
  ObstaclePlanes rigid_planes;
  Vec3 held_tip_m{Vec3::Zero()};  // the tip the physics stepped (the device's, or held), unit m
  // Viscoelastic main body: the parts of force_n relaxing with its kernel's terms (exact for the
  // pose held with the contact slots' displacement held, viscoelastic_history.hpp); none for an
  // elastic body (the force holds).
  std::array<RelaxingForce, kMaxRelaxingForces> relaxing{};
  int num_relaxing{0};
};

struct StepStats {
  double solve_us{0.0};  // wall time of the step, unit us
  int contact_rows{0};
  // Rows in contact (depth > 0) beyond SimulationOptions::max_contact_nodes_per_tool of a tool,
  // left out of this step's LCP (the deepest are kept), summed over the tools; 0 when every
  // touching row fits. A patch of cells much finer than the tip needs the limit raised.
  int contact_rows_dropped{0};
  bool converged{true};
  // Contact nodes touched for the first time in this step: their coupled compliance columns were
  // computed (block solves, milliseconds) inside the step, on the step's thread. Always 0 with
  // SimulationOptions::column_worker (the worker solves them ahead of the tool).
  int columns_computed{0};
  // column_worker only: contact nodes the step's rows needed whose columns were not ready yet
  // (handled by the fallback of contact_step.cpp's compliance_columns: the row's weight moves to
  // its ready nodes, a row with none is left out of this step). 0 when the worker kept ahead.
  int columns_not_ready{0};
  // LINEAR: LCPs of this step (rows found again on the surface each answer deformed, from rest).
  int geometry_iterations{0};
  // The LCPs' pivots over this step's geometries (warm and cold starts counted), and how many
  // of its LCPs took the warm start's active set (SimulationOptions::lcp_warm_start).
  int lcp_pivots{0};
  int lcp_warm_taken{0};
  int sliding_rows{0};    // unilateral rows of SLIDING couplings in this step's LCP
  int sliding_active{0};  // of which carry a force
  // COROTATIONAL and NONLINEAR with SimulationOptions::tier_worker_thread = false: the tier's
  // equilibrium update ran inside this step (tier_updated) and took tier_update_us of solve_us
  // (unit us); so solve_us - tier_update_us is what the step costs with the worker thread.
  bool tier_updated{false};
  double tier_update_us{0.0};
  // COROTATIONAL and NONLINEAR: elements inverted (det F <= 0) in the tier's newest equilibrium,
  // all bodies (the field displacements() returns): large compression; the answer stays finite.
  // 0 in LINEAR (small strain: no deformed configuration to invert).
  int inverted_elements{0};
  // smoothed-tet in NONLINEAR: elements the element barrier holds in the same equilibrium
  // (fem/element_barrier.hpp: crushed below J = 0.25 or stretched beyond I1 = 6); 0 otherwise.
  int barrier_elements{0};
  // Rest-surface candidate triangles tested in this step for the tools' reusable candidate lists
  // (contact_step.cpp, reusable_candidates: made again once a tool moved a quarter of a mean
  // edge): the candidate search's share of the step, 0 in most steps.
  int candidate_tests{0};
};

// One pair of a SLIDING coupling (server/interaction/sliding_coupling.hpp): B's surface node and
// its closest point on A's new boundary S'. Gap g = n . (sum w u_A - u_B) + g0 >= 0 (g < 0:
// interpenetration); the pair's normal force pushes A along +n and B along -n.
struct SlidingPairState {
  int embedded_node{-1};
  std::array<int, 3> host_nodes{};  // A's node ids (triangle of S')
  std::array<double, 3> weights{};
  Vec3 normal{Vec3::Zero()};  // unit, B's outward surface normal (from B towards A)
  double initial_gap_m{0.0};  // g0 >= 0, unit m
  double force_n{0.0};        // last good step's normal force (>= 0), unit N
};

// What displacement fields are computed from: the last good step's forces on every body.
// Simulation::snapshot fills it on the stepping thread (a copy, no solve);
// Simulation::displacements(snapshot, ...) reads it on any thread and touches nothing step()
// writes, so the server's field thread, neurosim-solve and the tests share one implementation.
struct FieldSnapshot {
  struct Body {
    std::vector<int> slots;              // contact slots carrying a force
    std::vector<Vec3> forces_n;          // per slot, the force on the tissue, unit N
    Eigen::VectorXd sliding_lambda_n;    // per sliding row of the body, normal force, unit N
    Eigen::VectorXd nodal_forces_n;      // optional: any other host nodal forces (3N_A), unit N
    // COROTATIONAL and NONLINEAR tiers: the body's latest equilibrium (host, then its tied
    // meshes), unit m; the fields are taken from it (slots and forces are those of the step).
    Eigen::VectorXd tier_u_m;
    // The host field for these forces (3N_A, unit m), computed on the first request.
    Eigen::VectorXd u_host_m;
    bool host_done{false};
    // The solve scratch of whoever computes the fields (made on the first request).
    std::shared_ptr<fem::SolveWorkspace> workspace;
    // SimulationOptions::field_column_budget_mb: the full columns of recently loaded nodes
    // (field_columns.hpp), kept across snapshots by whoever computes the fields.
    std::shared_ptr<FieldColumns> field_columns;
  };
  std::vector<Body> bodies;  // one per body (Simulation::body_index)
};

// Options the scene does not give (limits, tolerances), with defaults.
struct SimulationOptions {
  // Contact rows per tool at most (the deepest; a row is a node, an edge or a face point).
  int max_contact_nodes_per_tool{32};
  // Compliance in series with each contact row, relative to the row's own (W_ii (1 + eps)):
  // keeps W positive definite when a face row and the node rows of its vertices are nearly
  // dependent (contact_step.cpp); the force changes by about eps relative.
  double contact_row_compliance{1e-8};
  // LINEAR: 1 (the default) finds the rows on the rest surface, as the multirate tiers do: one
  // LCP per step, contact linearized about the configuration the elasticity is (small-strain
  // contact, as in Hertz's solution). More iterates the rows on the surface the step's own answer
  // deformed (rows, LCP, rows on that surface with the rest surface's, LCP, ...) until the same
  // features come out twice, at most this many LCPs per step: kept for comparison only, because
  // under a tool wider than the triangles those rows never settle (the deformed surface wraps the
  // sphere, face rows come and go: 5.9 of 6 geometries per step on the cube's 25 mm tip, the
  // force alternating 10-20 % between them and jumping with the pose), contact_step.cpp.
  int contact_geometry_iterations{1};
  // Spread each contact row's load over the surface around its point, over a radius of
  // contact_spread x the local edge length (ContactSurface::spread: consistent nodal weights of
  // a smooth pressure on the rest triangles, at most 32 nodes), instead of the point's
  // barycentric weights on its triangle: a tip whose contact patch is smaller than a triangle
  // then loads about the same surface wherever in the triangle it lands (a vertex and a face
  // centre differ less), and the row's weights change continuously as it slides. 0: barycentric
  // (dimensionless). The spread fades with the cells' size against the tool part's radius R:
  // full where the local edge is R or more, none at R / 2 and less (the cells resolve the part:
  // the barycentric rows). The tip's rows spread over at least 5/3 R, faded in from nothing at a
  // local edge of R / 2 to full at 3/4 R (contact_step.cpp tip_spread_floor_m; LINEAR's and the
  // tiers' alike; 0 turns it off with the rest). On by default (1, the best measured: the bundled brain's 40 mm slide
  // |F|/depth spread 1.69 at 1 mm and 1.33 at 2 mm with the two options below, against 3.93 /
  // 3.20 with barycentric rows; bench/RESULTS.md, "Contact options: the depth to the flat
  // surface", "The near field of a patch wider than the spread", "The spread fading on cells
  // finer than the tip").
  double contact_spread{1.0};
  // The tip's face rows from the tip centre projected along the normal field interpolated from
  // the surface nodes' normals (ContactSurface project_along_normals: a smooth contact surface
  // over the flat triangles) instead of the closest point of each flat triangle with edge rows
  // between them: the row's point and normal pass continuously across edges and creases (no row
  // entering or leaving with a force). Its depth is the centre's distance to the closest point
  // of the flat surface triangles (contact_step.cpp merge_features), not the height along the
  // tilted interpolated normal, which over a convex ridge or a valley is longer (a shallower
  // row). Where no triangle within reach holds the projection (beside a steep facet whose node
  // normals turn far from its face normal) and the tip has no projected face row on a body, its
  // flat face and edge rows (closest points, their own heights) stand in. The node rows and the
  // shaft's rows are as without.
  bool contact_smooth_normals{true};
  // With contact_spread: the compliance the mesh cannot show under a tip whose contact patch is
  // smaller than the spread, in series with the tip's rows (Hertz's secant compliance at the
  // tip's depth less the half-space's under the patch spread by the rows' loads,
  // contact_step.cpp near_field_of_tool): the force of a tip smaller than the cells approaches
  // the continuum's and converges as they shrink (the term vanishes smoothly as the spread
  // becomes small against the patch: the press on a block graded to 4 / 2 / 1 / 0.5 mm cells,
  // 1 mm deep, 8.3 / 8.8 / 8.7 / 7.2 mN, Sneddon 6.7). On a viscoelastic body it
  // relaxes with the host's kernel, as the mesh's compliance (contact_step.cpp, near_field).
  bool contact_near_field{true};
  // With contact_near_field: the shaft's near field, in series with the shaft's rows on a body
  // as the tip's with the tip's (contact_step.cpp near_field_of_shaft): the capsule's patch under
  // cells wider than it, an elliptic patch across and along the axis (tool_geometry.hpp
  // shaft_patch, patch_near_field). Elastic; not on a relaxing body (the tip's history slot is
  // the tip's force), where the shaft keeps the mesh's compliance alone.
  bool contact_shaft_near_field{true};
  int lcp_max_iterations{200};
  double lcp_tolerance{1e-10};  // relative
  // The contact LCP (without sliding rows) pivots first from the rows active in the last LCP
  // (matched by body, tool and feature); the answer does not depend on it: the active set it
  // ends with is solved again from scratch in row order and taken only if complementary with a
  // margin, else the cold start (the rows that penetrate) decides (active_set_lcp.hpp). false:
  // the cold start only (the same answers, more pivots).
  bool lcp_warm_start{true};
  // Disk cache of each body's boundary operator (keyed by meshes, materials, fixed nodes and the
  // coupling map) and of its host's factor (keyed by the factored stiffness, fem/factor_cache),
  // so a second start skips the factorization and the boundary compliance solves: the same
  // numbers bit for bit. Empty: no cache.
  std::string compliance_cache_dir{};
  // A tool part (tip or shaft) whose centre lies deeper than this below a surface node's patch
  // does not push that node (so a tool that jumps through the body feels a bounded force, at
  // most what this indentation gives), unit m. 0: 0.45 x the smallest extent of the host's
  // bounding box.
  double max_penetration_m{0.0};
  // Candidate rows whose depth is above -candidate_margin x tip radius enter the LCP inactive,
  // so a node the deformation would push into the tool is caught (dimensionless).
  double candidate_margin{0.1};
  // Compute the coupled compliance columns of every contactable node at load (else on first
  // touch, a few ms each).
  bool precompute_contact_columns{false};
  // The step never solves a compliance column: a worker thread (column_worker.hpp) solves the
  // columns of the contact nodes within column_max_tool_speed_m_per_s x column_horizon_s (+ the
  // part's radius) of each tool, nearest first, ahead of the tool; a row whose columns are not
  // ready yet takes the fallback (StepStats::columns_not_ready). The live server sets it; false
  // (the default: tests, neurosim-replay, offline tools) solves first touches inside the step,
  // so the answer depends on the poses alone (a replay equals a live run whose steps reported
  // columns_not_ready = 0).
  bool column_worker{false};
  double column_horizon_s{0.05};              // unit s
  double column_max_tool_speed_m_per_s{0.5};  // unit m/s
  // column_worker: the worker thread's nice value, 0..19 (ColumnWorkerOptions::nice; the server
  // keeps 10, below the step; tests that wait for the worker set 0).
  int column_worker_nice{10};
  // column_worker: columns solved at load, so the first touch of a small body or of the tissue
  // under a rigid opening never waits for the worker: every contact node's when they all fit in
  // this budget, else the nodes within the opening's radius + the widest tool part + the
  // worker's reach of each opening's axis (the surface a tool entering through it reaches first),
  // nearest the axis first, up to the budget, unit MB.
  double column_preload_budget_mb{256.0};
  // column_worker: at most this much column storage per body, unit MB (ContactColumns::
  // bytes_per_slot: 3 x (3s + sliding rows) doubles per node of a body with s contact nodes, so
  // the node count follows from the mesh: 0.85 MB per node on the 3 mm brain). Beyond it the
  // worker evicts the nodes least recently within a tool's reach (never one the step holds); at
  // least the preloaded nodes + two blocks, and raised to the reach of the tools' poses while
  // that is larger (ColumnCacheStats::raised_capacity_slots, logged by the server). 0: no bound.
  double column_cache_budget_mb{1024.0};
  // Keep the full coupled compliance columns of touched nodes (3N x 3 doubles each: 0.4 MB per
  // node on a 25k-tet brain) so displacements() of a host is a sum of columns, not a sparse solve.
  bool cache_full_field_columns{false};
  // Fields from a FieldSnapshot (the server's field thread) of LINEAR contact forces alone (no
  // sliding force, no other nodal force): a sum of the loaded nodes' full columns
  // (field_columns.hpp: solved once per node when a field first needs it, the least recently
  // used evicted) instead of a sparse solve per field; this much memory per body at most, unit
  // MB (3N x 3 doubles per node: 0.37 MB on the bundled brain, 3.9 MB on the 3 mm one). 0: every
  // field is a sparse solve.
  double field_column_budget_mb{256.0};
  // With coupling: remove the host's tetrahedra inside S' (the embedded mesh keeps its volume,
  // paper 2.4); false keeps the host whole and adds the embedded mesh's stiffness on top.
  bool carve_host{true};
  // Couplings with method ITERATIVE (the paper's baseline, never the default): the tie is
  // solved by boundary iteration to this relative tolerance, at most this many iterations.
  double iterative_tolerance{1e-12};
  int iterative_max_iterations{10000};
  // SLIDING couplings. false: the meshes touch at rest, g0 = 0 (the space between S' and B's
  // surface is the fusion's discretization, bridged as a tie bridges it); true: g0 = the normal
  // distance max(0, n . (p - x)) from B's node x to its closest point p on S'.
  bool sliding_geometric_gap{false};
  // A floating embedded mesh (no fixed node) in sliding contact is anchored in its six rigid
  // modes only, by this fraction of its mean diagonal stiffness (dimensionless, > 0).
  double sliding_anchor_ratio{1e-6};
  // The contact LCP may pivot lcp_max_iterations + this x (number of sliding rows) times.
  int lcp_iterations_per_sliding_row{4};
  // Sliding rows in the LCP: true, the inverse of their constant block is computed at load
  // (O(n_s^3)) and each step works on the inactive sliding rows (ContactLcp::set_constant_block);
  // false, the reference path (a factor of the active rows, kept between steps). Same LCP.
  bool sliding_inactive_set{true};
  // With sliding_inactive_set: that path in every step, however few sliding rows are active
  // (otherwise the reference path takes the steps with few; tests).
  bool sliding_inactive_set_always{false};
  // COROTATIONAL and NONLINEAR tiers (tier_equilibrium.hpp): the equilibrium follows the contact
  // forces on a worker thread, as fast as it goes (true: the server; the step never waits), or
  // step() updates it after its LCP (false: deterministic, each step pays a Newton solve; tests
  // and offline replay). Either way a held tool converges to the tier's contact equilibrium.
  bool tier_worker_thread{true};
  // Relative Newton tolerance of those updates (fem::NewtonOptions::tolerance).
  double tier_newton_tolerance{1e-10};
  // Newton steps per update at most (fem::NewtonOptions::step_limit; 0: each update converges).
  // The step and the updates are iterated anyway, so an update need not converge: its fixed
  // point is the same, and a few cheap steps per update refresh the rotations more often (brain,
  // multirate_bench: COROTATIONAL 5 -> 25 updates/s, held force converged in 2 s instead of
  // 23 % off; NONLINEAR ramp error 13 -> 2 %).
  int tier_update_steps{2};
};

// Load-time cost of build(), unit s.
struct SetupStats {
  double load_meshes_s{0.0};
  double factor_s{0.0};
  double fusion_s{0.0};    // inclusion decision + coupling map
  double condense_s{0.0};  // Schur complements of embedded meshes
  double boundary_s{0.0};  // host compliance columns at the new boundary
  double operator_s{0.0};  // coupling operator G
  double columns_s{0.0};   // precomputed contact columns
  double sliding_s{0.0};   // Delassus block of the sliding rows (host and embedded parts)
  double total_s{0.0};
  int boundary_nodes{0};  // host nodes on S' used by the ties (all couplings)
  int tied_nodes{0};      // embedded nodes tied (all couplings)
  int exposed_nodes{0};   // embedded surface nodes outside their host, left untied
  int carved_tets{0};     // host tetrahedra removed inside S' (carve_host)
  int cache_hits{0};      // bodies whose boundary operator came from compliance_cache_dir
  int factor_cache_hits{0};  // bodies whose host factor came from compliance_cache_dir
  double factor_bytes{0.0};  // the host factors' values and structure (all bodies), unit byte
  int sliding_rows{0};    // unilateral rows of SLIDING couplings (all couplings)
};

// The physics split as MuJoCo splits mjModel and mjData: a constant Model built once from the
// scene (meshes, factorizations, coupling operators, contact geometry, tool shapes) and a State
// holding everything a step changes (contact rows, LCP warm start and factor, forces, last good
// answer, the contact-compliance cache). Defined in simulation.cpp; Simulation below owns one of
// each and is what the service and the tools call.
class Model;
class State;
struct StateDeleter {
  void operator()(State* state) const;
};
using StatePtr = std::unique_ptr<State, StateDeleter>;
// Throws as Simulation::build does. Shared: one constant Model may serve several States.
std::shared_ptr<const Model> build_model(const scene::Model& model,
                                         const SimulationOptions& options = {});
// A fresh State for `model` (precomputed contact columns and the constant sliding block when the
// options ask for them). The model must outlive it.
StatePtr make_state(const Model& model);
// One step for all tools at once (several stations feel each other): poses in, one result per
// tool out (contacts.size() == poses.size()). Writes only `state`; no allocation once warmed up.
void step(const Model& model, State& state, const std::vector<ToolPose>& poses,
          std::vector<ToolContact>& contacts, StepStats& stats);
// The same at the poses' sample time (unit s): time enters the step of a viscoelastic body (the
// time since the last converged step); step() above takes one step period (1 / rates.step_hz)
// after the last step.
void step_at(const Model& model, State& state, double time_s, const std::vector<ToolPose>& poses,
             std::vector<ToolContact>& contacts, StepStats& stats);

class Simulation {
 public:
  // Builds only what model.effects asks for (no coupling → no inclusion decision, ...).
  // Throws std::runtime_error naming the scene file and the mesh/coupling on bad input, and for
  // an elasticity tier this build does not implement (never runs another tier instead).
  static std::unique_ptr<Simulation> build(const scene::Model& model,
                                           const SimulationOptions& options = {});
  // A Simulation with a fresh State on a Model built before (build_model): several runs of one
  // scene (benchmarks, test suites) pay the load-time solves once.
  static std::unique_ptr<Simulation> from_model(std::shared_ptr<const Model> model);
  virtual ~Simulation() = default;

  virtual int num_meshes() const = 0;
  virtual const std::string& mesh_id(int mesh) const = 0;
  virtual const mesh::TetMesh& mesh(int mesh) const = 0;

  // One step for all tools at once (several stations feel each other): poses in, one result
  // per tool out (contacts.size() == poses.size()). No allocation once warmed up.
  virtual void step(const std::vector<ToolPose>& poses, std::vector<ToolContact>& contacts,
                    StepStats& stats) = 0;
  // The same at the poses' sample time, unit s (a viscoelastic body's history advances by the
  // time since the last converged step; step() takes one step period after it). Replay and the
  // live server both pass sample times. Default (test doubles): step().
  virtual void step_at(double time_s, const std::vector<ToolPose>& poses,
                       std::vector<ToolContact>& contacts, StepStats& stats) {
    (void)time_s;
    step(poses, contacts, stats);
  }

  // Displacement of every vertex of `mesh` for the last step's contact and coupling forces
  // (3N, unit m); one sparse solve per mesh, only when someone asks. A host with
  // cache_full_field_columns sums cached columns instead of solving; an embedded mesh takes its
  // host's field on the tied nodes plus one solve for its interior. Reads what step() writes:
  // call it from the stepping thread (or use a snapshot).
  virtual void displacements(int mesh, Eigen::VectorXd& u_m) const = 0;
  // The last good step's forces, copied (stepping thread; no solve, no allocation once sized).
  // Defaults (test doubles without bodies): an empty snapshot.
  virtual void snapshot(FieldSnapshot& s) const { s.bodies.clear(); }
  // Displacement of `mesh` for the forces of `s` (3N, unit m): the same fields as above, from
  // any thread (never reads the step's state or its caches); the host field of a body is solved
  // once per snapshot and serves the host and its tied meshes. Default (test doubles): the
  // stepping-thread path.
  virtual void displacements(FieldSnapshot& s, int mesh, Eigen::VectorXd& u_m) const {
    (void)s;
    displacements(mesh, u_m);
  }
  // The body `mesh` belongs to (index into FieldSnapshot::bodies), -1 if inert.
  virtual int body_index(int mesh) const { (void)mesh; return -1; }
  // The ITERATIVE baseline: the iterations the coupling of `mesh`'s body needed for the contact
  // columns computed so far (counted in the State, never in the Model). Default: none.
  virtual IterativeReport iterative_report(int mesh) const { (void)mesh; return {}; }

  // Meshes that take part: a mesh with no fixed node that is not tied to a host (e.g. the
  // embedded mesh with coupling off) is inert: never touched, displacement zero.
  virtual bool mesh_active(int mesh) const = 0;
  // Largest tie mismatch |sum w u_A - u_B| over every tied node for the last step, unit m
  // (full-field solves: for tests and benchmarks).
  virtual double tie_residual_m() const = 0;
  virtual const SetupStats& setup_stats() const = 0;
  // Fixed nodes of `mesh` (sorted): the scene's, plus, on a carved host, the nodes left without
  // a tetrahedron inside the embedded mesh. mesh(m) is the carved mesh (same vertex ids).
  virtual const std::vector<int>& fixed_nodes(int mesh) const = 0;
  virtual int num_tools() const = 0;
  // The scene's rigid obstacles the step holds each station's tool outside of (a proxy per
  // station in the State), or nullptr (none, or effects.tool_contact off); and how far the
  // proxies look around the tool each step, unit m. Defaults (test doubles): none.
  virtual const RigidObstacle* rigid_obstacle() const { return nullptr; }
  virtual double proxy_reach_m() const { return 0.0; }
  // Forget a station's proxy (the station left, or its pose was refused): its next pose starts
  // afresh (free if outside the bone). Default: nothing to forget.
  virtual void reset_station(int station) { (void)station; }
  // The body (host + tied meshes) `mesh` belongs to, or nullptr if inert; and the last good
  // step's contact forces on it (contact slots, unit N; on a relaxing body the creep-equivalent
  // forces, the elastic forces that give its displacement). For benchmarks and the baseline.
  virtual const CoupledBody* body_of(int mesh) const = 0;
  virtual void last_contact_forces(int mesh, std::vector<int>& slots,
                                   std::vector<Vec3>& forces_n) const = 0;
  // SLIDING couplings: the pairs of the coupling whose embedded mesh is `mesh` with the last good
  // step's forces (empty if `mesh` is not embedded by SLIDING). Defaults (for implementations
  // without sliding couplings, e.g. test doubles): none.
  virtual void sliding_pairs(int /*mesh*/, std::vector<SlidingPairState>& pairs) const {
    pairs.clear();
  }
  // Largest interpenetration max(0, -g) over every sliding pair for the last step, unit m
  // (full-field solves: for tests and benchmarks).
  virtual double sliding_penetration_m() const { return 0.0; }
  // Solves on a solver's own (locked) workspace in the Model since construction, over every
  // body's host solver, tied interior and sliding compliance: set-up only. Steps and fields
  // (the State's and a FieldSnapshot's scratch) never add to it.
  virtual std::uint64_t shared_workspace_uses() const { return 0; }

  // SimulationOptions::column_worker: contact nodes whose columns were not ready when a step's
  // rows needed them, summed over the steps since build (StepStats::columns_not_ready); columns
  // the worker solved ahead of the tools; and (tests, benchmarks) a wait until every column
  // within reach of the last step's poses is ready (false: timeout, or no worker). Stepping
  // thread, except columns_solved_ahead (any thread).
  virtual std::uint64_t columns_not_ready() const { return 0; }
  // Steps since build that left touching contact rows out (StepStats::contact_rows_dropped > 0)
  // and steps whose contact LCP did not converge within SimulationOptions::lcp_max_iterations
  // (StepStats::converged false: the last good answer was kept). Stepping thread.
  virtual std::uint64_t steps_with_rows_dropped() const { return 0; }
  virtual std::uint64_t steps_not_converged() const { return 0; }
  virtual std::uint64_t columns_solved_ahead() const { return 0; }
  virtual bool wait_columns_ready(double timeout_s) const {
    (void)timeout_s;
    return false;
  }
  // The contact-compliance cache of the host of mesh `m` (column_worker's bound; any thread).
  struct ColumnCacheStats {
    std::size_t ready_slots{0};     // contact nodes with columns now
    std::size_t capacity_slots{0};  // the bound (0: none)
    std::size_t bytes_per_slot{0};  // unit byte
    std::uint64_t evicted{0};       // nodes freed so far
    // The bound below one post's reach (more contact nodes within the worker's reach of the
    // tools than capacity_slots): the largest reach the worker raised it to, else 0.
    std::size_t raised_capacity_slots{0};
  };
  virtual ColumnCacheStats column_cache(int m) const {
    (void)m;
    return {};
  }
  // Tests: hold the column worker (a solve under way finishes, none starts) or let it go.
  virtual void pause_column_worker(bool paused) { (void)paused; }

  // The elasticity tier that runs (the scene's effects.tier; never another one).
  virtual scene::Tier tier() const { return scene::Tier::kLinear; }
  // COROTATIONAL and NONLINEAR: equilibrium updates (the tier's field and the rotations the
  // contact compliance is warped by) completed per second over the last second, unit Hz; 0 for
  // LINEAR (nothing to update). Any thread.
  virtual double tier_update_rate_hz() const { return 0.0; }
  // COROTATIONAL and NONLINEAR: every equilibrium update since build and their summed time, unit
  // s (TierWorker::totals; a mean rate over any span of updates, e.g. a bench's whole press);
  // {0, 0} for LINEAR. Any thread.
  struct TierUpdateTotals {
    std::uint64_t updates{0};
    double busy_s{0.0};
  };
  virtual TierUpdateTotals tier_update_totals() const { return {}; }
  // Equilibrium updates that failed since build (Newton did not converge, a malformed load): the
  // previous equilibrium stays; and the last failure's message (empty: none). Any thread.
  virtual std::uint64_t tier_update_failures() const { return 0; }
  virtual std::string tier_last_error() const { return {}; }
};

}  // namespace neurosim::interaction
