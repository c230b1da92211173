#include "web/http_server.hpp"

#include "web/client_session.hpp"

#include <civetweb.h>

#include <cstring>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

namespace neurosim::web {

namespace {

// Every response: nothing cached (the token is in the URL), no sniffing, no referrer (the token
// must not leave in a Referer header), and the page may load and connect to this origin only.
constexpr const char* kCommonHeaders =
    "Cache-Control: no-store\r\n"
    "X-Content-Type-Options: nosniff\r\n"
    "Referrer-Policy: no-referrer\r\n"
    "Content-Security-Policy: default-src 'self'; img-src 'self' data:; connect-src 'self'; "
    "frame-ancestors 'none'\r\n"
    "Connection: close\r\n";

void respond(mg_connection* conn, int status, const char* reason, const std::string& type,
             const std::string& body, const char* extra_headers = "") {
  const mg_request_info* ri = mg_get_request_info(conn);
  const bool head = ri != nullptr && std::strcmp(ri->request_method, "HEAD") == 0;
  mg_printf(conn, "HTTP/1.1 %d %s\r\nContent-Type: %s\r\nContent-Length: %zu\r\n%s%s\r\n", status,
            reason, type.c_str(), body.size(), kCommonHeaders, extra_headers);
  if (!head && !body.empty()) mg_write(conn, body.data(), body.size());
}

// One WebSocket connection: its outbox (null: refused) and its sender thread.
struct Connection {
  std::shared_ptr<ClientOutbox> outbox;
  std::thread sender;
};

std::string peer_of(const mg_connection* conn) {
  const mg_request_info* ri = mg_get_request_info(conn);
  if (ri == nullptr) return "?";
  return std::string(ri->remote_addr) + ":" + std::to_string(ri->remote_port);
}

}  // namespace

struct HttpServer::Impl {
  HttpServerOptions options;
  AccessToken token;
  PageFiles page;
  Hub& hub;
  Stats stats;
  Log log;
  mg_context* ctx = nullptr;
  int port = 0;

  Impl(const HttpServerOptions& o, AccessToken t, PageFiles p, Hub& h, Stats s, Log l)
      : options(o),
        token(std::move(t)),
        page(std::move(p)),
        hub(h),
        stats(std::move(s)),
        log(std::move(l)) {}

  // The token of a request: the URL parameter `token`, else an Authorization: Bearer header.
  // Sets from_query when it came in the URL.
  bool authorized(mg_connection* conn, bool& from_query) const {
    from_query = false;
    const mg_request_info* ri = mg_get_request_info(conn);
    if (ri->query_string != nullptr) {
      char buf[kMaxTokenLength + 2];
      const int n =
          mg_get_var(ri->query_string, std::strlen(ri->query_string), "token", buf, sizeof buf);
      if (n >= 0 && token.matches(std::string_view(buf, static_cast<std::size_t>(n)))) {
        from_query = true;
        return true;
      }
    }
    if (const char* h = mg_get_header(conn, "Authorization"))
      if (token.matches(AccessToken::bearer(h))) return true;
    return false;
  }

  // Before any handler: methods and the access token. Returns 0 to go on to the handlers.
  static int begin_request(mg_connection* conn) {
    auto* im = static_cast<Impl*>(mg_get_user_data(mg_get_context(conn)));
    const mg_request_info* ri = mg_get_request_info(conn);
    if (std::strcmp(ri->request_method, "GET") != 0 &&
        std::strcmp(ri->request_method, "HEAD") != 0) {
      respond(conn, 405, "Method Not Allowed", "text/plain; charset=utf-8",
              "neurosim-web is read-only: GET and HEAD only\n", "Allow: GET, HEAD\r\n");
      return 405;
    }
    bool from_query = false;
    if (!im->authorized(conn, from_query)) {
      respond(conn, 401, "Unauthorized", "text/plain; charset=utf-8",
              "neurosim-web: an access token is required: open the URL with ?token=TOKEN, or send "
              "the header Authorization: Bearer TOKEN\n",
              "WWW-Authenticate: Bearer realm=\"neurosim-web\"\r\n");
      return 401;
    }
    return 0;
  }

  static int log_message(const mg_connection* conn, const char* message) {
    auto* im = static_cast<Impl*>(mg_get_user_data(mg_get_context(conn)));
    if (im != nullptr && im->log) im->log(std::string("neurosim-web: http: ") + message);
    return 1;
  }

  static int page_handler(mg_connection* conn, void* cb) {
    auto* im = static_cast<Impl*>(cb);
    const mg_request_info* ri = mg_get_request_info(conn);
    const PageFile* f = im->page.find(ri->local_uri);
    if (f == nullptr) {
      respond(conn, 404, "Not Found", "text/plain; charset=utf-8", "not found\n");
      return 404;
    }
    if (f->path == "/index.html") {
      // The page's own URLs carry the token when the page was opened with it.
      bool from_query = false;
      im->authorized(conn, from_query);
      std::string query;
      if (from_query) query = "?token=" + im->token.text();  // URL-safe characters only
      respond(conn, 200, "OK", f->content_type, im->page.index_html(query));
    } else {
      respond(conn, 200, "OK", f->content_type, f->body);
    }
    return 200;
  }

  static int stats_handler(mg_connection* conn, void* cb) {
    auto* im = static_cast<Impl*>(cb);
    respond(conn, 200, "OK", "application/json", im->stats());
    return 200;
  }

  static int ws_connect(const mg_connection*, void*) { return 0; }  // the token was checked

  // After the handshake (so the close handler always follows): join the hub or be refused.
  static void ws_ready(mg_connection* conn, void* cb) {
    auto* im = static_cast<Impl*>(cb);
    auto* c = new Connection;
    mg_set_user_connection_data(conn, c);
    const std::string peer = peer_of(conn);
    c->outbox = im->hub.join(peer);
    if (!c->outbox) {
      const std::string reason = "neurosim-web serves at most " +
                                 std::to_string(im->hub.max_clients()) +
                                 " clients; try again later";
      const std::string refused = "{\"type\":\"refused\",\"reason\":\"" + reason + "\"}";
      mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_TEXT, refused.data(), refused.size());
      // Close frame: status 1013 (try again later), then the reason (at most 123 bytes).
      std::string close_payload{static_cast<char>(1013 >> 8), static_cast<char>(1013 & 0xff)};
      close_payload += reason.substr(0, 123);
      mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, close_payload.data(),
                         close_payload.size());
      if (im->log) im->log("neurosim-web: client " + peer + " refused: " + reason);
      return;
    }
    if (im->log)
      im->log("neurosim-web: client " + std::to_string(c->outbox->id()) + " (" + peer +
              ") joined; " + std::to_string(im->hub.clients()) + " of " +
              std::to_string(im->hub.max_clients()));
    c->sender = std::thread([conn, outbox = c->outbox] {
      ClientSession session(outbox, [conn](const Message& m) {
        const int op = m.binary ? MG_WEBSOCKET_OPCODE_BINARY : MG_WEBSOCKET_OPCODE_TEXT;
        const int n = mg_websocket_write(conn, op, m.bytes.data(), m.bytes.size());
        return m.bytes.empty() ? n >= 0 : n == static_cast<int>(m.bytes.size());
      });
      session.run();
    });
  }

  static int ws_data(mg_connection*, int bits, char*, size_t, void*) {
    // The page sends nothing; a close frame ends the connection.
    return (bits & 0x0f) == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE ? 0 : 1;
  }

  static void ws_close(const mg_connection* cconn, void* cb) {
    auto* im = static_cast<Impl*>(cb);
    auto* conn = const_cast<mg_connection*>(cconn);
    auto* c = static_cast<Connection*>(mg_get_user_connection_data(conn));
    if (c == nullptr) return;
    mg_set_user_connection_data(conn, nullptr);
    if (c->outbox) {
      const ClientCounters k = c->outbox->counters();
      im->hub.leave(c->outbox);  // closes the outbox: the sender stops
      if (c->sender.joinable()) c->sender.join();
      if (im->log)
        im->log("neurosim-web: client " + std::to_string(k.id) + " (" + k.peer + ") left after " +
                std::to_string(static_cast<long long>(k.connected_s)) +
                " s: " + std::to_string(k.frames_sent) + " frames sent, " +
                std::to_string(k.frames_dropped) + " dropped" + (k.failed ? ", send failed" : ""));
    }
    delete c;
  }
};

HttpServer::HttpServer(const HttpServerOptions& options, AccessToken token, PageFiles page,
                       Hub& hub, Stats stats, Log log)
    : impl_(std::make_unique<Impl>(options, std::move(token), std::move(page), hub,
                                   std::move(stats), std::move(log))) {
  static std::once_flag init;
  std::call_once(init, [] { mg_init_library(0); });
  Impl& im = *impl_;
  const std::string listen = options.address + ":" + std::to_string(options.port);
  // One worker per WebSocket client (its read loop), one for the refused one, the rest for the
  // page and /api/stats.
  const std::string threads = std::to_string(hub.max_clients() + 6);
  const std::string write_ms = std::to_string(static_cast<long>(options.write_timeout_s * 1000));
  const std::string ping_ms = std::to_string(static_cast<long>(options.ping_period_s * 1000));
  const char* cfg[] = {"listening_ports",
                       listen.c_str(),
                       "num_threads",
                       threads.c_str(),
                       "request_timeout_ms",
                       write_ms.c_str(),
                       "websocket_timeout_ms",
                       ping_ms.c_str(),
                       "enable_websocket_ping_pong",
                       "yes",
                       "enable_keep_alive",
                       "no",
                       nullptr};
  mg_callbacks callbacks{};
  callbacks.begin_request = &Impl::begin_request;
  callbacks.log_message = &Impl::log_message;
  im.ctx = mg_start(&callbacks, &im, cfg);
  if (im.ctx == nullptr)
    throw std::runtime_error("cannot listen on " + listen +
                             " (address not on this machine, or port in use)");
  for (const PageFile& f : im.page.files())
    mg_set_request_handler(im.ctx, f.path.c_str(), &Impl::page_handler, &im);
  mg_set_request_handler(im.ctx, "/", &Impl::page_handler, &im);
  mg_set_request_handler(im.ctx, "/api/stats", &Impl::stats_handler, &im);
  mg_set_websocket_handler(im.ctx, "/ws", &Impl::ws_connect, &Impl::ws_ready, &Impl::ws_data,
                           &Impl::ws_close, &im);
  mg_server_port ports[4]{};
  const int n = mg_get_server_ports(im.ctx, 4, ports);
  if (n < 1) {
    mg_stop(im.ctx);
    throw std::runtime_error("cannot listen on " + listen);
  }
  im.port = ports[0].port;
}

HttpServer::~HttpServer() {
  impl_->hub.close_all();
  mg_stop(impl_->ctx);
}

int HttpServer::port() const { return impl_->port; }

}  // namespace neurosim::web
