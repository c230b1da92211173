// Keeps every body's tier equilibrium (TierEquilibrium) following the contact forces: on its own
// thread, as fast as it goes (the server: the 1 kHz step never waits for a Newton solve), or
// inline after each step (deterministic: tests and offline replay).
//
//   step thread:  begin_step() takes the newest linearizations; linearization(b) reads them;
//                 post(loads) hands over the step's contact forces (never blocks).
//   worker:       newest loads -> relaxed forces -> TierEquilibrium::update per body -> publish
//                 (triple buffers: neither side waits; a load not taken yet is replaced by a
//                 newer one; loads found with an older linearization than the newest are
//                 skipped).
//
// The step and the updates form a fixed-point iteration on the contact forces: the step finds
// the forces lambda for the linearization made at forces f, the update makes the next one at f'.
// Plain f' = lambda converges only while the warped linear compliance W is within a factor two of
// the tier's tangent compliance C_t (error factor I - W^-1 C_t); under a small tip a single node
// can soften more than that in the corotational tier and the forces then oscillate with growing
// amplitude. So f' = f + omega (lambda - f) with Aitken's dynamic relaxation factor (as in
// partitioned fluid-structure coupling, Kuettler & Wall 2008), per body, clamped to
// [kMinRelaxation, kMaxRelaxation]: the fixed point is the same, it is reached in both cases. A
// negative estimate (the residual grew along itself: f lagging a lambda that moves with the tool,
// not overshooting it) leaves the factor unchanged: clamped to the floor it made f lag further
// and kept the factor there through a whole press.
// A step whose forces on an elastic body are all zero (the tools left it) sets f' = 0 at once and restarts
// the relaxation: the body is then at rest in one update (TierEquilibrium::update), instead of
// relaxing towards rest while the step finds its rows on a surface no tool holds any more.
//
// Updates cut short (NewtonOptions::step_limit, the server's 2 Newton steps) are inexact: the
// linearization is then taken at an iterate u that is not the equilibrium of f, and the step's
// lambda - f carries that error as well as the fixed point's residual. Where Newton needs many
// steps (the bundled brain pressed 10 mm: strain ~3, the update's residual after its 2 steps
// often larger than the forces' change) moving f at every update by that lambda made the two
// iterations chase each other: the held force circled (0.31-0.36 N) instead of settling. So, as
// the forcing term of an inexact Newton method (Eisenstat & Walker 1996) bounds the inner error by
// a fraction of the outer residual, f moves only when the last update's Newton residual is at
// most kNewtonForcing x max |lambda - f| (or it converged); otherwise the next update goes on
// for the same f from the last iterate (each update still at most step_limit steps: the rate is
// unchanged). The fixed point is the same.
#pragma once

#include "common/triple_buffer.hpp"
#include "server/interaction/tier_equilibrium.hpp"

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace neurosim::interaction {

class TierWorker {
 public:
  // The forcing term of the inexact updates: the relaxed forces move only once the current
  // update's Newton residual (TierLinearization::residual_n) is at most this fraction of the
  // step's change of them, max |lambda - f| (or the update converged); dimensionless.
  static constexpr double kNewtonForcing = 0.1;
  // One equilibrium per body (none null). threaded: the updates run on a thread started here
  // and joined by the destructor; else post() runs them. max_forces_per_body: the hand-over
  // buffers are sized for that many contact forces per body (more: they grow once).
  TierWorker(std::vector<std::unique_ptr<TierEquilibrium>> bodies, bool threaded,
             int max_forces_per_body);
  ~TierWorker();
  TierWorker(const TierWorker&) = delete;
  TierWorker& operator=(const TierWorker&) = delete;

  // Step thread. The linearizations stay the same between two begin_step() calls.
  void begin_step();
  const TierLinearization& linearization(int body) const;
  // Step thread: the contact forces of a good step, one load per body. Threaded: hands them
  // over; else updates every body now (throws what TierEquilibrium::update throws).
  // Returns true when an update ran inside this call (synchronous worker), else false.
  bool post(const std::vector<TierLoad>& loads);

  // Equilibrium updates per second of work, 1 / mean update time (all bodies) over the updates
  // of the current one-second window (kept while idle: a held tool, once its forces are a fixed
  // point, needs none), unit Hz; 0 before the first.
  // Any thread.
  double rate_hz() const { return rate_hz_.load(std::memory_order_relaxed); }
  // Every update so far (all bodies each) and their summed time, unit s, read as one pair: the
  // mean rate over any span of updates is the difference of the counts over that of the times
  // (a bench's press: its every update, not the last second's few). Any thread.
  struct Totals {
    std::uint64_t updates{0};
    double busy_s{0.0};
  };
  Totals totals() const;
  // Updates that went on for the same forces although the step's had changed, because the
  // last update was cut short further from its equilibrium than kNewtonForcing of that change.
  // Any thread.
  std::uint64_t held_updates() const { return held_.load(std::memory_order_relaxed); }
  // Updates that did not converge (the previous equilibrium stays) and the last message.
  std::uint64_t failures() const { return failures_.load(std::memory_order_relaxed); }
  std::string last_error() const;

 private:
  std::vector<std::unique_ptr<TierEquilibrium>> bodies_;
  bool threaded_;
  common::TripleBuffer<std::vector<TierLoad>> loads_;
  common::TripleBuffer<std::vector<TierLinearization>> published_;
  std::vector<TierLinearization> current_;  // synchronous mode, and the worker's own copy
  std::vector<TierLoad> pending_, relaxed_;  // worker: newest loads, what the update solves for
  // Aitken relaxation per body: the forces f of the current equilibrium (3 per contact slot),
  // the last fixed-point residual lambda - f, and the factor.
  struct Relaxation {
    Eigen::VectorXd f, residual, previous;
    double omega{1.0};
    bool has_previous{false};
  };
  std::vector<Relaxation> relax_;
  std::atomic<std::uint64_t> held_{0};
  std::atomic<bool> stop_{false};
  std::atomic<double> rate_hz_{0.0};
  std::atomic<std::uint64_t> failures_{0};
  mutable std::mutex error_mutex_;
  mutable std::mutex totals_mutex_;
  Totals totals_;
  std::string last_error_;
  double window_start_s_{0.0}, window_busy_s_{0.0};
  int window_updates_{0};
  std::thread thread_;
  // Relaxes `loads` into relaxed_ and updates every body for them into current_. Returns false
  // when there was nothing to do (stale loads, or a fixed point: lambda == f bitwise with every
  // equilibrium converged; one cut short by the step limit is continued); a body
  // whose update failed keeps its equilibrium (error recorded; synchronous: thrown).
  bool update_all(const std::vector<TierLoad>& loads);
  void run();
};

}  // namespace neurosim::interaction
