// ColumnWorker: the coupled compliance columns of the contact nodes a tool can reach soon, solved
// on a thread of its own ahead of the tool, so the step never solves one.
//
//   step thread:   post(poses)            (every step; a triple buffer, never blocks)
//   worker thread: newest poses -> the contact slots within reach, nearest first, that are not
//                  ready -> one block solve of up to CoupledBody::kBlockColumns / 3 slots with
//                  its own fem::SolveWorkspace -> each slot published in the State's
//                  ContactColumns (contact_columns.hpp: written once, release/acquire flag)
//
// Reach: a contact node is wanted when its rest position lies within
//   part radius + max_tool_speed_m_per_s x horizon_s + idle_slack_m + the body's behind reach
// of a tool part (the tip sphere, the shaft capsule): the surface the tool can touch within the
// horizon at the tool's maximum speed (defaults: 0.5 m/s for 50 ms, 25 mm, so a tool sliding at
// 20 mm/s sees its next 1.25 s of surface ready). Nearest first (distance to the part's surface),
// so a tool faster than the assumption still finds the surface right under it solved first.
// The worker never takes a lock the step takes and never touches the step's solve scratch; the
// step handles a row whose columns are not ready yet by a fallback (contact_step.cpp,
// compliance_columns) and counts them (StepStats::columns_not_ready).
#pragma once

#include "server/fem/static_solver.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/tool_geometry.hpp"

#include "common/triple_buffer.hpp"

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <utility>
#include <vector>

namespace neurosim::interaction {

class ContactColumns;

// Defaults for SimulationOptions::column_worker.
struct ColumnWorkerOptions {
  double horizon_s{0.05};              // how far ahead of the tool, unit s
  double max_tool_speed_m_per_s{0.5};  // the tool's fastest motion assumed, unit m/s
  double idle_sleep_s{0.001};          // nothing to solve: look again after this, unit s
  // The reach is solved this much wider, so a tool that moved less since everything was ready
  // needs no new scan of the surface, unit m.
  double idle_slack_m{0.001};
  // The thread's nice value, 0..19 (setpriority): by default below the other normal threads, so
  // on a loaded machine the step and the DDS threads go first and a lagging worker only means
  // more rows on the fallback. Tests that wait for the worker set 0: their counts do not depend
  // on its priority, but at nice 10 next to busy threads it gets a few % of a core.
  int nice{10};
};

// One body the worker fills: its contact slots' rest positions and the State's cache.
struct ColumnWorkerBody {
  const std::vector<mesh::Vec3>* rest_m{nullptr};  // per contact slot, unit m
  ContactColumns* columns{nullptr};
  double behind_reach_m{0.0};  // how far behind the surface a part still pushes it, unit m
  // At most this many slots ready at once (0: no bound). Before a block solve that would pass
  // it, the worker proposes the least recently reached ready slots for eviction (never one
  // within reach of the newest poses; the step keeps those it holds, contact_columns.hpp).
  // The bound may be passed by one block until the step grants. A bound below the reach of the
  // newest poses (more slots within reach than it) is raised to that reach while the poses need
  // it: below it, the reach beyond the bound would stay on the step's fallback for as long as the
  // tool stays (raised_capacity() reports the largest bound used).
  std::size_t capacity_slots{0};
};

class ColumnWorker {
 public:
  // Tools beyond this many in one post are not looked ahead of (their rows use the fallback).
  static constexpr int kMaxTools = 64;

  // Starts the thread (named "ns-columns", SCHED_OTHER at options.nice). bodies and tools must
  // outlive it.
  ColumnWorker(std::vector<ColumnWorkerBody> bodies, const std::vector<ToolShape>& tools,
               const ColumnWorkerOptions& options);
  ~ColumnWorker();  // stops and joins (a block solve under way finishes first)
  ColumnWorker(const ColumnWorker&) = delete;
  ColumnWorker& operator=(const ColumnWorker&) = delete;

  // Step thread: the poses the worker looks ahead of (no allocation, never waits).
  void post(const std::vector<ToolPose>& poses);
  // Columns this worker solved so far (any thread).
  std::uint64_t columns_solved() const { return solved_.load(std::memory_order_acquire); }
  // Tests and benchmarks: true once every slot within reach of the newest posted poses is ready,
  // or a bounded cache is full of slots within reach (waits at most timeout_s, unit s).
  bool wait_ready(double timeout_s) const;
  // Tests and benchmarks: a paused worker starts no solve (one under way finishes).
  void set_paused(bool paused) { paused_.store(paused, std::memory_order_release); }
  // A block solve threw (out of memory): the worker stopped; the cache keeps what it had.
  bool failed() const { return failed_.load(std::memory_order_acquire); }
  // Reach beyond a part's radius, unit m (max_tool_speed_m_per_s x horizon_s).
  double lookahead_m() const { return lookahead_m_; }
  // Slots proposed for eviction so far, and scans that found the cache full of slots within
  // reach (nothing to evict, a wanted slot left unsolved) (any thread).
  std::uint64_t evictions_proposed() const { return proposed_.load(std::memory_order_acquire); }
  std::uint64_t capacity_full() const { return capacity_full_.load(std::memory_order_acquire); }
  // The largest bound the worker used for a body whose capacity_slots was below the reach of
  // some poses (the most slots within reach of one post), 0 if the bound never had to be raised
  // (any thread).
  std::size_t raised_capacity(int body) const {
    return raised_[static_cast<std::size_t>(body)].load(std::memory_order_acquire);
  }

 private:
  struct Part {
    Vec3 p0{Vec3::Zero()}, p1{Vec3::Zero()};  // the tip centre, the shaft's far end (p0: a sphere)
    double radius_m{0.0};
  };
  struct Poses {
    int count{0};
    std::uint64_t sequence{0};
    std::array<Part, 2 * kMaxTools> parts{};
  };
  void run();
  static bool within_slack(const Poses& now, const Poses& then, double slack);
  // The nearest wanted slots that are not ready, at most `most`, of one body; false: none.
  // Stamps every slot within reach with this scan's number (last_reach_).
  bool wanted(const Poses& poses, int body, std::size_t most, std::vector<int>& out);
  // A bounded body: how many slots the next block may solve (proposing evictions when full).
  std::size_t room(int body, std::size_t chunk);

  std::vector<ColumnWorkerBody> bodies_;
  std::vector<ToolShape> tools_;
  ColumnWorkerOptions options_;
  double lookahead_m_{0.0};
  common::TripleBuffer<Poses> poses_;
  Poses posting_;  // step thread's staging copy
  std::uint64_t posted_{0};                   // step thread
  std::atomic<std::uint64_t> idle_at_{0};      // sequence of the poses whose reach is all ready
  std::atomic<std::uint64_t> posted_last_{0};  // the newest sequence posted (for wait_ready)
  std::vector<fem::SolveWorkspace> workspaces_;  // the worker's own, one per body
  std::atomic<std::uint64_t> solved_{0};
  std::atomic<bool> failed_{false};
  std::atomic<bool> paused_{false};
  std::vector<std::pair<double, int>> near_;  // worker: candidates (distance, slot)
  // Worker: per body and slot, the number of the last scan that found the slot within reach.
  std::vector<std::vector<std::uint64_t>> last_reach_;
  std::vector<std::size_t> reach_slots_;  // worker: per body, slots within reach at its last scan
  std::unique_ptr<std::atomic<std::size_t>[]> raised_;  // per body, raised_capacity()
  std::uint64_t scan_{0};
  bool stuck_{false};  // room(): full of slots within reach, nothing to evict
  std::vector<std::pair<std::uint64_t, int>> old_;  // worker: eviction candidates (scan, slot)
  std::vector<int> victims_;
  std::atomic<std::uint64_t> proposed_{0};
  std::atomic<std::uint64_t> capacity_full_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace neurosim::interaction
