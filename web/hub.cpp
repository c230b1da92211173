#include "web/hub.hpp"

#include <algorithm>

namespace neurosim::web {

Hub::Hub(HubOptions options) : options_(options) {}

std::shared_ptr<ClientOutbox> Hub::join(std::string peer) {
  std::lock_guard<std::mutex> lk(m_);
  if (clients_.size() >= options_.max_clients) {
    ++refused_;
    return nullptr;
  }
  auto outbox = std::make_shared<ClientOutbox>(next_id_++, std::move(peer));
  if (topology_) outbox->put_topology(topology_);
  if (status_) outbox->put_status(status_);
  if (stations_) outbox->put_stations(stations_);
  for (const auto& [mesh, f] : frames_) outbox->put_frame(f);
  clients_.push_back(outbox);
  ++joined_;
  return outbox;
}

void Hub::leave(const std::shared_ptr<ClientOutbox>& outbox) {
  if (!outbox) return;
  outbox->close();
  std::lock_guard<std::mutex> lk(m_);
  clients_.erase(std::remove(clients_.begin(), clients_.end(), outbox), clients_.end());
}

void Hub::close_all() {
  std::lock_guard<std::mutex> lk(m_);
  for (auto& c : clients_) c->close();
}

void Hub::publish_topology(TopologyPtr topology) {
  std::lock_guard<std::mutex> lk(m_);
  topology_ = topology;
  frames_.clear();
  for (auto& c : clients_) c->put_topology(topology);
}

void Hub::publish_frame(FramePtr frame) {
  std::lock_guard<std::mutex> lk(m_);
  if (!topology_ || frame->generation != topology_->generation) return;
  frames_[frame->mesh_index] = frame;
  for (auto& c : clients_) c->put_frame(frame);
}

void Hub::publish_status(MessagePtr status) {
  std::lock_guard<std::mutex> lk(m_);
  status_ = status;
  for (auto& c : clients_) c->put_status(status);
}

void Hub::publish_stations(MessagePtr stations) {
  std::lock_guard<std::mutex> lk(m_);
  stations_ = stations;
  for (auto& c : clients_) c->put_stations(stations);
}

std::size_t Hub::clients() const {
  std::lock_guard<std::mutex> lk(m_);
  return clients_.size();
}

HubCounters Hub::counters() const {
  std::lock_guard<std::mutex> lk(m_);
  HubCounters c;
  c.clients = clients_.size();
  c.max_clients = options_.max_clients;
  c.joined = joined_;
  c.refused = refused_;
  for (const auto& o : clients_) c.per_client.push_back(o->counters());
  return c;
}

}  // namespace neurosim::web
