// Static equilibrium of one mesh in any elasticity tier: find u with f_int(u) = f_ext on the
// free dofs, fixed nodes at 0 and prescribed components at their values. Newton's method on the
// total potential E(u) - f_ext . u, with a backtracking line search (Armijo on the potential, or
// a decrease of the residual when the potential is flat to round-off) and load increments that
// are cut back when an increment fails to converge. The tangent K_ff is refactorized by CHOLMOD
// (supernodal LL^T, EquilibriumDefinition::ordering: METIS on the node graph) at every
// iteration, reusing the one symbolic analysis made at construction (the constrained dofs, hence
// the pattern, never change); the tangent of tied meshes, T^T K T, is scattered into a pattern
// made once as well, so a tangent allocates nothing. An indefinite tangent (compression with buckling modes, clamped elements) is
// replaced by the one with every element tangent projected to positive semidefinite, so each
// step is a descent direction.
//
// Warm-started updates (NewtonOptions::reuse_factorization): the numeric factorization is
// 70-90 % of a Newton iteration on the 14k-free-dof brain mesh (bench/RESULTS.md, "Equilibrium
// updates"), so a worker that re-solves for slowly changing loads keeps the last factor across
// iterations and calls and takes Anderson-accelerated chord steps u += K_old^-1 r (same
// acceptance test, same convergence test), refactorizing only when a step contracts the
// residual too little.
//
// Not thread-safe: an EquilibriumSolver holds its factorization and scratch (one per thread).
#pragma once

#include "server/fem/elastic_forces.hpp"
#include "server/fem/factor_ordering.hpp"
#include "server/fem/prescribed.hpp"

#include <Eigen/Core>

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::fem {

// A mesh tied to the host (the first mesh): each of its `tied_nodes` k follows the host,
// u_B(k) = sum_a weights[k][a] u_A(host_nodes[k][a]) (a point of the host's boundary S').
// The constraint is eliminated exactly (u = T q, K_q = T^T K T, r_q = T^T r).
struct TiedMeshDefinition {
  const mesh::TetMesh* mesh{nullptr};  // only used during construction
  MaterialMap materials;
  std::vector<int> fixed_nodes;  // B's own supports (not tied)
  std::vector<int> tied_nodes;
  std::vector<std::array<int, 3>> host_nodes;
  std::vector<std::array<double, 3>> weights;  // dimensionless, sum 1 per node
};

struct EquilibriumDefinition {
  const mesh::TetMesh* mesh{nullptr};  // the host; only used during construction
  MaterialMap materials;
  Tier tier{Tier::kNonlinear};
  std::vector<int> fixed_nodes;  // u = 0 in x, y, z
  // Prescribed components on the host (values at load factor 1); the constrained dofs are
  // fixed here, the values may be changed later with set_prescribed_values.
  std::vector<PrescribedDofs> prescribed;
  // Meshes tied to the host, in the same tier. Displacements, forces and reactions are then
  // stacked: the host's 3 N_A dofs, then each tied mesh's 3 N_B (body_offset).
  std::vector<TiedMeshDefinition> tied;
  // The fill-reducing ordering of the tangent's factor (factor_ordering.hpp): its size and the
  // time of every factorization and solve, never the answer beyond round-off.
  FactorOrdering ordering{FactorOrdering::kNodeMetis};
  // Memory for the tangent's numeric factor, unit byte, as SolverOptions::max_factor_bytes: its
  // size is known exactly from the symbolic analysis made at construction, and a larger one is
  // refused there (FactorTooLarge, static_solver.hpp, with both numbers) instead of the process
  // being killed by the kernel half-way through the first factorization. 0:
  // common::memory_available_bytes() at construction (MemAvailable, RLIMIT_AS or the cgroup's
  // limit, the smallest). The background refactorizations' second factor has its own test
  // (NewtonOptions::background_refactorization).
  double max_factor_bytes{0.0};
};

struct NewtonOptions {
  // Load increments: 0 chooses them (four to start, cut back and regrown as Newton allows);
  // N > 0 starts with N equal increments (still cut back when one fails).
  int increments{0};
  // Converged when max |r_free| <= tolerance * force scale, the force scale being the largest
  // of max |f_ext|, max |reaction| and 1e-6 E_max h^2 (h: cube root of the mean element
  // volume), unit N. Dimensionless.
  double tolerance{1e-10};
  int max_iterations{40};  // per increment
  // solve only. > 0: the increments before the last (load factor < 1) end when max |r_free| <=
  // path_tolerance * force scale (when it is above `tolerance`); the last increment is converged
  // to `tolerance` either way. The increments only lead Newton along the load path to the
  // answer at load factor 1, which for a hyperelastic body (no history) does not depend on how
  // tightly the path was followed: a looser path saves the last one or two iterations of every
  // increment but the last. 0: every increment to `tolerance`. Dimensionless.
  double path_tolerance{0.0};
  // Iterations taken even when the start already meets the tolerance (a step that finds no
  // decrease there ends the solve, converged). A worker that re-solves for forces which moved by
  // less than the tolerance still follows them (1), instead of keeping an answer that is only
  // within the tolerance of theirs (0).
  int min_iterations{0};
  // solve_from only. > 0: return after this many iterations even when the tolerance is not met
  // (no error; NewtonIncrement::converged says whether it was). For a caller that iterates the
  // updates themselves (the multirate contact loop: each update a few cheap steps, the loop's
  // fixed point the converged equilibrium). 0: iterate to the tolerance (or max_iterations).
  int step_limit{0};
  int max_cutbacks{12};    // halvings of one increment before the solve fails
  // Modified Newton for warm-started updates: keep the last factorized tangent (from an earlier
  // iteration, increment or call of this solver) and step with it, u += K_old^-1 r (Anderson-
  // accelerated, below), accepted by the same test as the line search's; the tangent is
  // reassembled and refactorized at the current u (a full Newton step with line search) only
  // when there is no factor yet, when a step with the old one finds no decrease, when the steps
  // with the current factor contract max |r_free| too slowly (their geometric mean over the last
  // two or three steps (a call's first chord step that increased it less than twofold does not
  // count when step_limit leaves the Anderson steps after it room to judge: 0 or > 2) above
  // refactor_contraction, or above the rate at which the chord steps
  // left to the tolerance would cost more than a factorization: the factorization's cost in
  // back-substitutions from its flop count, about 70 on the 5 mm smoothed-tet brain), when the
  // last step needed a line-search halving, and at every iteration after the first
  // max_iterations / 2 (so a slow chord sequence cannot use up the budget). A call cut short by
  // step_limit when a refactorization was due leaves it to the next call's first iteration.
  // The convergence test and tolerance are the ones
  // above: the answer is the converged equilibrium, not an approximation. Applies to solve (the
  // factor carried from increment to increment) and solve_from. false: a fresh tangent at every
  // iteration (full Newton, today's iterates exactly).
  bool reuse_factorization{false};
  // Chord rate (residual ratio r_new / r_old per step, max norms, the geometric mean over the
  // last steps with one factor) above which the next iteration refactorizes at least;
  // dimensionless, in (0, 1). Smaller: closer to full Newton (more factorizations, fewer
  // iterations). Only read when reuse_factorization is set.
  double refactor_contraction{0.5};
  // Anderson acceleration of those chord steps: the last `anderson_depth` steps with the same
  // factor are mixed (a least-squares combination, GMRES-like), which removes the few slowly
  // contracting components a changed tangent leaves; 0: plain chord steps. Iterations, at most
  // 16. Only read when reuse_factorization is set.
  int anderson_depth{5};
  // With reuse_factorization: a refactorization that a poor contraction asks for is made on
  // another thread, at the iterate where it was asked for, while the following steps go on with
  // the old factor (Anderson-accelerated chord steps); the new factor is taken at the first
  // iteration after it is done, and waited for only when a step with the old one fails. Same
  // convergence test, same answer; the iterates then depend on the threads' timing (false: the
  // factorization in line, deterministic iterates). For a worker whose every call must stay
  // short (the NONLINEAR tier's updates: a factorization of the 7 mm brain takes seconds, a
  // chord step tens of milliseconds). The factorization at the last iteration budget
  // (max_iterations / 2) stays in line. Uses a second factor of the tangent's size, made only
  // when it is at most half of the memory the process can still get (else in line). Not with a
  // relaxing body (set_viscous_step): then in line.
  bool background_refactorization{false};
  // solve only. true: each increment starts from the tangent predictor instead of the converged
  // u with only the constrained dofs moved to their new values: one linear step
  // u_f += K_ff^-1 (f_ext(t_next) - f_int(u) - K_fc dc), dc the change of the constrained values,
  // with the last factorized tangent K (assembled at u if there is none), i.e. the first Newton
  // step of the increment taken before the prescribed displacement is imposed, as CalculiX
  // does. Without it a prescribed step on a few nodes first crushes the one layer of elements
  // around them (the first residual of the increment grows, the tangent there is indefinite and
  // Newton spends iterations undoing it). The predicted start is kept only when its residual
  // is finite and below the plain start's. Same convergence test: the answer does not change.
  bool tangent_predictor{false};
};

struct NewtonIncrement {
  double load_factor{0.0};        // reached at the end of the increment, in (0, 1]
  std::vector<double> residual_n;  // max |r_free| before each iteration and after the last, N
  int projected_iterations{0};     // iterations whose step used a projected tangent
  int line_search_halvings{0};
  int cutbacks{0};  // failed attempts before this increment converged
  bool converged{true};  // false only when NewtonOptions::step_limit stopped it first
  // Numeric factorizations of the tangent in this increment (a failed exact one followed by
  // the projected one counts 2). Full Newton: at least one per iteration; with
  // reuse_factorization it may be 0 (every step taken with an earlier factor).
  int factorizations{0};
  // NewtonOptions::tangent_predictor: the increment started from the predicted u (false: from
  // the plain start, or the option is off).
  bool predicted{false};
  // Factorizations made on another thread (start_factorization, background_refactorization)
  // that this increment took as its factor.
  int adopted_factorizations{0};
};

struct EquilibriumResult {
  Eigen::VectorXd displacement_m;  // 3N, unit m
  // 3N, unit N: force the supports exert on the body, f_int(u) - f_ext at constrained dofs,
  // zero elsewhere (as StaticSolver's PrescribedSolution).
  Eigen::VectorXd reaction_n;
  std::vector<NewtonIncrement> increments;
  ElasticForcesReport elements;  // at the solution
  double force_scale_n{0.0};     // of the convergence test at load factor 1
};

class EquilibriumSolver {
 public:
  // Throws std::invalid_argument for bad input (mesh, material, node ids, prescribed sets as
  // expand_prescribed) and when nothing is constrained (rigid-body modes).
  explicit EquilibriumSolver(const EquilibriumDefinition& definition);
  ~EquilibriumSolver();
  EquilibriumSolver(const EquilibriumSolver&) = delete;
  EquilibriumSolver& operator=(const EquilibriumSolver&) = delete;

  // Full load path from u = 0 to load factor 1 (forces_n: empty or 3N dead loads, unit N;
  // prescribed values and forces both scaled by the load factor). Throws std::runtime_error
  // when an increment does not converge after max_cutbacks halvings (the message gives the
  // load factor reached and the last residual).
  EquilibriumResult solve(const Eigen::VectorXd& forces_n, const NewtonOptions& options = {});

  // Newton at load factor 1 from a given start (u_m: 3N, warm start, overwritten with the
  // answer; its constrained dofs are set to their values). No increments; returns the residual
  // history. Throws std::runtime_error if it does not converge in max_iterations. With
  // options.reuse_factorization, the factor left by the previous call (or solve) is the first
  // step's: the worker's loop of small load changes then costs a few back-substitutions and
  // residual evaluations per call instead of a factorization per iteration.
  NewtonIncrement solve_from(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m,
                             const NewtonOptions& options = {});

  // Starts factorizing the tangent at u_m (3N) on another thread; the next call with
  // reuse_factorization steps with it (waiting for it if there is no factor yet). A caller that
  // knows where its first solve starts (the NONLINEAR tier: at rest) so factorizes ahead, while
  // it does other work. Returns false (nothing started) while one runs, with a simplicial factor
  // or a relaxing body. Throws std::invalid_argument for a wrong size or non-finite u.
  bool start_factorization(const Eigen::VectorXd& u_m);

  // Values of the prescribed components, in the order of expand_prescribed's dofs (host dofs).
  void set_prescribed_values(const Eigen::VectorXd& values_m);
  const std::vector<int>& prescribed_dofs() const;
  const ElasticForces& forces() const;  // the host's
  const ElasticForces& body_forces(int body) const;  // 0: the host, k: tied[k - 1]
  // A relaxing body (quasi_linear_viscoelastic.hpp): every evaluation of body `body` from now on
  // is that of `step` (not owned; its contents may change between solves: call again after
  // QuasiLinearViscoelastic::begin, which forgets the internal forces kept from the last solve).
  // Null: elastic.
  void set_viscous_step(int body, const ViscousStep* step);
  int body_offset(int body) const;  // first stacked dof of a body
  int num_dofs() const;             // all stacked dofs
  Tier tier() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace neurosim::fem
