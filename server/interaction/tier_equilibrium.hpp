// A body (host + tied meshes) in the COROTATIONAL or NONLINEAR tier, seen by the 1 kHz contact
// step through a linearization of its latest static equilibrium (multirate compliance warping:
// Saupin, Duriez, Cotin, Grisoni 2008; SOFA's PrecomputedConstraintCorrection with rotations).
//
//   slow (worker): u* = the tier's equilibrium under the contact forces f* of a recent step
//                  (fem::EquilibriumSolver: Newton on host and tied meshes in one system, ties
//                  eliminated exactly, warm-started from the previous answer);
//   fast (step):   the contact LCP on the body's linear coupled compliance C warped by per-node
//                  rotations R taken from u*:  u(f) ~ u0 + R C R^T f,  u0 = u* - R C R^T f*.
//
// For the forces f* the model gives u* exactly, so the step and the updates form a fixed-point
// iteration whose fixed point is the tier's own contact equilibrium (the warping sets how fast it
// converges, not where). Per contact slot s the step reads the rotation R_s (a row with normal n
// acting on slots a, b by weights w: W_rs = sum w_a w_b (R_a^T n_r) . C_ab (R_b^T n_s)) and the
// offset u0_s (depth_r + n_r . sum w_a u0_a). R_s: the polar rotation of
// the mean deformation gradient of the host tetrahedra around the slot's node.
//
// Slots on an exposed tied mesh (CoupledBody::expose_tie) are that mesh's nodes in the stacked
// equilibrium: their forces load its dofs (the solver's tie elimination carries a force on a tied
// node to the host), their rotations come from its tetrahedra, and their columns C are the tied
// system's (the LINEAR tier's, ContactColumns).
//
// The contact rows are those of the rest surface, their depth and forces taken in the reference
// configuration (forces along the rows' normals as dead loads), so the tiers differ only in the
// elasticity.
//
// Relaxing tissue (a mesh whose material has viscoelastic terms; NONLINEAR tier, linear-tet):
// quasi-linear viscoelasticity (fem/quasi_linear_viscoelastic.hpp), internal variables per
// element. Time enters the equilibrium: each update is the QLV equilibrium at its load's time
// (TierLoad::time_s, the step's sample time) from the internal variables committed at the
// previous update, which it then advances (dt = the time between the loads of two consecutive
// updates; an update at the time of the last one replaces it). The fixed point of the step and
// the updates therefore moves in time: while the tool moves, the history integrates the
// updates' iterates (each the equilibrium under the worker's relaxed forces, converged or cut
// short by the step limit); a held tool's forces converge, at each instant, to the viscoelastic
// contact equilibrium, and with time to the relaxed one (the hyperelastic answer with every
// modulus scaled by g_inf, exact for the stated model).
#pragma once

#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/quasi_linear_viscoelastic.hpp"
#include "server/fem/material.hpp"
#include "server/fem/tier.hpp"
#include "server/interaction/contact_columns.hpp"
#include "server/interaction/coupled_body.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace neurosim::interaction {

// Contact forces on a body: per contact slot carrying one, the force on the tissue, unit N.
struct TierLoad {
  std::vector<int> slots;
  std::vector<mesh::Vec3> forces_n;
  std::uint64_t linearization{0};  // TierLinearization::count of the model they were found with
  double time_s{0.0};  // the step's time (its poses' sample time), unit s; relaxing bodies only
};

// What the contact step reads of a body's latest equilibrium.
struct TierLinearization {
  std::vector<mesh::Vec3> offset_m;       // per contact slot: u0 at its node, unit m
  std::vector<mesh::Vec3> warped_normal;  // per contact slot: R^T n (unit)
  std::vector<Eigen::Matrix3d> rotation;  // per contact slot: R (a row's normal n -> R^T n)
  // Per contact slot: u* at its node (the host's, or an exposed tied mesh's: its stacked dofs,
  // TierEquilibrium::slot_dof), unit m.
  std::vector<mesh::Vec3> displacement_m;
  // The equilibrium: host (3 N_A) then each tied mesh (TierEquilibrium::body_offset), unit m.
  Eigen::VectorXd u_m;
  TierLoad load;             // the forces u_m is the equilibrium of
  int iterations{0};         // Newton iterations of the update (0 at rest)
  int inverted_elements{0};  // elements of the body with det F <= 0 in u_m
  // smoothed-tet in NONLINEAR: elements of the body the element barrier holds in u_m
  // (fem/element_barrier.hpp; 0 for the other elements and tiers).
  int barrier_elements{0};
  // The update met the Newton tolerance (false: cut short by NewtonOptions::step_limit; the
  // worker continues it even when the forces no longer change).
  bool converged{true};
  // The equilibrium's own residual at u_m: max |f_ext - f_int| over the free dofs after the
  // update's last Newton step (0 at rest), unit N. Below NewtonOptions::tolerance x the force
  // scale when converged; the worker compares it with the contact forces' change (TierWorker).
  double residual_n{0.0};
  std::uint64_t count{0};  // updates of this body so far
};

// The static equilibrium problem of a body in `tier`: its (carved) host with its supports and
// every tied mesh, ties eliminated exactly (no load, nothing prescribed).
fem::EquilibriumDefinition equilibrium_definition(const CoupledBody& body,
                                                  const fem::Material& host_material,
                                                  const std::vector<int>& host_fixed_nodes,
                                                  fem::Tier tier);

struct TierEquilibriumDefinition {
  const CoupledBody* body{nullptr};  // finalized, exact ties, no sliding rows; must outlive
  fem::Material host_material;
  std::vector<int> host_fixed_nodes;  // of the (carved) host
  fem::Tier tier{fem::Tier::kNonlinear};
  fem::NewtonOptions newton{};
  // The linearization's C R^T f* at the contact slots (u0 = u* - R C R^T f*) is a sum of the
  // loaded slots' coupled compliance columns at the contact nodes (ContactColumns, the worker's
  // own: solved once per slot when first loaded, 3 s x 3 doubles per slot for s contact slots),
  // kept up to this many bytes, the least recently loaded evicted. A load on more slots than
  // fit, or 0: one coupled solve of the host per update (CoupledBody::host_displacement), as
  // before. Same answer to round-off (tier_equilibrium_test). Unit byte.
  std::size_t column_budget_bytes{std::size_t{64} << 20};
};

class TierEquilibrium {
 public:
  // Throws std::invalid_argument for a linear tier, a body with sliding rows or an iterative
  // tie, and what fem::EquilibriumSolver throws.
  explicit TierEquilibrium(const TierEquilibriumDefinition& def);
  ~TierEquilibrium();
  TierEquilibrium(const TierEquilibrium&) = delete;
  TierEquilibrium& operator=(const TierEquilibrium&) = delete;

  // The linearization at rest: u* = 0, R = I, u0 = 0 (the linear model until the first update).
  void rest(TierLinearization& out) const;
  // The equilibrium for `load`, warm-started from the previous one (Newton at full load; when
  // that fails, the load path from rest in increments), and its linearization. Throws
  // std::runtime_error (naming the body) when the tier does not converge; `out` and the warm
  // start are then unchanged. A load without force on a body that does not relax is the rest
  // state, exactly (u* = 0, no Newton iteration). One thread at a time.
  void update(const TierLoad& load, TierLinearization& out);

  int num_slots() const { return static_cast<int>(slot_dof_.size()); }  // contact slots
  // A contact slot's first dof in the stacked equilibrium (host 3 N_A, then each tied mesh's
  // 3 N_B): the host's node, or a node of an exposed tied mesh (CoupledBody::contact_point).
  int slot_dof(int slot) const { return slot_dof_.at(static_cast<std::size_t>(slot)); }

  // Phase "linearization" of update() for the equilibrium it holds (u*) under `load` (its forces
  // f*): per contact slot the rotation R, the warped normal and the offset u0 = u* - R C R^T f*
  // into `out` (offset_m, warped_normal, rotation; nothing else of it). Allocates nothing once
  // `out` is sized and the load's slots have their columns (a held tool). Public for the tests.
  void linearize(const TierLoad& load, TierLinearization& out);
  // The compliance columns kept for the linearization: at most column_capacity() slots (0: no
  // columns, every linearization solves), kept now, solved and evicted so far; and the
  // linearizations made by a coupled solve instead (a load on more slots than the capacity).
  std::size_t column_capacity() const { return column_capacity_; }
  std::size_t columns_kept() const { return kept_.size(); }
  std::uint64_t columns_solved() const { return columns_solved_; }
  std::uint64_t columns_evicted() const { return columns_ ? columns_->evicted() : 0; }
  std::uint64_t linearization_solves() const { return linearization_solves_; }

  // Some mesh of the body relaxes (viscoelastic terms).
  bool viscoelastic() const { return !qlv_.empty(); }
  // An update for a load at time_s would move the equilibrium although the forces did not: the
  // body relaxes, time_s is past the last update's, and some element's stress is more than
  // kRelaxedFraction of the largest from its relaxed value.
  static constexpr double kRelaxedFraction = 1e-9;
  bool relaxing_at(double time_s) const;
  // The internal variables of body mesh `body` (0: host, k: tied k - 1), or null (elastic).
  const fem::QuasiLinearViscoelastic* history(int body) const;

 private:
  // The load's slots and forces agree in number, every slot exists and every force is finite;
  // else std::invalid_argument naming `who` and the body.
  void check_load(const TierLoad& load, const char* who) const;
  const CoupledBody* body_;
  fem::Tier tier_;
  fem::NewtonOptions newton_;
  std::unique_ptr<fem::EquilibriumSolver> solver_;
  // Per contact slot: its mesh in the solver (0: host, k: tied k - 1), its node there and its
  // first stacked dof (slots on an exposed tied mesh: that mesh's node).
  std::vector<int> slot_mesh_, slot_vertex_, slot_dof_;
  Eigen::VectorXd f_tie_, u_tie_;  // linearization by a coupled solve: a tied mesh's loads, field
  Eigen::VectorXd u_, f_, trial_, u_lin_;  // warm start and scratch
  std::vector<Eigen::VectorXd> u_body_;              // per solver body: its part of u_ (scratch)
  std::vector<mesh::Vec3> rotated_;
  // The linearization's compliance columns (null: column_budget_bytes too small for one slot).
  std::unique_ptr<ContactColumns> columns_;
  std::size_t column_capacity_{0};             // slots
  std::vector<std::uint64_t> last_load_;       // per contact slot: the linearization that last loaded it
  std::vector<int> kept_, missing_, victims_;  // slots with columns; scratch
  std::vector<mesh::Vec3> compliance_;         // per contact slot: C R^T f* at its node, unit m
  std::uint64_t linearizations_{0}, columns_solved_{0}, linearization_solves_{0};
  // C R^T f* (rotated_ on the load's slots) at every contact slot into compliance_ from the
  // columns; false (nothing changed) when the load's slots do not fit in the capacity.
  bool compliance_from_columns(const TierLoad& load);
  // Its first part: marks the load's slots as loaded now, evicts to make room and lists in
  // missing_ the load's slots without columns (not solved yet); false when they do not fit.
  bool plan_columns(const TierLoad& load);
  // Phase "Newton" of update(): u (the warm start, u_'s copy) becomes the equilibrium for f_
  // (the rest state for an elastic body without force); throws std::runtime_error naming the
  // body when it does not converge.
  void equilibrium(Eigen::VectorXd& u, int& iterations, bool& converged, double& residual_n);
  // The worker's own solve scratch: its linearizations lock nothing the step or the fields use.
  std::unique_ptr<fem::SolveWorkspace> ws_ = std::make_unique<fem::SolveWorkspace>();
  std::vector<Eigen::Matrix3d> rotation_;  // per contact slot
  std::uint64_t count_{0};
  // Relaxing meshes: per solver body (null: elastic), the time of the last update.
  std::vector<std::unique_ptr<fem::QuasiLinearViscoelastic>> qlv_;
  double time_s_{0.0};
  bool timed_{false};
  // R per contact slot from u_ (each slot's mesh: its tetrahedra around the slot's node).
  void rotations();
  // Elements inverted and held by the element barrier in u_, every mesh of the body.
  void count_elements(int& inverted, int& barrier);
};

}  // namespace neurosim::interaction
