// neurosim-web's bridge: the DDS side (DdsSource, read-only), the clients (Hub) and the HTTP /
// WebSocket side (HttpServer), put together. Depends on the contracts in idl/ only.
#pragma once

#include "web/access_token.hpp"
#include "web/dds_source.hpp"
#include "web/http_server.hpp"

#include <functional>
#include <memory>
#include <string>

namespace neurosim::web {

struct BridgeOptions {
  HttpServerOptions http;  // address, port, timeouts
  std::size_t max_clients = 16;
  std::string page_dir;  // the bundled page (index.html, app.js, style.css)
  DdsSourceOptions dds;  // domain, topic prefix
};

class Bridge {
 public:
  using Log = std::function<void(const std::string&)>;
  // Reads the page, joins DDS, starts listening. Throws std::runtime_error naming what failed
  // (a page file, DDS, the listening address).
  Bridge(const BridgeOptions& options, AccessToken token, Log log);
  ~Bridge();

  int port() const;
  // What /api/stats returns, a JSON document: clients (per client: frames sent and dropped,
  // bytes), DDS counters, server alive, resident memory.
  std::string stats() const;

 private:
  std::unique_ptr<Hub> hub_;
  std::unique_ptr<DdsSource> dds_;
  std::unique_ptr<HttpServer> http_;
};

// Resident set size of this process (VmRSS), unit KiB; 0 when it cannot be read.
long resident_kib();

}  // namespace neurosim::web
