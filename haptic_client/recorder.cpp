#include "haptic_client/recorder.hpp"

#include "idl/wire/recording_io.hpp"

#include <chrono>
#include <cstdio>
#include <stdexcept>

namespace neurosim::haptic {

struct Recorder::Writer {
  wire::RecordingWriter w;
  Writer(const std::string& f, recording::Header h) : w(f, std::move(h)) {}
};

Recorder::Recorder(const std::string& file, recording::Header header, bool blocking,
                   std::size_t capacity)
    : file_(file), ring_(capacity < 2 ? 2 : capacity), blocking_(blocking) {
  writer_ = std::make_unique<Writer>(file, std::move(header));
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() {
  try {
    close();
  } catch (...) {
    // Destructors do not throw; call close() to see the error.
  }
}

bool Recorder::push(const RecordSample& s) {
  const std::uint64_t h = head_.load(std::memory_order_relaxed);
  while (h - tail_.load(std::memory_order_acquire) >= ring_.size()) {
    if (!blocking_ || stop_.load()) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    std::this_thread::yield();
  }
  ring_[h % ring_.size()] = s;
  head_.store(h + 1, std::memory_order_release);
  return true;
}

void Recorder::run() {
  recording::Sample out;
  auto drain = [&] {
    std::uint64_t t = tail_.load(std::memory_order_relaxed);
    const std::uint64_t h = head_.load(std::memory_order_acquire);
    for (; t < h; ++t) {
      const RecordSample& s = ring_[t % ring_.size()];
      out.set_time_s(s.time_s);
      auto* p = out.mutable_position_m();
      p->set_x(s.position_m.x());
      p->set_y(s.position_m.y());
      p->set_z(s.position_m.z());
      auto* q = out.mutable_orientation();
      q->set_w(s.orientation[0]);
      q->set_x(s.orientation[1]);
      q->set_y(s.orientation[2]);
      q->set_z(s.orientation[3]);
      auto* v = out.mutable_velocity_m_per_s();
      v->set_x(s.velocity_m_per_s.x());
      v->set_y(s.velocity_m_per_s.y());
      v->set_z(s.velocity_m_per_s.z());
      out.set_buttons(s.buttons);
      auto* f = out.mutable_force_n();
      f->set_x(s.force_n.x());
      f->set_y(s.force_n.y());
      f->set_z(s.force_n.z());
      out.set_contact_model_sequence(s.contact_model_sequence);
      out.set_tool_sequence(s.tool_sequence);
      out.set_in_contact(s.in_contact);
      writer_->w.write(out);
      written_.fetch_add(1, std::memory_order_relaxed);
      tail_.store(t + 1, std::memory_order_release);
    }
  };
  try {
    while (!stop_.load(std::memory_order_acquire)) {
      drain();
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    drain();
  } catch (const std::exception& e) {
    // Said at once (the loop goes on without the recording; push() drops from now on).
    std::fprintf(stderr, "neurosim-haptic: %s; the session goes on without the recording\n",
                 e.what());
    {
      std::lock_guard<std::mutex> lock(error_mutex_);
      error_ = e.what();
    }
    failed_.store(true, std::memory_order_release);
    stop_ = true;
  }
}

void Recorder::close() {
  if (closed_) return;
  closed_ = true;
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
  if (failed_.load()) throw std::runtime_error(error_);
  writer_->w.close();
}

}  // namespace neurosim::haptic
