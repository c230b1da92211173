// neurosim-web's command line: defaults, --listen, the token (required, from the command line
// or a file), errors naming the option; the exit status of the program on a usage error.
#include "web/options.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

namespace web = neurosim::web;
namespace nt = neurosim::testing;

namespace {

web::WebOptions parse(std::vector<std::string> args) {
  args.insert(args.begin(), "neurosim-web");
  std::vector<const char*> argv;
  for (auto& a : args) argv.push_back(a.c_str());
  bool help = false;
  return web::parse_options(static_cast<int>(argv.size()), argv.data(), help);
}

std::string error_of(std::vector<std::string> args) {
  return nt::message_of([&] { parse(args); });
}

}  // namespace

TEST(WebOptions, Defaults) {
  const auto o = parse({"--token", "0123456789abcdef"});
  EXPECT_EQ(o.bridge.http.address, "127.0.0.1");
  EXPECT_EQ(o.bridge.http.port, 8090);
  EXPECT_EQ(o.bridge.max_clients, 16U);
  EXPECT_EQ(o.bridge.page_dir, web::default_page_dir());
  EXPECT_EQ(o.bridge.dds.domain, -1);
  ASSERT_TRUE(o.token);
  EXPECT_TRUE(o.token->matches("0123456789abcdef"));
  EXPECT_EQ(o.duration_s, 0);
}

TEST(WebOptions, ListenMaxClientsTokenFile) {
  const auto dir = nt::temp_dir("web_options");
  std::ofstream(dir / "token") << "from-a-file-0123456789\n";
  const auto o = parse({"--listen", "127.0.0.2:0", "--max-clients", "3", "--token-file",
                        (dir / "token").string(), "--topic-prefix", "p_", "--domain", "7"});
  EXPECT_EQ(o.bridge.http.address, "127.0.0.2");
  EXPECT_EQ(o.bridge.http.port, 0);
  EXPECT_EQ(o.bridge.max_clients, 3U);
  EXPECT_TRUE(o.token->matches("from-a-file-0123456789"));
  EXPECT_EQ(o.bridge.dds.topic_prefix, "p_");
  EXPECT_EQ(o.bridge.dds.domain, 7);
}

TEST(WebOptions, ErrorsNameTheOption) {
  EXPECT_NE(error_of({}).find("an access token is required: --token T or --token-file F"),
            std::string::npos);
  EXPECT_NE(error_of({"--token", "short"}).find("--token: the access token has 5 characters"),
            std::string::npos);
  EXPECT_NE(error_of({"--token", "0123456789abcdef", "--listen", "localhost:80"})
                .find("--listen 'localhost:80': 'localhost' is not a dotted IPv4 address"),
            std::string::npos);
  EXPECT_NE(error_of({"--token", "0123456789abcdef", "--listen", "127.0.0.1:70000"})
                .find("port '70000' is not a number in 0..65535"),
            std::string::npos);
  EXPECT_NE(error_of({"--token", "0123456789abcdef", "--listen", "127.0.0.1"})
                .find("expected ADDRESS:PORT"),
            std::string::npos);
  EXPECT_NE(error_of({"--token", "0123456789abcdef", "--max-clients", "0"}).find("--max-clients"),
            std::string::npos);
  EXPECT_NE(error_of({"--token", "0123456789abcdef", "--token-file", "/x"}).find("excludes"),
            std::string::npos);
  EXPECT_NE(error_of({"--token-file", "/nonexistent/token"})
                .find("--token-file /nonexistent/token: cannot be read"),
            std::string::npos);
}

TEST(WebOptions, ProgramExitsTwoOnAUsageErrorAndOneWhenItCannotListen) {
  const std::string exe = (nt::bin_dir() / "neurosim-web").string();
  const auto run = [&](const std::string& args, std::string& out) {
    FILE* p = popen((exe + " " + args + " 2>&1").c_str(), "r");
    char buf[512];
    out.clear();
    while (fgets(buf, sizeof buf, p) != nullptr) out += buf;
    return WEXITSTATUS(pclose(p));
  };
  std::string out;
  EXPECT_EQ(run("--listen 127.0.0.1:0", out), 2);
  EXPECT_NE(out.find("neurosim-web: an access token is required"), std::string::npos) << out;
  EXPECT_NE(out.find("Run with --help for more information."), std::string::npos);
  EXPECT_EQ(run("--version", out), 0);
  EXPECT_NE(out.find("neurosim-web "), std::string::npos);
  // 192.0.2.1 (TEST-NET-1) is on no interface of this machine: binding it fails, nothing is sent.
  EXPECT_EQ(run("--listen 192.0.2.1:0 --token 0123456789abcdef --duration 5", out), 1);
  EXPECT_NE(out.find("cannot listen on 192.0.2.1:0"), std::string::npos) << out;
  EXPECT_EQ(run("--listen 127.0.0.1:0 --token 0123456789abcdef --page-dir /nonexistent", out), 1);
  EXPECT_NE(out.find("page file /nonexistent/index.html missing"), std::string::npos) << out;
}
