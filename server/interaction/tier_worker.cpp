#include "server/interaction/tier_worker.hpp"

#include "common/clock.hpp"

#include <algorithm>
#include <chrono>
#include <stdexcept>

namespace neurosim::interaction {

namespace {

bool same_loads(const std::vector<TierLoad>& a, const std::vector<TierLoad>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i].slots != b[i].slots || a[i].forces_n != b[i].forces_n) return false;
  }
  return true;
}

double now_s() {
  return std::chrono::duration<double>(common::Clock::now().time_since_epoch()).count();
}

}  // namespace

TierWorker::TierWorker(std::vector<std::unique_ptr<TierEquilibrium>> bodies, bool threaded,
                       int max_forces_per_body)
    : bodies_(std::move(bodies)), threaded_(threaded) {
  current_.resize(bodies_.size());
  solved_.resize(bodies_.size());
  for (std::size_t b = 0; b < bodies_.size(); ++b) {
    if (!bodies_[b]) throw std::invalid_argument("TierWorker: body " + std::to_string(b) + " null");
    bodies_[b]->rest(current_[b]);
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
  const auto t0 = common::Clock::now();
  bool ok = true;
  for (std::size_t b = 0; b < bodies_.size(); ++b) {
    try {
      bodies_[b]->update(loads[b], current_[b]);
    } catch (const std::exception& e) {
      ok = false;
      failures_.fetch_add(1, std::memory_order_relaxed);
      std::lock_guard<std::mutex> lock(error_mutex_);
      last_error_ = e.what();
      if (!threaded_) throw;
    }
  }
  updates_.fetch_add(1, std::memory_order_relaxed);
  // Rate: 1 / mean update time over this window's updates (a window lasts a second).
  window_busy_s_ += common::seconds_since(t0);
  ++window_updates_;
  if (window_busy_s_ > 0.0)
    rate_hz_.store(window_updates_ / window_busy_s_, std::memory_order_relaxed);
  const double t = now_s();
  if (t - window_start_s_ >= 1.0) {
    window_start_s_ = t;
    window_busy_s_ = 0.0;
    window_updates_ = 0;
  }
  return ok;
}

void TierWorker::post(const std::vector<TierLoad>& loads) {
  if (threaded_) {
    loads_.publish(loads);
    return;
  }
  if (same_loads(loads, solved_)) return;  // the equilibrium already is that of these forces
  update_all(loads);
  solved_ = loads;
}

void TierWorker::run() {
  while (!stop_.load(std::memory_order_relaxed)) {
    // Nothing new, or the forces the current equilibrium is already for: wait a little.
    if (!loads_.take(pending_) || same_loads(pending_, solved_)) {
      std::this_thread::sleep_for(std::chrono::microseconds(200));
      continue;
    }
    try {
      if (update_all(pending_)) solved_ = pending_;
    } catch (const std::exception& e) {  // malformed loads: recorded, the worker goes on
      failures_.fetch_add(1, std::memory_order_relaxed);
      std::lock_guard<std::mutex> lock(error_mutex_);
      last_error_ = e.what();
      continue;
    }
    published_.publish(current_);
  }
}

}  // namespace neurosim::interaction
