#include "server/interaction/tier_worker.hpp"

#include "server/fem/cholmod_threads.hpp"

#include "common/clock.hpp"

#include <pthread.h>

#include <algorithm>
#include <cmath>
#include <chrono>
#include <stdexcept>

namespace neurosim::interaction {

namespace {

constexpr double kMinRelaxation = 0.1;
constexpr double kMaxRelaxation = 1.5;

double now_s() {
  return std::chrono::duration<double>(common::Clock::now().time_since_epoch()).count();
}

}  // namespace

TierWorker::TierWorker(std::vector<std::unique_ptr<TierEquilibrium>> bodies, bool threaded,
                       int max_forces_per_body)
    : bodies_(std::move(bodies)), threaded_(threaded) {
  current_.resize(bodies_.size());
  relaxed_.resize(bodies_.size());
  relax_.resize(bodies_.size());
  for (std::size_t b = 0; b < bodies_.size(); ++b) {
    if (!bodies_[b]) throw std::invalid_argument("TierWorker: body " + std::to_string(b) + " null");
    bodies_[b]->rest(current_[b]);
    const int n = 3 * bodies_[b]->num_slots();
    relax_[b].f.setZero(n);
    relax_[b].residual.setZero(n);
    relax_[b].previous.setZero(n);
  }
  if (threaded_) {
    // Size the three load buffers now (the consumer side is still this thread), so that handing
    // over a step's forces copies into capacity that is already there: no allocation in post().
    std::vector<TierLoad> sized(bodies_.size());
    for (auto& l : sized) {
      l.slots.assign(static_cast<std::size_t>(std::max(1, max_forces_per_body)), 0);
      l.forces_n.assign(l.slots.size(), mesh::Vec3::Zero());
    }
    for (int k = 0; k < 3; ++k) {
      loads_.publish(sized);
      loads_.consume();
    }
    published_.publish(current_);
    published_.consume();
    window_start_s_ = now_s();
    thread_ = std::thread([this] { run(); });
  }
}

TierWorker::~TierWorker() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void TierWorker::begin_step() {
  if (threaded_) published_.consume();
}

const TierLinearization& TierWorker::linearization(int body) const {
  const auto& lin = threaded_ ? published_.newest() : current_;
  return lin.at(static_cast<std::size_t>(body));
}

std::string TierWorker::last_error() const {
  std::lock_guard<std::mutex> lock(error_mutex_);
  return last_error_;
}

bool TierWorker::update_all(const std::vector<TierLoad>& loads) {
  if (loads.size() != bodies_.size()) {
    throw std::invalid_argument("TierWorker: " + std::to_string(loads.size()) + " loads for " +
                                std::to_string(bodies_.size()) + " bodies");
  }
  // Fixed-point residual lambda - f per body; nothing to do for stale loads or at a fixed point.
  bool moved = false;
  for (std::size_t b = 0; b < bodies_.size(); ++b) {
    if (loads[b].linearization != current_[b].count) return false;
    if (loads[b].slots.size() != loads[b].forces_n.size()) {
      throw std::invalid_argument("TierWorker: body " + std::to_string(b) + ": " +
                                  std::to_string(loads[b].slots.size()) + " slots, " +
                                  std::to_string(loads[b].forces_n.size()) + " forces");
    }
    Relaxation& rx = relax_[b];
    rx.residual = -rx.f;
    for (std::size_t k = 0; k < loads[b].slots.size(); ++k) {
      const int s = loads[b].slots[k];
      if (s < 0 || 3 * s >= rx.f.size()) {
        throw std::invalid_argument("TierWorker: body " + std::to_string(b) + ": contact slot " +
                                    std::to_string(s) + " out of range");
      }
      rx.residual.segment<3>(3 * s) += loads[b].forces_n[k];
    }
    moved = moved || rx.residual.cwiseAbs().maxCoeff() > 0.0;
  }
  // A fixed point of the forces ends the updates only once every equilibrium has converged: an
  // update cut short by the step limit goes on for the same forces. (The tool leaving the tissue
  // is a fixed point at once, forces 0 = 0, and would otherwise leave the tissue in the last
  // unconverged iterate, up to 1e-5 m off rest.)
  // Relaxing tissue moves with time although its forces do not: a body whose stress has not
  // relaxed yet is updated at every newer load time.
  bool settled = true;
  for (const TierLinearization& lin : current_) settled = settled && lin.converged;
  for (std::size_t b = 0; b < bodies_.size() && settled && !moved; ++b)
    settled = !bodies_[b]->relaxing_at(loads[b].time_s);
  if (!moved && settled) return false;
  const auto t0 = common::Clock::now();
  for (std::size_t b = 0; b < bodies_.size(); ++b) {
    Relaxation& rx = relax_[b];
    // The step's forces on this elastic body are all zero (a relaxing body is not at rest
    // without force: its history holds it).
    bool released = !bodies_[b]->viscoelastic();
    for (const mesh::Vec3& f : loads[b].forces_n)
      released = released && f.cwiseAbs().maxCoeff() == 0.0;
    if (moved && released) {
      // Every tool has left the body: its forces are 0 at once (a body without force is at rest,
      // TierEquilibrium::update), not relaxed towards 0 over several updates, during which the
      // tissue would stay deformed where no tool holds it and the step would find its rows on
      // that surface. The relaxation starts again from there.
      rx.f.setZero();
      rx.has_previous = false;
      rx.omega = 1.0;
    } else if (moved && !current_[b].converged &&
               current_[b].residual_n > kNewtonForcing * rx.residual.cwiseAbs().maxCoeff()) {
      // The equilibrium of the current forces is further from converged than a fraction of
      // the step's change of them: its linearization is not yet the model's at f, so the
      // step's lambda - f is mostly the update's own error, not the fixed point's residual.
      // Newton goes on for the same f (the Aitken history kept: its next secant is taken
      // between two linearizations that were equilibria to within that fraction).
      held_.fetch_add(1, std::memory_order_relaxed);
    } else if (moved) {
      if (rx.has_previous) {  // Aitken: omega <- -omega r_prev . (r - r_prev) / |r - r_prev|^2
        rx.previous = rx.residual - rx.previous;
        const double den = rx.previous.squaredNorm();
        const double num = (rx.residual - rx.previous).dot(rx.previous);  // r_prev . dr
        const double estimate = -rx.omega * num / den;
        // A negative estimate (the residual grew along itself) is a lag, not an overshoot: f
        // behind a moving lambda (a press: the tool moves between updates), or behind an
        // update's own progress. A smaller factor only makes f lag further, which keeps the
        // estimate negative: the factor would sit at its floor for the whole press. The factor
        // stays as it was; an overshoot (the residual turning back) still lowers it.
        if (den > 0.0 && std::isfinite(estimate) && estimate > 0.0) {
          rx.omega = std::clamp(estimate, kMinRelaxation, kMaxRelaxation);
        }
      }
      rx.f += rx.omega * rx.residual;
      rx.previous = rx.residual;
      rx.has_previous = true;
    }
    TierLoad& out = relaxed_[b];
    out.slots.clear();
    out.forces_n.clear();
    for (int s = 0; 3 * s < rx.f.size(); ++s) {
      if (rx.f.segment<3>(3 * s).cwiseAbs().maxCoeff() == 0.0) continue;
      out.slots.push_back(s);
      out.forces_n.push_back(rx.f.segment<3>(3 * s));
    }
    out.linearization = loads[b].linearization;
    out.time_s = loads[b].time_s;
    try {
      bodies_[b]->update(out, current_[b]);
    } catch (const std::exception& e) {
      // The equilibrium stays that of its last forces: the relaxation restarts from them.
      rx.f.setZero();
      const TierLoad& kept = current_[b].load;
      for (std::size_t k = 0; k < kept.slots.size(); ++k)
        rx.f.segment<3>(3 * kept.slots[k]) = kept.forces_n[k];
      rx.has_previous = false;
      rx.omega = 1.0;
      failures_.fetch_add(1, std::memory_order_relaxed);
      std::lock_guard<std::mutex> lock(error_mutex_);
      last_error_ = e.what();
      if (!threaded_) throw;
    }
  }
  // Rate: 1 / mean update time over this window's updates (a window lasts a second).
  const double busy_s = common::seconds_since(t0);
  {
    std::lock_guard<std::mutex> lock(totals_mutex_);
    ++totals_.updates;
    totals_.busy_s += busy_s;
  }
  window_busy_s_ += busy_s;
  ++window_updates_;
  if (window_busy_s_ > 0.0)
    rate_hz_.store(window_updates_ / window_busy_s_, std::memory_order_relaxed);
  const double t = now_s();
  if (t - window_start_s_ >= 1.0) {
    window_start_s_ = t;
    window_busy_s_ = 0.0;
    window_updates_ = 0;
  }
  return true;
}

TierWorker::Totals TierWorker::totals() const {
  std::lock_guard<std::mutex> lock(totals_mutex_);
  return totals_;
}

bool TierWorker::post(const std::vector<TierLoad>& loads) {
  if (threaded_) {
    loads_.publish(loads);
    return false;
  }
  return update_all(loads);
}

void TierWorker::run() {
  pthread_setname_np(pthread_self(), "ns-tier");  // ps -L, top -H, perf (the column worker's habit)
  // Each update factors a tangent: with OMP_NUM_THREADS=1, CHOLMOD's parallel regions run on
  // this thread alone (cholmod_threads.hpp), as on neurosim-solve's.
  fem::cholmod_threads_follow_omp_num_threads();
  while (!stop_.load(std::memory_order_relaxed)) {
    // Nothing new, stale, or a fixed point: wait a little.
    bool updated = false;
    try {
      updated = loads_.take(pending_) && update_all(pending_);
    } catch (const std::exception& e) {  // malformed loads: recorded, the worker goes on
      failures_.fetch_add(1, std::memory_order_relaxed);
      std::lock_guard<std::mutex> lock(error_mutex_);
      last_error_ = e.what();
    }
    if (!updated) {
      std::this_thread::sleep_for(std::chrono::microseconds(200));
      continue;
    }
    published_.publish(current_);
  }
}

}  // namespace neurosim::interaction
