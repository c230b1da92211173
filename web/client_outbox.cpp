#include "web/client_outbox.hpp"

#include "common/clock.hpp"

namespace neurosim::web {

ClientOutbox::ClientOutbox(std::uint64_t id, std::string peer)
    : id_(id), peer_(std::move(peer)), connected_(std::chrono::steady_clock::now()) {}

void ClientOutbox::put_topology(TopologyPtr topology) {
  {
    std::lock_guard<std::mutex> lk(m_);
    if (closed_) return;
    for (auto it = pending_.frames.begin(); it != pending_.frames.end();) {
      if (it->second->generation != topology->generation) {
        ++counters_.frames_dropped;
        it = pending_.frames.erase(it);
      } else {
        ++it;
      }
    }
    pending_.topology = std::move(topology);
  }
  cv_.notify_one();
}

void ClientOutbox::put_frame(FramePtr frame) {
  {
    std::lock_guard<std::mutex> lk(m_);
    if (closed_) return;
    FramePtr& slot = pending_.frames[frame->mesh_index];
    if (slot) ++counters_.frames_dropped;  // latest wins
    slot = std::move(frame);
  }
  cv_.notify_one();
}

void ClientOutbox::put_status(MessagePtr status) {
  {
    std::lock_guard<std::mutex> lk(m_);
    if (closed_) return;
    pending_.status = std::move(status);
  }
  cv_.notify_one();
}

void ClientOutbox::put_stations(MessagePtr stations) {
  {
    std::lock_guard<std::mutex> lk(m_);
    if (closed_) return;
    pending_.stations = std::move(stations);
  }
  cv_.notify_one();
}

void ClientOutbox::close() {
  {
    std::lock_guard<std::mutex> lk(m_);
    closed_ = true;
    pending_ = Pending{};
  }
  cv_.notify_all();
}

bool ClientOutbox::closed() const {
  std::lock_guard<std::mutex> lk(m_);
  return closed_;
}

bool ClientOutbox::take(Pending& out, std::chrono::milliseconds timeout) {
  out = Pending{};
  std::unique_lock<std::mutex> lk(m_);
  cv_.wait_for(lk, timeout, [this] { return closed_ || !pending_.empty(); });
  if (closed_) return false;
  std::swap(out, pending_);
  return true;
}

void ClientOutbox::note_sent(std::size_t bytes, bool frame, bool keyframe) {
  std::lock_guard<std::mutex> lk(m_);
  ++counters_.messages_sent;
  counters_.bytes_sent += bytes;
  if (frame) ++counters_.frames_sent;
  if (keyframe) ++counters_.keyframes_sent;
}

void ClientOutbox::note_failed() {
  std::lock_guard<std::mutex> lk(m_);
  counters_.failed = true;
}

void ClientOutbox::note_dropped(std::uint64_t frames) {
  std::lock_guard<std::mutex> lk(m_);
  counters_.frames_dropped += frames;
}

ClientCounters ClientOutbox::counters() const {
  std::lock_guard<std::mutex> lk(m_);
  ClientCounters c = counters_;
  c.id = id_;
  c.peer = peer_;
  c.connected_s = common::seconds_since(connected_);
  return c;
}

}  // namespace neurosim::web
