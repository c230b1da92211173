// neurosim-web command line (common/cli: CLI11): where to listen, the access token, how many
// clients, which DDS domain and topic prefix, where the page is.
#pragma once

#include "web/access_token.hpp"
#include "web/bridge.hpp"

#include <optional>
#include <string>

namespace neurosim::web {

struct WebOptions {
  BridgeOptions bridge;
  std::optional<AccessToken> token;  // set after a successful parse
  double duration_s = 0;             // stop after this long (0: until a signal), unit s
};

// "ADDRESS:PORT" with a dotted IPv4 address and a port 0..65535 (0: any free port). Throws
// cli::UsageError naming --listen otherwise.
void parse_listen(const std::string& text, HttpServerOptions& http);

// Parses argv. Throws cli::UsageError (a std::invalid_argument) with a message naming the option
// on a bad or missing value, an unknown option, no token or an unacceptable one. For --help or
// --version it prints on stdout, sets help = true and returns defaults.
WebOptions parse_options(int argc, const char* const* argv, bool& help);

// As above for main(): std::nullopt when the program should run (options in `out`); otherwise
// its exit status, after --help / --version (0) or a usage error (2, reported on stderr as
// "neurosim-web: <message>").
std::optional<int> parse_command_line(int argc, const char* const* argv, WebOptions& out);

// The bundled page of this build (set by CMake).
std::string default_page_dir();

}  // namespace neurosim::web
