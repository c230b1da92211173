#include "server/service/deformation_publisher.hpp"

#include "server/fem/strain.hpp"

#include <algorithm>
#include <chrono>

namespace neurosim::service {

DeformationPublisher::DeformationPublisher(interaction::Simulation& sim, const wire::Participant& pp,
                                           const std::string& topic_prefix, std::uint32_t full_frame_period,
                                           std::function<void(const std::string&)> log)
    : sim_(sim),
      log_(std::move(log)),
      topic_(pp, wire::topic_name<neurosim_Deformation>(topic_prefix)),
      writer_(pp, topic_) {
  wire::DeformationEncoderOptions eo;
  eo.full_frame_period = full_frame_period;
  for (int m = 0; m < sim_.num_meshes(); ++m) {
    encoders_.emplace_back(sim_.mesh_id(m), sim_.mesh(m).num_vertices(), 1, eo);
    out_.emplace_back();
    u_m_.emplace_back(Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(sim_.mesh(m).num_vertices())));
  }
  written_.assign(static_cast<std::size_t>(sim_.num_meshes()), false);
}

DeformationPublisher::~DeformationPublisher() { stop(); }

void DeformationPublisher::start(std::function<void()> on_start,
                                 std::function<void(const std::exception&)> on_error) {
  thread_ = std::thread([this, on_start = std::move(on_start), on_error = std::move(on_error)] {
    try {
      if (on_start) on_start();
      field_loop();
    } catch (const std::exception& e) {
      busy_.store(false, std::memory_order_release);
      if (on_error) on_error(e);
    }
  });
}

void DeformationPublisher::stop() {
  {
    std::lock_guard<std::mutex> lk(m_);  // so the worker cannot miss the wake-up
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void DeformationPublisher::tick(std::uint64_t step, std::int64_t now_ns) {
  const std::uint32_t matched = writer_.matched_readers();
  // A viewer that just matched decodes from the next frame on.
  if (matched > last_matched_viewers_) full_frame_pending_ = true;
  last_matched_viewers_ = matched;
  if (matched == 0) return;
  // Worker still on the previous frame: skip this one rather than wait.
  if (busy_.load(std::memory_order_acquire)) {
    ++counters_.skipped;
    return;
  }
  const bool strain = strain_due_.load(std::memory_order_relaxed);
  if (strain) strain_due_.store(false, std::memory_order_relaxed);
  sim_.snapshot(snapshot_);
  busy_.store(true, std::memory_order_release);
  {
    std::lock_guard<std::mutex> lk(m_);
    job_step_ = step;
    job_time_ns_ = now_ns;
    job_strain_ = strain;
    job_ = true;
  }
  cv_.notify_one();
}

double DeformationPublisher::take_max_strain() {
  strain_due_.store(true, std::memory_order_relaxed);
  if (last_matched_viewers_ == 0) max_strain_.store(-1.0, std::memory_order_relaxed);
  return max_strain_.load(std::memory_order_relaxed);
}

bool DeformationPublisher::wait_idle(int timeout_ms) const {
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (busy_.load(std::memory_order_acquire)) {
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

void DeformationPublisher::encode_and_write(std::uint64_t step, std::int64_t now_ns, bool strain) {
  if (full_frame_pending_.exchange(false))
    for (auto& e : encoders_) e.force_full_next();
  double max_strain = 0.0;
  for (int m = 0; m < sim_.num_meshes(); ++m) {
    const auto mi = static_cast<std::size_t>(m);
    auto& u = u_m_[mi];
    sim_.displacements(snapshot_, m, u);
    ++counters_.full_field_solves;
    if (strain && sim_.mesh_active(m))
      max_strain = std::max(max_strain, fem::max_principal_strain(sim_.mesh(m), u).max_strain);
    auto& out = *out_[mi];
    encoders_[mi].encode(u.data(), static_cast<std::size_t>(u.size()), step, now_ns, out);
    writer_.write(out);
    written_[mi] = true;
    ++counters_.frames;
  }
  if (strain) max_strain_.store(max_strain, std::memory_order_relaxed);
}

// Field thread: full-field solves and Deformation writes, off the step thread.
void DeformationPublisher::field_loop() {
  for (;;) {
    std::uint64_t step = 0;
    std::int64_t t = 0;
    bool strain = false;
    {
      std::unique_lock<std::mutex> lk(m_);
      cv_.wait(lk, [&] { return job_ || stopping_; });
      if (stopping_) return;
      job_ = false;
      step = job_step_;
      t = job_time_ns_;
      strain = job_strain_;
    }
    encode_and_write(step, t, strain);
    busy_.store(false, std::memory_order_release);
  }
}

void DeformationPublisher::dispose_all() {
  for (std::size_t m = 0; m < out_.size(); ++m)
    if (written_[m]) {
      wire::set_string(out_[m]->mesh_id, sim_.mesh_id(static_cast<int>(m)), "mesh_id");
      writer_.dispose(*out_[m]);
      written_[m] = false;
    }
}

}  // namespace neurosim::service
