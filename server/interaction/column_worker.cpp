#include "server/interaction/column_worker.hpp"

#include "server/fem/cholmod_threads.hpp"

#include "server/interaction/contact_columns.hpp"
#include "server/interaction/coupled_body.hpp"

#include <pthread.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace neurosim::interaction {

ColumnWorker::ColumnWorker(std::vector<ColumnWorkerBody> bodies, const std::vector<ToolShape>& tools,
                           const ColumnWorkerOptions& options)
    : bodies_(std::move(bodies)), tools_(tools), options_(options) {
  if (!(options_.horizon_s >= 0.0) || !(options_.max_tool_speed_m_per_s >= 0.0) ||
      !std::isfinite(options_.horizon_s * options_.max_tool_speed_m_per_s)) {
    throw std::invalid_argument(
        "ColumnWorkerOptions: horizon_s and max_tool_speed_m_per_s must be finite and >= 0");
  }
  if (!(options_.idle_slack_m >= 0.0) || !std::isfinite(options_.idle_slack_m))
    throw std::invalid_argument("ColumnWorkerOptions: idle_slack_m must be finite and >= 0");
  if (!(options_.idle_sleep_s > 0.0 && options_.idle_sleep_s <= 1.0))
    throw std::invalid_argument("ColumnWorkerOptions: idle_sleep_s must be in (0, 1] s");
  if (options_.nice < 0 || options_.nice > 19)
    throw std::invalid_argument("ColumnWorkerOptions: nice must be in 0..19");
  for (const auto& b : bodies_)
    if (b.rest_m == nullptr || b.columns == nullptr)
      throw std::invalid_argument("ColumnWorker: a body without rest positions or cache");
  lookahead_m_ = options_.max_tool_speed_m_per_s * options_.horizon_s;
  workspaces_.resize(bodies_.size());
  last_reach_.resize(bodies_.size());
  reach_slots_.assign(bodies_.size(), 0);
  raised_ = std::make_unique<std::atomic<std::size_t>[]>(bodies_.size());
  for (std::size_t b = 0; b < bodies_.size(); ++b) raised_[b].store(0, std::memory_order_relaxed);
  for (std::size_t b = 0; b < bodies_.size(); ++b) last_reach_[b].assign(bodies_[b].rest_m->size(), 0);
  thread_ = std::thread([this] { run(); });
}

ColumnWorker::~ColumnWorker() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

void ColumnWorker::post(const std::vector<ToolPose>& poses) {
  int n = 0;
  for (const ToolPose& p : poses) {
    if (n + 2 > static_cast<int>(posting_.parts.size())) break;
    if (p.tool < 0 || p.tool >= static_cast<int>(tools_.size())) continue;
    const ToolShape& s = tools_[p.tool];
    const double len = p.axis.norm();
    const Vec3 axis = len > 0.0 ? Vec3(p.axis / len) : Vec3::UnitZ();
    posting_.parts[n++] = Part{p.tip_m, p.tip_m, s.tip_radius_m};
    if (s.shaft_radius_m > 0.0 && s.shaft_length_m > 0.0)
      posting_.parts[n++] = Part{p.tip_m, p.tip_m + s.shaft_length_m * axis, s.shaft_radius_m};
  }
  posting_.count = n;
  posting_.sequence = ++posted_;
  posted_last_.store(posted_, std::memory_order_release);
  poses_.publish(posting_);
}

bool ColumnWorker::wanted(const Poses& poses, int body, std::size_t most, std::vector<int>& out) {
  const ColumnWorkerBody& b = bodies_[body];
  const auto& rest = *b.rest_m;
  // (distance beyond the part's surface, slot) of every slot within reach that is not ready.
  std::vector<std::pair<double, int>>& near = near_;
  near.clear();
  const bool bounded = b.capacity_slots > 0;
  const std::uint64_t scan = ++scan_;
  std::size_t within = 0;
  for (int s = 0; s < static_cast<int>(rest.size()); ++s) {
    const bool ready = b.columns->has(s);
    if (ready && !bounded) continue;
    double best = std::numeric_limits<double>::infinity();
    for (int k = 0; k < poses.count; ++k) {
      const Part& p = poses.parts[k];
      const double d = (rest[s] - closest_on_segment(rest[s], p.p0, p.p1)).norm() - p.radius_m;
      best = std::min(best, d);
    }
    if (best <= lookahead_m_ + options_.idle_slack_m + b.behind_reach_m) {
      last_reach_[body][s] = scan;
      ++within;
      if (!ready) near.emplace_back(best, s);
    }
  }
  reach_slots_[static_cast<std::size_t>(body)] = within;
  if (near.empty()) return false;
  const std::size_t n = std::min(most, near.size());
  std::partial_sort(near.begin(), near.begin() + static_cast<std::ptrdiff_t>(n), near.end());
  out.clear();
  for (std::size_t k = 0; k < n; ++k) out.push_back(near[k].second);
  return true;
}

// A bounded body: room for at most `chunk` more slots. When the ready slots and a block would
// pass the bound, the ready slots outside the last scan's reach are proposed for eviction, least
// recently within reach first (the step grants those it does not hold, reclaim() frees them).
std::size_t ColumnWorker::room(int body, std::size_t chunk) {
  ColumnWorkerBody& b = bodies_[body];
  b.columns->reclaim();
  stuck_ = false;
  if (b.capacity_slots == 0) return chunk;
  // The bound, raised to the last scan's reach when that is larger: a bound below one pose's
  // reach would leave the rest of the reach unsolved for as long as the tool stays there.
  const std::size_t reach = reach_slots_[static_cast<std::size_t>(body)];
  const std::size_t capacity = std::max(b.capacity_slots, reach);
  if (capacity > b.capacity_slots) {
    std::atomic<std::size_t>& raised = raised_[static_cast<std::size_t>(body)];
    if (capacity > raised.load(std::memory_order_relaxed)) raised.store(capacity, std::memory_order_release);
  }
  const std::size_t ready = b.columns->size();
  if (ready + chunk > capacity) {
    old_.clear();
    const auto& last = last_reach_[body];
    for (int s = 0; s < static_cast<int>(last.size()); ++s)
      if (b.columns->has(s) && last[s] != scan_) old_.emplace_back(last[s], s);
    const std::size_t want = std::min<std::size_t>(
        {ready + chunk - capacity, old_.size(), ContactColumns::kMaxVictims});
    if (want > 0) {
      std::partial_sort(old_.begin(), old_.begin() + static_cast<std::ptrdiff_t>(want), old_.end());
      victims_.clear();
      for (std::size_t k = 0; k < want; ++k) victims_.push_back(old_[k].second);
      if (b.columns->propose_eviction(victims_))
        proposed_.fetch_add(want, std::memory_order_acq_rel);
    }
  }
  if (ready < capacity) return std::min(chunk, capacity - ready);
  // Full: an eviction pending (or just proposed) frees room soon; none possible: stuck.
  stuck_ = old_.empty();
  return 0;
}

// Whether every part of `now` lies within `slack` of the same part of `then` (then each point a
// part of `now` reaches lies within reach + slack of `then`'s).
bool ColumnWorker::within_slack(const Poses& now, const Poses& then, double slack) {
  if (now.count != then.count) return false;
  for (int k = 0; k < now.count; ++k) {
    const Part &a = now.parts[k], &b = then.parts[k];
    if ((a.p0 - b.p0).norm() > slack || (a.p1 - b.p1).norm() > slack || a.radius_m != b.radius_m)
      return false;
  }
  return true;
}

void ColumnWorker::run() {
  pthread_setname_np(pthread_self(), "ns-columns");
  // Below the other normal threads (nice 10 by default): on a loaded machine the step (and,
  // without real-time priority, the DDS and field threads) go first; a lagging worker only means
  // more rows take the fallback. Lowering one's own priority needs no privilege.
  if (options_.nice != 0) setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), options_.nice);
  // Its block solves go through CHOLMOD: with OMP_NUM_THREADS=1, any parallel region of it runs
  // on this thread alone (cholmod_threads.hpp).
  fem::cholmod_threads_follow_omp_num_threads();
  Poses poses;
  Poses idle_poses;         // the poses of the last scan that found nothing to solve
  bool idle_valid = false;  // nothing within reach + slack of idle_poses is missing
  std::vector<int> slots;
  const auto idle = std::chrono::duration<double>(options_.idle_sleep_s);
  const std::size_t chunk = static_cast<std::size_t>(CoupledBody::kBlockColumns / 3);
  while (!stop_.load(std::memory_order_acquire)) {
    poses_.take(poses);
    // Evictions the step granted are freed now, whether or not this body needs room next.
    for (auto& b : bodies_) b.columns->reclaim();
    bool worked = false;
    if (paused_.load(std::memory_order_acquire)) {
      idle_valid = false;
      std::this_thread::sleep_for(idle);
      continue;
    }
    // A tool that moved less than the slack since a scan found everything ready needs nothing
    // new: no scan (a fine mesh's scan costs ~0.1 ms).
    if (idle_valid && within_slack(poses, idle_poses, options_.idle_slack_m)) {
      idle_at_.store(poses.sequence, std::memory_order_release);
      std::this_thread::sleep_for(idle);
      continue;
    }
    bool waiting = false;  // a bounded body is full: the step's grant or the tool's move awaited
    for (int b = 0; b < static_cast<int>(bodies_.size()) && poses.count > 0; ++b) {
      if (stop_.load(std::memory_order_acquire)) return;
      if (!wanted(poses, b, chunk, slots)) continue;
      const std::size_t n_room = room(b, slots.size());
      if (n_room == 0) {
        if (stuck_) capacity_full_.fetch_add(1, std::memory_order_acq_rel);
        waiting = true;
        continue;
      }
      if (slots.size() > n_room) slots.resize(n_room);
      try {
        const int n = bodies_[b].columns->ensure(slots, workspaces_[static_cast<std::size_t>(b)]);
        solved_.fetch_add(static_cast<std::uint64_t>(n), std::memory_order_acq_rel);
      } catch (const std::exception&) {
        // A failed solve (out of memory, CHOLMOD): the worker stops; the step keeps stepping
        // with the columns it has and counts the rest as not ready.
        failed_.store(true, std::memory_order_release);
        return;
      }
      worked = true;
      break;  // the newest poses first, then this body again
    }
    if (!worked && waiting) {
      // Full: look again soon (the step grants at its next start; the tool may move on). With
      // nothing to evict the worker has done what it can for these poses (wait_ready).
      idle_valid = false;
      if (stuck_) idle_at_.store(poses.sequence, std::memory_order_release);
      std::this_thread::sleep_for(idle);
      continue;
    }
    idle_valid = !worked;
    if (!worked) {
      idle_poses = poses;
      idle_at_.store(poses.sequence, std::memory_order_release);
      std::this_thread::sleep_for(idle);
    }
  }
}

bool ColumnWorker::wait_ready(double timeout_s) const {
  const auto t0 = std::chrono::steady_clock::now();
  const std::uint64_t want = posted_last_.load(std::memory_order_acquire);
  while (idle_at_.load(std::memory_order_acquire) < want) {
    if (failed()) return false;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s)
      return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace neurosim::interaction
