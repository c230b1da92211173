// A host mesh A with the embedded meshes B tied to it (paper 2.3/2.6, Eq. 5-6), solved exactly.
//
// Formulation (exact, no regularization, also when B floats): every free surface node k of B is
// tied to its closest point on A's new boundary S' (barycentric weights w), u_B,k = sum w u_A.
// Each B is condensed onto its tied nodes (TieCondensation, tie_condensation.hpp) and adds the
// stiffness K_add = J^T S_B J on A's boundary dofs b. The coupled compliance is then, by
// Woodbury, L = L_A - L_A[:,b] G L_A[b,:] with G = (I + K_add L_bb)^-1 K_add, the coupling
// operator factored once at load. The tie holds to round-off by construction: B's tied nodes
// take the interpolated displacement of A, and B's interior follows from K_ii.
#pragma once

#include "server/fem/material.hpp"
#include "server/fem/static_solver.hpp"
#include "server/interaction/boundary_cache.hpp"
#include "server/interaction/iterative_tie.hpp"
#include "server/interaction/sliding_coupling.hpp"
#include "server/interaction/sliding_operator.hpp"
#include "server/interaction/tie_condensation.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::interaction {

struct CoupledBodyTiming {
  double factor_s{0.0};    // host assembly + factorization (or its read from the cache), unit s
  double boundary_s{0.0};  // compliance columns of A at S' and rows at the contact nodes, unit s
  double condense_s{0.0};  // Schur complements of the embedded meshes, unit s
  double operator_s{0.0};  // K_add and the factored coupling operator G, unit s
  double sliding_s{0.0};   // coupled compliance W_A over the sliding rows, unit s
};

class CoupledBody {
 public:
  // host_fixed must hold enough nodes to remove A's rigid modes (StaticSolver checks).
  // solver_options: the host's StaticSolver's (SolverOptions::factor_cache_dir: the factor's
  // disk cache).
  CoupledBody(int host_index, const mesh::TetMesh& host, const fem::Material& material,
              const std::vector<int>& host_fixed, const fem::SolverOptions& solver_options = {});

  // Adds an embedded mesh tied through the map (B's surface node -> S' triangle of A, weights):
  // condensed onto its tied nodes at once (TieCondensation; throws what its constructor throws).
  void add_tie(const TieDefinition& tie);

  // Host faces an embedded mesh covers (before finalize; a coupling's S', any orientation and
  // order; the calls accumulate): never contactable. On a carved host they are the surface of the
  // cavity (an enclosed mesh) or the groove under a mesh that leaves the host; the host's faces
  // around them stay contactable, also where their nodes are on S' (the ring around a vessel's
  // exit).
  void cover_faces(const std::vector<mesh::Tri>& faces);
  // The covered faces' node triples, each sorted, sorted (after finalize).
  const std::vector<std::array<int, 3>>& covered_faces() const { return covered_faces_; }

  // Tool contact on tie `tie`'s exposed part (before finalize; LINEAR and NONLINEAR tiers):
  // outside has one entry per node of that mesh, 1 for a surface node outside the host
  // (fusion::Exposure). Its surface faces with a node outside become contactable, and their
  // free nodes contact slots after the host's (see contact_point); their columns are the tied
  // system's (the unit force on B reaches A through TieCondensation::add_equivalent_host_loads).
  void expose_tie(int tie, const std::vector<char>& outside);
  // Tool contact on the exposed part of a SLIDING-coupled mesh (before finalize; LINEAR tier):
  // `slide` is its index among the body's sliding couplings (BodyModel::slides), `first_row`
  // the index of its first row among the body's sliding rows (add_sliding_rows' return), outside
  // as for expose_tie. Its contact slots come after the exposed ties'; B is not part of the
  // coupled compliance: a column of a slot on B is B's own L_B[:, node] (EmbeddedCompliance, zero
  // on A and the ties) and reaches A only through the sliding rows (contact_rows' `sliding`:
  // J_B L_B[:, node], row k -n_k . L_B(k, node)). `coupling` must outlive the body.
  void expose_slide(int slide, const SlidingCoupling& coupling, int first_row,
                    const std::vector<char>& outside);

  // Registers the host side of sliding rows (before finalize; the rows of all calls are stacked,
  // returns the index of the first one). Finalize builds
  // the sliding operator over them (sliding()). Throws std::invalid_argument on a bad row
  // (check_sliding_rows; what: for messages).
  int add_sliding_rows(const std::vector<HostSlidingRow>& rows, const std::string& what);
  // After finalize: the stacked rows, J_A on the free dofs, W_A = J_A L J_A^T with the coupled
  // compliance L (ties included); contact columns add J_A L[:, slot] through it.
  const SlidingOperator& sliding() const { return sliding_; }
  // Coupled host displacement (ties included) for arbitrary nodal forces (3N_A, unit N), unit m.
  // Two sparse solves when the body has ties, one otherwise; the matrix form solves all its
  // columns (3N_A x k load cases) as one block.
  // ws: the caller's solve scratch; null uses the host solver's own, locked one (set-up, offline).
  void coupled_displacement(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_host_m,
                            fem::SolveWorkspace* ws = nullptr) const;
  void coupled_displacement(const Eigen::MatrixXd& forces_n, Eigen::MatrixXd& u_host_m,
                            fem::SolveWorkspace* ws = nullptr) const;

  // Coupled displacement of A (3N_A) and of tied mesh ties()[tie] (3N_B), unit m, for forces on
  // that mesh's nodes (3N_B, unit N), e.g. a press on its exposed, untied part: the tie's
  // equivalent load on A (TieCondensation::add_equivalent_host_load), one coupled solve, then
  // B's interior with the forces. Set-up and offline (the solvers' own, locked workspaces).
  void tied_mesh_displacement(int tie, const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_host_m,
                              Eigen::VectorXd& u_embedded_m) const;

  // Directory of the disk cache of the boundary operator (L_bb, L_cb, K_add, G), keyed by a
  // hash of both meshes, materials, fixed nodes and the coupling map; empty: no cache.
  void set_cache_dir(std::string dir) { cache_dir_ = std::move(dir); }
  // After the last add_tie: boundary compliance, coupling operator, contact rows of L_A at b
  // (read from the cache when a file with the same key exists, else computed and stored).
  void finalize();
  bool cache_hit() const { return cache_hit_; }

  // Baseline instead of the factored operator (before finalize): G is applied by the
  // paper-style iteration on the boundary (IterativeTie::apply, built at finalize). Results then
  // differ from the exact ones by about the tolerance; for comparison only.
  void set_iterative(const IterativeOptions& options);
  // Counters of the iterations so far (all zero for the exact operator).

  int host_index() const { return host_index_; }
  const mesh::TetMesh& host() const { return *host_; }
  const fem::StaticSolver& host_solver() const { return *solver_; }
  // The tied meshes in the order of add_tie: their maps, condensed stiffness and displacement.
  const std::vector<TieCondensation>& ties() const { return ties_; }
  const std::vector<int>& boundary_nodes() const { return boundary_nodes_; }  // A ids, sorted

  // Contactable points (after finalize): A's free surface nodes on at least one surface face
  // that is not covered (A ids ascending) and their outward unit normals (area-weighted over the
  // uncovered surface faces); then, with exposed ties (expose_tie), each exposed tie's free
  // surface nodes on a face with a node outside A (B ids ascending, tie by tie), with normals
  // area-weighted over those faces. Node ids are contact_mesh()'s: A's own, then B's shifted by
  // tie_vertex_offset(tie).
  const std::vector<int>& contact_nodes() const { return contact_nodes_; }
  const std::vector<mesh::Vec3>& contact_normals() const { return contact_normals_; }
  int contact_slot(int contact_mesh_node) const { return contact_slot_[contact_mesh_node]; }
  // Slots [0, num_host_contact()) are A's nodes, the rest an exposed tie's.
  int num_host_contact() const { return num_host_contact_; }
  // The mesh and node of a slot: tie and slide -1 for A (node: A's id); else on an exposed tie
  // (tie: its index, slide -1) or an exposed sliding mesh (slide: its index as in expose_slide,
  // tie -1), node: that mesh's id.
  struct ContactPoint {
    int tie{-1};
    int node{-1};
    int slide{-1};
  };
  ContactPoint contact_point(int slot) const {
    if (slot < num_host_contact_) return ContactPoint{-1, contact_nodes_[slot], -1};
    const int e = slot - num_host_contact_;
    const int tie = contact_tie_[e], slide = contact_slide_[e];
    const int offset = tie >= 0 ? tie_offset_[tie] : exposed_slides_[slide].offset;
    return ContactPoint{tie, contact_nodes_[slot] - offset, slide};
  }
  // The slot's part of the body: -1 the host, t < ties().size() tie t, else an exposed sliding
  // mesh (ties().size() + its slide index); num_parts() bounds it. part_mesh: the scene mesh.
  int contact_part(int slot) const {
    const ContactPoint p = contact_point(slot);
    return p.slide >= 0 ? static_cast<int>(ties_.size()) + p.slide : p.tie;
  }
  int num_parts() const { return static_cast<int>(ties_.size() + exposed_slides_.size()); }
  int part_mesh(int part) const;
  bool has_exposed_contact() const { return num_host_contact_ < static_cast<int>(contact_nodes_.size()); }
  // Some slot lies on an exposed sliding mesh (expose_slide).
  bool has_exposed_slide() const { return exposed_slide_slots_; }
  // The mesh the contact geometry lives on: A itself, or with exposed ties and sliding meshes A
  // and those meshes in one vertex numbering (a tie's vertex v is tie_vertex_offset(tie) + v, a
  // sliding mesh's slide_vertex_offset(slide) + v).
  const mesh::TetMesh& contact_mesh() const { return contact_mesh_ ? *contact_mesh_ : *host_; }
  int tie_vertex_offset(int tie) const { return tie_offset_.at(static_cast<std::size_t>(tie)); }
  int slide_vertex_offset(int slide) const {
    return exposed_slides_.at(static_cast<std::size_t>(slide)).offset;
  }
  // The SLIDING coupling of an exposed sliding mesh (expose_slide), null if `slide` is not one.
  const SlidingCoupling* exposed_slide(int slide) const {
    return slide >= 0 && slide < static_cast<int>(exposed_slides_.size())
               ? exposed_slides_[static_cast<std::size_t>(slide)].coupling
               : nullptr;
  }
  // Faces of contact_mesh() never contactable (sorted triples, sorted): covered_faces() and the
  // exposed ties' surface faces with no node outside A.
  const std::vector<std::array<int, 3>>& contact_excluded_faces() const {
    return contact_mesh_ ? contact_excluded_faces_ : covered_faces_;
  }
  // Fixed nodes of contact_mesh() (sorted): A's and the exposed ties' own, shifted.
  const std::vector<int>& contact_fixed_nodes() const { return contact_fixed_nodes_; }
  // Host load (3N_A, +=) of forces on contact slots (force_n per slot, unit N): on A's nodes
  // directly, on a tie's through its equivalent load. ws: the caller's solve scratch.
  void add_contact_loads(const std::vector<int>& slots, const std::vector<mesh::Vec3>& forces_n,
                         Eigen::VectorXd& host_load_n, fem::SolveWorkspace* ws = nullptr) const;
  // The forces (3N_B) those slots put on tie `tie`'s own nodes; false if none.
  bool tie_contact_forces(int tie, const std::vector<int>& slots,
                          const std::vector<mesh::Vec3>& forces_n, Eigen::VectorXd& forces_b) const;
  // The forces (3N_B) those slots put on exposed sliding mesh `slide`'s nodes; false if none.
  bool slide_contact_forces(int slide, const std::vector<int>& slots,
                            const std::vector<mesh::Vec3>& forces_n,
                            Eigen::VectorXd& forces_b) const;
  // Displacement rows at every contact slot (3S x 3n, unit m/N) of the columns x (free dofs x 3n)
  // solve_contact_columns gave for `slots`: A's slots read from x, a tie's slots from B's
  // displacement (A's field and, for a column of a slot on B, its unit force), an exposed
  // sliding mesh's from L_B (its own columns only; zero elsewhere). sliding (optional, with
  // exposed sliding meshes): the sliding rows' part of each column on a sliding mesh, J_B L_B
  // (sliding rows x 3n; zero for the other columns, whose part is sliding().apply(x)).
  void contact_rows(const std::vector<int>& slots, const Eigen::MatrixXd& x, Eigen::MatrixXd& rows,
                    fem::SolveWorkspace* ws = nullptr, Eigen::MatrixXd* sliding = nullptr) const;

  // Coupled compliance columns for unit forces at the given contact slots: X (free dofs x 3n,
  // the reduced index of host_solver()), one block solve (ContactColumns caches them).
  // With `ws` (the caller's: a State's ContactColumns) the solve locks nothing; without, it
  // uses the host solver's own workspace under its mutex (set-up, offline).
  // `iterations` (ITERATIVE baseline only) gets the iterations the coupling needed.
  void solve_contact_columns(const std::vector<int>& slots, Eigen::MatrixXd& x,
                             fem::SolveWorkspace* ws = nullptr,
                             IterativeReport* iterations = nullptr) const;
  // Unit right-hand sides per CHOLMOD block solve (BLAS-3 inside the supernodes).
  static constexpr int kBlockColumns = 63;

  // Host displacement (3N_A, unit m) for nodal forces on contact slots (force_n per slot, unit
  // N), ties included; a tied mesh's displacement follows from it (ties()[t].displacement).
  // `ws` as for solve_contact_columns (the field thread's and the tier worker's own).
  void host_displacement(const std::vector<int>& slots, const std::vector<mesh::Vec3>& forces_n,
                         Eigen::VectorXd& u_host_m, fem::SolveWorkspace* ws = nullptr) const;

  const CoupledBodyTiming& timing() const { return timing_; }
  // Boundary blocks (for the iterative baseline): L_A[b,b], K_add, rows of L_A at contact x b.
  const Eigen::MatrixXd& boundary_compliance() const { return op_.l_bb; }
  const Eigen::MatrixXd& boundary_stiffness() const { return op_.k_add; }
  const Eigen::MatrixXd& contact_boundary_compliance() const { return op_.l_sb; }
  // Host-only compliance L_A(i, j) of contact slots (3x3), from one solve per call (reference).
  Eigen::Matrix3d host_block(int slot_i, int slot_j) const;

 private:
  int host_index_{-1};
  const mesh::TetMesh* host_{nullptr};
  std::unique_ptr<fem::StaticSolver> solver_;
  std::vector<TieCondensation> ties_;
  std::vector<int> boundary_nodes_;
  std::vector<int> boundary_slot_;  // A node -> slot in boundary_nodes_ or -1
  std::vector<int> contact_nodes_;
  std::vector<int> contact_slot_;  // A node -> contact slot or -1
  std::vector<mesh::Vec3> contact_normals_;
  int num_host_contact_{0};
  std::vector<std::vector<char>> exposed_;  // per tie: expose_tie's flags (empty: not exposed)
  std::vector<int> tie_offset_;             // per tie: its vertex offset in contact_mesh_
  std::vector<int> contact_tie_;            // per slot beyond the host's: its tie or -1
  std::vector<int> contact_slide_;          // per slot beyond the host's: its slide or -1
  struct ExposedSlide {
    const SlidingCoupling* coupling{nullptr};  // null: that slide is not exposed
    int first_row{0};
    std::vector<char> outside;
    int offset{-1};  // its vertex offset in contact_mesh_
  };
  std::vector<ExposedSlide> exposed_slides_;  // indexed by slide (expose_slide)
  bool exposed_slide_slots_{false};
  // The exposed meshes' rows of the columns on sliding meshes (contact_rows).
  void slide_rows(const std::vector<int>& slots, Eigen::MatrixXd& rows, fem::SolveWorkspace* ws,
                  Eigen::MatrixXd* sliding) const;
  std::unique_ptr<mesh::TetMesh> contact_mesh_;  // A + the exposed ties (null: A alone)
  std::vector<std::array<int, 3>> contact_excluded_faces_;
  std::vector<int> contact_fixed_nodes_;
  void select_exposed_contact_nodes();
  // Unit right-hand sides (free dofs x 3) of the slots on ties, i.e. their equivalent loads.
  void tie_slot_loads(const std::vector<int>& slots, Eigen::MatrixXd& rhs,
                      fem::SolveWorkspace* ws) const;
  BoundaryOperator op_;  // L_bb, L_cb, K_add, G (boundary_cache.hpp)
  std::vector<HostSlidingRow> sliding_rows_;  // added before finalize, then moved to sliding_
  std::vector<std::array<int, 3>> covered_faces_;  // sorted triples, sorted at finalize
  SlidingOperator sliding_;
  // X = coupled L B for free-dof right-hand sides (ties by Woodbury: two solves; the ITERATIVE
  // baseline's iterations counted in `iterations`, if given).
  void coupled_solve_reduced(const Eigen::MatrixXd& b, Eigen::MatrixXd& x,
                             fem::SolveWorkspace* ws = nullptr,
                             IterativeReport* iterations = nullptr) const;
  CoupledBodyTiming timing_;
  bool finalized_{false};
  fem::Material material_;
  std::string cache_dir_;
  bool cache_hit_{false};
  bool iterative_requested_{false};
  IterativeOptions iterative_options_;
  std::unique_ptr<IterativeTie> iterative_;  // the baseline, built at finalize (null: exact G)
  // out = G in (exact) or its iterative approximation.
  void apply_coupling(const Eigen::MatrixXd& in, Eigen::MatrixXd& out,
                      IterativeReport* iterations = nullptr) const;
  void select_contact_nodes();
  void compute_boundary_operator();
  std::uint64_t cache_key() const;
};

// Area-weighted outward vertex normals of a mesh's surface (unit; zero where no face).
std::vector<mesh::Vec3> surface_vertex_normals(const mesh::TetMesh& mesh);

}  // namespace neurosim::interaction
