// HttpServer in the test process (the bridge's other parts left out): the page and /api/stats
// only with the token (HEAD without a body), the stats callback's document served as it is,
// nothing listening on another loopback address, a port already taken refused naming the
// address, and a WebSocket client that answers no ping closed after the pings it ignored.
#include "web/http_server.hpp"

#include "web/options.hpp"
#include "web_test_util.hpp"

#include <gtest/gtest.h>

#include <cerrno>
#include <chrono>
#include <mutex>
#include <string>
#include <vector>

namespace web = neurosim::web;
namespace wt = neurosim::web::testing;

namespace {

struct Served {
  web::Hub hub;
  std::mutex m;
  std::vector<std::string> log;
  std::unique_ptr<web::HttpServer> server;

  explicit Served(web::HttpServerOptions o = {}) {
    o.port = 0;
    server = std::make_unique<web::HttpServer>(
        o, web::AccessToken::from_text(wt::kToken, "test"),
        web::PageFiles::load(web::default_page_dir()), hub,
        [] { return std::string("{\"answer\":42}"); },
        [this](const std::string& line) {
          std::lock_guard<std::mutex> lk(m);
          log.push_back(line);
        });
  }
  int port() const { return server->port(); }
};

TEST(WebHttpServer, ServesThePageAndStatsWithTheTokenOnly) {
  Served s;
  const std::string q = std::string("?token=") + wt::kToken;
  const wt::HttpResponse stats = wt::http_request(s.port(), "GET", "/api/stats" + q);
  EXPECT_EQ(stats.status, 200);
  EXPECT_EQ(stats.body, "{\"answer\":42}");
  EXPECT_NE(stats.head.find("Cache-Control: no-store"), std::string::npos);
  EXPECT_EQ(wt::http_request(s.port(), "GET", "/api/stats").status, 401);
  EXPECT_EQ(wt::http_request(s.port(), "GET", "/").status, 401);
  const wt::HttpResponse page = wt::http_request(s.port(), "GET", "/" + q);
  EXPECT_EQ(page.status, 200);
  EXPECT_FALSE(page.body.empty());
  const wt::HttpResponse head = wt::http_request(s.port(), "HEAD", "/" + q);
  EXPECT_EQ(head.status, 200);
  EXPECT_TRUE(head.body.empty());
  EXPECT_NE(head.head.find("Content-Length: " + std::to_string(page.body.size())),
            std::string::npos)
      << head.head;
}

TEST(WebHttpServer, ListensOnTheGivenAddressOnly) {
  Served s;
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(s.port()));
  a.sin_addr.s_addr = htonl(0x7f000002);  // 127.0.0.2: loopback, but not the address given
  const int rc = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  const int err = errno;
  ::close(fd);
  EXPECT_NE(rc, 0);
  EXPECT_EQ(err, ECONNREFUSED);
  EXPECT_EQ(wt::http_request(s.port(), "GET", std::string("/api/stats?token=") + wt::kToken).status,
            200);
}

TEST(WebHttpServer, APortInUseIsRefusedNamingTheAddress) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = 0;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  ASSERT_EQ(::listen(fd, 1), 0);
  socklen_t len = sizeof a;
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len), 0);
  const int taken = ntohs(a.sin_port);
  web::Hub hub;
  web::HttpServerOptions o;
  o.port = taken;
  const std::string msg = neurosim::testing::message_of([&] {
    web::HttpServer server(o, web::AccessToken::from_text(wt::kToken, "test"),
                           web::PageFiles::load(web::default_page_dir()), hub,
                           [] { return std::string("{}"); }, [](const std::string&) {});
  });
  ::close(fd);
  EXPECT_NE(msg.find("cannot listen on 127.0.0.1:" + std::to_string(taken)), std::string::npos)
      << msg;
}

TEST(WebHttpServer, AWebSocketClientThatAnswersNoPingIsClosed) {
  web::HttpServerOptions o;
  o.ping_period_s = 0.05;
  Served s(o);
  const int fd = wt::connect_loopback(s.port());
  ASSERT_GE(fd, 0);
  const std::string req = std::string("GET /ws?token=") + wt::kToken +
                          " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + wt::upgrade_headers() + "\r\n";
  ASSERT_EQ(::send(fd, req.data(), req.size(), MSG_NOSIGNAL), static_cast<ssize_t>(req.size()));
  // Read the upgrade, then the server's frames (unmasked) without ever answering, until it
  // closes the connection. Receive timeout 5 s per read (connect_loopback); 60 s in all.
  std::string in;
  char buf[4096];
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  bool closed = false;
  while (std::chrono::steady_clock::now() < until) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n == 0) {
      closed = true;
      break;
    }
    if (n < 0) {
      if (errno == EAGAIN || errno == EINTR) continue;
      closed = true;  // reset by the server
      break;
    }
    in.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  ASSERT_TRUE(closed) << "still open after 60 s";
  ASSERT_EQ(in.rfind("HTTP/1.1 101", 0), 0u) << in.substr(0, 80);
  std::size_t p = in.find("\r\n\r\n");
  ASSERT_NE(p, std::string::npos);
  p += 4;
  int pings = 0;
  while (p + 2 <= in.size()) {
    const int opcode = static_cast<unsigned char>(in[p]) & 0x0f;
    std::size_t len = static_cast<unsigned char>(in[p + 1]) & 0x7f, head = 2;
    if (len == 126) {
      if (p + 4 > in.size()) break;
      len = (static_cast<unsigned char>(in[p + 2]) << 8) | static_cast<unsigned char>(in[p + 3]);
      head = 4;
    } else if (len == 127) {
      break;  // nothing this large is sent to an idle client
    }
    if (opcode == 0x9) ++pings;
    p += head + len;
  }
  EXPECT_GE(pings, 5) << "closed after " << pings << " pings";
  // The hub forgot the client.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (s.hub.clients() > 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(s.hub.clients(), 0u);
}

}  // namespace
