// Baseline: the paper's iterative interaction (2.6, Eq. 3: virtual displacements on the
// colliding boundary adjusted until the two meshes' boundary responses agree), written as a
// relaxed fixed-point iteration on the boundary displacement of the host:
//   u_b <- (1 - w) u_b + w (v - L_bb K_add u_b),  v = L_A[b, c] f_c,
// whose fixed point is the exact tie solution (I + L_bb K_add) u_b = v. Kept for comparison
// only (iterations and time to reach the exact method's accuracy), never the default.
// A body built with CoupledBody::set_iterative applies its coupling operator through apply().
#pragma once

#include <Eigen/Core>

#include <atomic>
#include <vector>

namespace neurosim::interaction {

class CoupledBody;  // server/interaction/coupled_body.hpp

struct IterativeOptions {
  int max_iterations{10000};
  double tolerance{1e-12};  // relative to |v|: stop when |u_b - exact| / |v| <= tolerance
  double relaxation{0.0};   // w; 0: 2 / (2 + rho) with rho = spectral radius of L_bb K_add
};

// Counters of apply() (the iterations a body's coupled solves needed), kept by the caller (the
// State's ContactColumns), never in the Model.
struct IterativeReport {
  int solves{0};          // right-hand sides iterated
  int max_iterations{0};  // most iterations one needed
  int unconverged{0};     // stopped at max_iterations
};

struct IterativeResult {
  int iterations{0};
  bool converged{false};
  std::vector<double> residual;  // per iteration: |u_b(k) - u_b exact| / |v| (paper Figure 13)
  double relaxation{0.0};
};

class IterativeTie {
 public:
  // Precomputes P = L_bb K_add and the relaxation (power iteration); body must be finalized.
  explicit IterativeTie(const CoupledBody& body, const IterativeOptions& options = {});
  // Contact forces (unit N) on contact slots; u_b_exact: the exact boundary displacement (for
  // the residual), unit m. u_b: the iterate on return.
  IterativeResult solve(const std::vector<int>& slots, const std::vector<Eigen::Vector3d>& forces_n,
                        const Eigen::VectorXd& u_b_exact, Eigen::VectorXd& u_b) const;
  // The exact boundary displacement for the same forces (direct solve of the same system).
  Eigen::VectorXd exact(const std::vector<int>& slots,
                        const std::vector<Eigen::Vector3d>& forces_n) const;
  double relaxation() const { return omega_; }
  // out = G in by the iteration, per column: u_b <- (1 - w) u_b + w (in - P u_b) until an update
  // is below tolerance x |in| (or max_iterations), then G in = K_add u_b. Writes nothing of its
  // own (const, thread-safe); the iterations are added to `counts` if given.
  void apply(const Eigen::MatrixXd& in, Eigen::MatrixXd& out, IterativeReport* counts = nullptr) const;

 private:
  const CoupledBody& body_;
  IterativeOptions options_;
  Eigen::MatrixXd p_;  // L_bb K_add
  double omega_{1.0};
  Eigen::VectorXd load(const std::vector<int>& slots,
                       const std::vector<Eigen::Vector3d>& forces_n) const;
};

}  // namespace neurosim::interaction
