// The bridge's HTTP and WebSocket side (CivetWeb, web/README.md "Why CivetWeb"): listens on one
// address only, checks the access token on every request (401 without it), serves the page
// files, /api/stats and the WebSocket /ws. Each WebSocket client gets an outbox from the Hub and
// a sender thread (ClientSession); the (max_clients + 1)-th is told it is refused and closed
// (close code 1013, "try again later"). Nothing more is sent to a client whose socket takes
// nothing for write_timeout_s; a client that sends nothing is pinged every ping_period_s and
// closed after five unanswered pings (browsers answer pings by themselves).
#pragma once

#include "web/access_token.hpp"
#include "web/hub.hpp"
#include "web/page_files.hpp"

#include <functional>
#include <memory>
#include <string>

namespace neurosim::web {

struct HttpServerOptions {
  std::string address = "127.0.0.1";  // IPv4 address to listen on (nothing else is opened)
  int port = 8090;                    // 0: any free port (see port())
  double write_timeout_s = 5;         // a send without progress this long fails, unit s
  double ping_period_s = 2;           // ping a silent WebSocket client this often, unit s
};

class HttpServer {
 public:
  using Stats = std::function<std::string()>;  // /api/stats: a JSON document
  using Log = std::function<void(const std::string&)>;
  // Starts listening. Throws std::runtime_error naming the address when it cannot.
  HttpServer(const HttpServerOptions& options, AccessToken token, PageFiles page, Hub& hub,
             Stats stats, Log log);
  ~HttpServer();  // closes every client and stops
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  int port() const;  // the port listened on (the one picked when options.port was 0)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace neurosim::web
