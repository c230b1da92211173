#include "web/client_session.hpp"

namespace neurosim::web {

ClientSession::ClientSession(std::shared_ptr<ClientOutbox> outbox, Send send)
    : outbox_(std::move(outbox)), send_(std::move(send)) {}

bool ClientSession::write(const Message& m, bool frame, bool keyframe) {
  if (!send_(m)) {
    outbox_->note_failed();
    return false;
  }
  outbox_->note_sent(m.bytes.size(), frame, keyframe);
  return true;
}

bool ClientSession::send(ClientOutbox::Pending& batch) {
  if (batch.topology) {
    for (const MessagePtr& m : batch.topology->messages)
      if (!write(*m, false, false)) return false;
    have_topology_ = true;
    generation_ = batch.topology->generation;
    full_serial_.assign(batch.topology->meshes, 0);  // nothing decodable yet
  }
  if (batch.status && !write(*batch.status, false, false)) return false;
  if (batch.stations && !write(*batch.stations, false, false)) return false;
  std::uint64_t skipped = 0;
  for (const auto& [mesh, f] : batch.frames) {
    if (!have_topology_ || f->generation != generation_ || mesh >= full_serial_.size()) {
      ++skipped;
      continue;
    }
    if (!f->full && full_serial_[mesh] != f->full_serial) {
      if (!f->base) {
        ++skipped;
        continue;
      }
      if (!write(f->base->message, true, true)) return false;
      full_serial_[mesh] = f->full_serial;
    }
    if (!write(f->message, true, false)) return false;
    if (f->full) full_serial_[mesh] = f->full_serial;
  }
  if (skipped > 0) outbox_->note_dropped(skipped);
  return true;
}

void ClientSession::run(std::chrono::milliseconds poll) {
  ClientOutbox::Pending batch;
  while (outbox_->take(batch, poll)) {
    if (batch.empty()) continue;
    if (!send(batch)) return;
  }
}

}  // namespace neurosim::web
