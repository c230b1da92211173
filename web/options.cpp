#include "web/options.hpp"

#include "common/cli.hpp"

#include <arpa/inet.h>

#include <stdexcept>

#ifndef NEUROSIM_WEB_PAGE_DIR
#error "NEUROSIM_WEB_PAGE_DIR must be defined (web/CMakeLists.txt: the bundled page's folder)"
#endif

namespace neurosim::web {

std::string default_page_dir() { return NEUROSIM_WEB_PAGE_DIR; }

void parse_listen(const std::string& text, HttpServerOptions& http) {
  const auto colon = text.rfind(':');
  const auto bad = [&](const std::string& why) {
    return cli::UsageError("--listen '" + text + "': " + why);
  };
  if (colon == std::string::npos) throw bad("expected ADDRESS:PORT, e.g. 127.0.0.1:8090");
  const std::string address = text.substr(0, colon), port = text.substr(colon + 1);
  in_addr a{};
  if (inet_pton(AF_INET, address.c_str(), &a) != 1)
    throw bad("'" + address + "' is not a dotted IPv4 address");
  if (port.empty() || port.size() > 5 ||
      port.find_first_not_of("0123456789") != std::string::npos || std::stol(port) > 65535)
    throw bad("port '" + port + "' is not a number in 0..65535");
  http.address = address;
  http.port = static_cast<int>(std::stol(port));
}

WebOptions parse_options(int argc, const char* const* argv, bool& help) {
  WebOptions o;
  help = false;
  std::string listen = "127.0.0.1:8090", token, token_file;
  int max_clients = static_cast<int>(o.bridge.max_clients);
  o.bridge.page_dir = default_page_dir();
  cli::Parser p("neurosim-web",
                "Read-only web observer: joins the simulation over DDS and serves a page that "
                "shows it to a browser (HTTP and WebSocket).");
  p.add_option("--listen", listen,
               "ADDRESS:PORT to listen on, the only address opened (port 0: any free one)")
      ->capture_default_str();
  auto* tok = p.add_option("--token", token,
                           "access token (at least 16 of A-Z a-z 0-9 - . _ ~); clients give it "
                           "as ?token= or Authorization: Bearer");
  auto* tok_file =
      p.add_option("--token-file", token_file, "read the access token from the first line of F");
  tok->excludes(tok_file);
  p.add_option("--max-clients", max_clients, "serve at most N browsers at once; more are refused")
      ->check(cli::in_range(1, 256))
      ->capture_default_str();
  p.add_option("--write-timeout", o.bridge.http.write_timeout_s,
               "drop a browser whose socket takes nothing for S seconds")
      ->check(cli::in_range(0.1, 600))
      ->capture_default_str();
  p.add_option("--ping-period", o.bridge.http.ping_period_s,
               "ping a silent browser every S seconds; five unanswered pings drop it")
      ->check(cli::in_range(0.1, 600))
      ->capture_default_str();
  p.add_option("--page-dir", o.bridge.page_dir, "the bundled page (index.html, app.js, style.css)")
      ->capture_default_str();
  p.add_option("--duration", o.duration_s, "stop after S seconds (default: until a signal)")
      ->check(cli::positive());
  p.add_option("--domain", o.bridge.dds.domain,
               "DDS domain id (default: the CYCLONEDDS_URI configuration's)")
      ->check(cli::in_range(0, 230));
  p.add_option("--topic-prefix", o.bridge.dds.topic_prefix,
               "prepend P to every topic name (as neurosim-server --topic-prefix)");
  p.footer(
      "CYCLONEDDS_URI must be set (deploy/cyclonedds/loopback.xml for local runs). Serve it\n"
      "beyond this machine through a TLS reverse proxy (web/README.md).");
  p.check([&] {
    if (token.empty() && token_file.empty())
      throw cli::UsageError("an access token is required: --token T or --token-file F");
  });
  if (!p.parse_or_throw(argc, argv)) {
    help = true;
    return WebOptions{};
  }
  parse_listen(listen, o.bridge.http);
  o.bridge.max_clients = static_cast<std::size_t>(max_clients);
  try {
    o.token = token_file.empty() ? AccessToken::from_text(token, "--token")
                                 : AccessToken::from_file(token_file);
  } catch (const std::invalid_argument& e) {
    throw cli::UsageError(e.what());
  }
  return o;
}

std::optional<int> parse_command_line(int argc, const char* const* argv, WebOptions& out) {
  try {
    bool help = false;
    out = parse_options(argc, argv, help);
    if (help) return 0;
  } catch (const std::invalid_argument& e) {
    return cli::report_usage_error("neurosim-web", e.what());
  }
  return std::nullopt;
}

}  // namespace neurosim::web
