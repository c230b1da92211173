// Linear static solver: K u = f with fixed nodes eliminated, factored once with CHOLMOD
// (supernodal LL^T). The factor is Model (built once); the scratch of a solve is the caller's
// SolveWorkspace (State, field worker), or the solver's own one under a mutex.
#pragma once

#include "server/fem/assembly.hpp"
#include "server/fem/factor_ordering.hpp"
#include "server/fem/material.hpp"
#include "server/fem/prescribed.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace neurosim::fem {

struct SolverOptions {
  // After every solve, check ||K u - f|| on the free dofs against residual_tolerance * ||f||.
  bool check_residual{false};
  double residual_tolerance{1e-8};  // relative, dimensionless
  // Before factoring, check that the fixed nodes of every connected part of the mesh are at
  // least three non-collinear nodes (otherwise K_ff keeps rigid-body modes and is singular).
  bool check_rigid_modes{true};
  // A factor whose CHOLMOD rcond (min diag(L) / max diag(L))^2 is below this is singular.
  double min_rcond{1e-15};
  // Memory for the numeric factor, unit byte: the factor's size is known exactly from the
  // symbolic analysis, before the numeric factorization allocates it; a larger one is refused
  // there (FactorTooLarge, with the estimate) instead of the process being killed by the kernel
  // half-way. 0: common::memory_available_bytes() when the solver is built (MemAvailable, RLIMIT_AS or the
  // cgroup's limit, the smallest).
  double max_factor_bytes{0.0};
  // Let CHOLMOD print its own warnings to stdout (errors become exceptions either way).
  bool cholmod_verbose{false};
  // Folder of the disk cache of the factor (factor_cache.hpp), keyed by the inputs of K_ff
  // (mesh, materials, fixed nodes, ordering): a second solver of the same problem reads the
  // factor instead of analysing and factoring (the same factor bit for bit), and assembles K
  // only when something asks for it (stiffness(), reactions, the residual check, the condition
  // estimate). Empty: no cache.
  std::string factor_cache_dir{};
  // The fill-reducing ordering of K_ff (factor_ordering.hpp): the factor's size and time, never
  // the answer beyond round-off. Part of the factor cache's key. METIS on the node graph: the
  // same factor size as CHOLMOD's own choice (METIS on the dof graph) within 2 % on the brain,
  // its analysis 2-5x faster (bench/RESULTS.md "The host factor's ordering").
  FactorOrdering ordering{FactorOrdering::kNodeMetis};
};

// The factor of K_ff would not fit in SolverOptions::max_factor_bytes (or the memory available).
struct FactorTooLarge : std::runtime_error {
  FactorTooLarge(const std::string& what, double needed, double available)
      : std::runtime_error(what), needed_bytes(needed), available_bytes(available) {}
  double needed_bytes;     // the factor (values + structure), from the symbolic analysis, byte
  double available_bytes;  // the limit it was compared with, byte
};

// What the factorization cost and holds (reported by benchmarks and Compliance).
struct FactorInfo {
  int num_dofs{0};              // 3N
  int num_free_dofs{0};         // 3N minus fixed dofs: size of the factored system
  long long stiffness_nnz{0};   // stored entries of the full K (both triangles); 0 from the cache
  long long factor_nnz{0};      // nnz(L), CHOLMOD's lnz
  long long factor_entries{0};  // stored values of the supernodal L (with padding)
  std::size_t factor_bytes{0};  // values + integer structure of L, unit byte
  bool supernodal{false};
  // The ordering the factor was made with: SolverOptions::ordering's name, and for "cholmod"
  // the method CHOLMOD chose ("cholmod:amd", "cholmod:metis"); a cached factor: its option's.
  std::string ordering;
  double factor_flops{0.0};  // CHOLMOD's flop count of the factorization (0 from the cache)
  double rcond{0.0};        // CHOLMOD's rough reciprocal condition estimate
  double assembly_s{0.0};   // wall time of pattern + assembly, unit s (0 from the cache)
  double analyze_s{0.0};    // symbolic analysis (ordering), unit s
  double factorize_s{0.0};  // numeric factorization, unit s
  // SolverOptions::factor_cache_dir: the factor was read from the cache (analyze_s and
  // factorize_s are then 0) in cache_s (the key and the read); without a hit, cache_s is the
  // key, the attempt and the write.
  bool from_cache{false};
  double cache_s{0.0};  // unit s
};

// Extreme eigenvalues of K_ff by power / inverse power iteration (unit N/m).
struct ConditionEstimate {
  double lambda_max{0.0};
  double lambda_min{0.0};
  double condition{0.0};  // lambda_max / lambda_min
  int iterations{0};
  double rcond_cholmod{0.0};  // same as FactorInfo::rcond, for side-by-side reporting
};

struct PrescribedSolution {
  Eigen::VectorXd displacement_m;  // 3N, unit m
  // 3N, unit N: force the supports exert on the body, r = K u - f, at the constrained dofs
  // (all components of fixed nodes, the prescribed components of prescribed nodes); exactly
  // zero elsewhere, including the free components of a prescribed node (K u - f is round-off
  // there).
  Eigen::VectorXd reaction_n;
};

// Scratch of solves: a CHOLMOD common and the dense buffers, owned by whoever solves (a
// simulation State, a field worker, a tier worker), so that solves on different workspaces run
// at once and take no lock: the factor they read is constant.
class SolveWorkspace {
 public:
  SolveWorkspace();
  ~SolveWorkspace();
  SolveWorkspace(SolveWorkspace&&) noexcept;
  SolveWorkspace& operator=(SolveWorkspace&&) noexcept;
  SolveWorkspace(const SolveWorkspace&) = delete;
  SolveWorkspace& operator=(const SolveWorkspace&) = delete;
  struct Impl;

 private:
  friend class StaticSolver;
  std::unique_ptr<Impl> impl_;
};

// Thread safety: const members may be called from several threads. The overloads that take a
// SolveWorkspace lock nothing (the caller owns the scratch); the others share the solver's own
// workspace and are serialized by an internal mutex (set-up and offline use:
// shared_workspace_uses() counts them).
class StaticSolver {
 public:
  // Assembles K (one material, or one per tetrahedron), eliminates the fixed nodes (u = 0
  // there), analyses and factors K_ff. Throws std::invalid_argument for bad input (material,
  // element, node id out of range, nodes in no tetrahedron, too few fixed nodes: the message
  // says which part of the mesh is free to move) and std::runtime_error if CHOLMOD fails or
  // the factor is numerically singular. The mesh is not referenced after construction (a
  // factor read from the cache keeps a copy of it until K is first asked for).
  StaticSolver(const mesh::TetMesh& mesh, const MaterialMap& materials,
               const std::vector<int>& fixed_nodes, const SolverOptions& options = {});
  ~StaticSolver();
  StaticSolver(StaticSolver&&) noexcept;
  StaticSolver& operator=(StaticSolver&&) noexcept;
  StaticSolver(const StaticSolver&) = delete;
  StaticSolver& operator=(const StaticSolver&) = delete;

  // Displacements u (3N, m) for nodal forces f (3N, N); u = 0 at fixed nodes, forces there
  // go into the supports. Throws on non-finite forces or a wrong size. The overload with an
  // output argument does not allocate once `u_m` has size 3N (CHOLMOD workspace is reused).
  Eigen::VectorXd solve(const Eigen::VectorXd& forces_n) const;
  void solve(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m) const;
  void solve(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m, SolveWorkspace& ws) const;

  // Displacements prescribed on `nodes` (displacements_m: 3|nodes|, node-major x,y,z), plus
  // optional forces (empty or 3N). Prescribed nodes that are fixed nodes are eliminated;
  // others are imposed through the Schur complement of the factor, so no refactorization is
  // ever needed: cost 3|P| extra solves (in blocks of 64) and a dense 3|P| x 3|P| Cholesky, so
  // for large fixed-in-time sets (hundreds of nodes) pass them in fixed_nodes instead. All
  // three components of every node are prescribed (solve_prescribed_dofs for a subset).
  PrescribedSolution solve_prescribed(const std::vector<int>& nodes,
                                      const Eigen::VectorXd& displacements_m,
                                      const Eigen::VectorXd& forces_n = Eigen::VectorXd()) const;
  // The same on the caller's workspace (no lock; forces_n empty or 3N).
  PrescribedSolution solve_prescribed(const std::vector<int>& nodes,
                                      const Eigen::VectorXd& displacements_m,
                                      const Eigen::VectorXd& forces_n, SolveWorkspace& ws) const;

  // Prescribed displacements by component (PrescribedDofs: a node set, a displacement and the
  // components it holds; the other components are free unknowns), plus optional forces (empty
  // or 3N). Validated by expand_prescribed against fixed_nodes(): a node both fixed and
  // prescribed, a component prescribed twice with different values, no node or no component
  // in a definition are refused with std::invalid_argument naming the definition and the node.
  // Cost as solve_prescribed, with 3|P| replaced by the number of prescribed components.
  PrescribedSolution solve_prescribed_dofs(
      const std::vector<PrescribedDofs>& prescribed,
      const Eigen::VectorXd& forces_n = Eigen::VectorXd()) const;

  // Per-dof form: dofs (3 * node + axis, each at most once) take values_m (one per dof); the
  // other components of their nodes are free unless the node is fixed. A dof of a fixed node
  // may be given (its value replaces 0, as in solve_prescribed). Throws std::invalid_argument
  // naming node and axis for a dof out of range, given twice or with a non-finite value.
  PrescribedSolution solve_prescribed_per_dof(
      const std::vector<int>& dofs, const Eigen::VectorXd& values_m,
      const Eigen::VectorXd& forces_n = Eigen::VectorXd()) const;
  PrescribedSolution solve_prescribed_per_dof(const std::vector<int>& dofs,
                                              const Eigen::VectorXd& values_m,
                                              const Eigen::VectorXd& forces_n,
                                              SolveWorkspace& ws) const;

  // Reduced (free-dof) system, for Compliance and coupling code.
  // X = K_ff^-1 B for a dense B (num_free_dofs x m): all columns in one CHOLMOD call.
  void solve_reduced(const Eigen::MatrixXd& b, Eigen::MatrixXd& x) const;
  void solve_reduced(const Eigen::MatrixXd& b, Eigen::MatrixXd& x, SolveWorkspace& ws) const;
  // Solves that used the solver's own (locked) workspace since construction.
  std::uint64_t shared_workspace_uses() const;
  int num_nodes() const { return num_nodes_; }
  int num_dofs() const { return 3 * num_nodes_; }
  int num_free_dofs() const { return static_cast<int>(free_dofs_.size()); }
  const std::vector<int>& free_dofs() const { return free_dofs_; }          // reduced -> dof
  const std::vector<int>& reduced_index() const { return reduced_index_; }  // dof -> reduced or -1
  const std::vector<int>& fixed_nodes() const { return fixed_nodes_; }      // sorted, unique
  bool is_fixed_node(int node) const { return reduced_index_[3 * node] < 0; }

  // Full K (3N x 3N), unit N/m. After a factor cache hit it is assembled on the first call
  // (thread-safe; FactorInfo is not updated by it).
  const SparseMatrix& stiffness() const;
  const FactorInfo& factor_info() const { return info_; }
  const SolverOptions& options() const { return options_; }

  // Power iteration on K_ff and inverse iteration with the factor.
  ConditionEstimate estimate_condition(int max_iterations = 300, double tolerance = 1e-6) const;

 private:
  struct Impl;  // CHOLMOD factor and workspace (kept out of the header)
  std::unique_ptr<Impl> impl_;
  SolverOptions options_;
  int num_nodes_{0};
  std::vector<int> fixed_nodes_;
  std::vector<int> free_dofs_;
  std::vector<int> reduced_index_;
  FactorInfo info_;

  // The lower triangle of K_ff (fixed dofs eliminated) of a full K.
  SparseMatrix lower_free_block(const SparseMatrix& k) const;
  // Analysis, memory check against `limit` (from `source`) and numeric factorization of K_ff;
  // lnz gets nnz(L).
  void factorize(const SparseMatrix& kff, const std::string& where, double limit,
                 const char* source, double& lnz);
  void check_forces(const Eigen::VectorXd& forces_n, const char* what) const;
  void solve_free(const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m, SolveWorkspace::Impl& ws) const;
  // ws null: the solver's own workspace (each solve takes the lock).
  PrescribedSolution prescribed_per_dof(const std::vector<int>& dofs, const Eigen::VectorXd& values_m,
                                        const Eigen::VectorXd& forces_n, SolveWorkspace* ws) const;
  static std::vector<int> node_dofs(const std::vector<int>& nodes, const Eigen::VectorXd& displacements_m,
                                    int num_nodes);
  void check_residual(Eigen::VectorXd& scratch, const Eigen::VectorXd& u_m, const Eigen::VectorXd& forces_n,
                      const std::vector<char>* constrained) const;
};

}  // namespace neurosim::fem
