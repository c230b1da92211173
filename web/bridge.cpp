#include "web/bridge.hpp"

#include "common/json.hpp"
#include "common/process_stats.hpp"

#include <algorithm>
#include <fstream>
#include <string>

namespace neurosim::web {

long resident_kib() { return std::max(0L, common::resident_kib()); }

Bridge::Bridge(const BridgeOptions& options, AccessToken token, Log log) {
  PageFiles page = PageFiles::load(options.page_dir);
  HubOptions ho;
  ho.max_clients = options.max_clients;
  hub_ = std::make_unique<Hub>(ho);
  dds_ = std::make_unique<DdsSource>(options.dds, *hub_, log);
  http_ = std::make_unique<HttpServer>(
      options.http, std::move(token), std::move(page), *hub_, [this] { return stats(); }, log);
}

// The listener goes first (no new client), then DDS (nothing more published), then the hub.
Bridge::~Bridge() {
  http_.reset();
  dds_.reset();
}

int Bridge::port() const { return http_->port(); }

std::string Bridge::stats() const {
  const HubCounters h = hub_->counters();
  const ObserverCounters o = dds_->counters();
  common::Json clients = common::Json::array();
  for (const ClientCounters& c : h.per_client)
    clients.push_back({{"id", c.id},
                       {"peer", c.peer},
                       {"connected_s", c.connected_s},
                       {"messages_sent", c.messages_sent},
                       {"frames_sent", c.frames_sent},
                       {"keyframes_sent", c.keyframes_sent},
                       {"frames_dropped", c.frames_dropped},
                       {"bytes_sent", c.bytes_sent},
                       {"failed", c.failed}});
  return common::Json{{"clients", h.clients},
                      {"max_clients", h.max_clients},
                      {"joined", h.joined},
                      {"refused", h.refused},
                      {"per_client", std::move(clients)},
                      {"server_alive", dds_->server_alive()},
                      {"dds",
                       {{"topologies", o.topologies},
                        {"frames", o.frames},
                        {"frames_waiting", o.frames_waiting},
                        {"contacts", o.contacts},
                        {"statuses", o.statuses},
                        {"malformed", o.malformed_topology + o.malformed_frame +
                                          o.malformed_contact + o.malformed_status},
                        {"server_seen", o.server_seen},
                        {"server_lost", o.server_lost}}},
                      {"resident_kib", resident_kib()}}
             .dump(2) +
         "\n";
}

}  // namespace neurosim::web
