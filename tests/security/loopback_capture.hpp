// Captures the UDP payloads sent over the loopback interface to one DDS domain's ports, on its own
// thread, with a raw AF_PACKET socket (needs CAP_NET_RAW: the tests run as root). Used to check
// what an eavesdropper on the wire could read.
#pragma once

#include <arpa/inet.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <netinet/ip.h>
#include <netinet/udp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace neurosim::security::testing {

// Cyclone DDS's default port mapping (DDSI 9.6.1.1): a domain's ports are 7400 + 250 * domain
// + [0, 250) (discovery and user traffic, multicast and unicast, every participant index).
struct DomainPorts {
  std::uint16_t first, last;
  explicit DomainPorts(int domain)
      : first(static_cast<std::uint16_t>(7400 + 250 * domain)), last(static_cast<std::uint16_t>(first + 249)) {}
  bool contains(std::uint16_t port) const { return port >= first && port <= last; }
};

class LoopbackCapture {
 public:
  explicit LoopbackCapture(int domain, std::size_t max_bytes = 64u << 20) : ports_(domain), max_bytes_(max_bytes) {
    fd_ = ::socket(AF_PACKET, SOCK_DGRAM, htons(ETH_P_IP));
    if (fd_ < 0)
      throw std::runtime_error(std::string("loopback capture: AF_PACKET socket: ") + std::strerror(errno) +
                               " (needs root / CAP_NET_RAW)");
    sockaddr_ll addr{};
    addr.sll_family = AF_PACKET;
    addr.sll_protocol = htons(ETH_P_IP);
    addr.sll_ifindex = static_cast<int>(::if_nametoindex("lo"));
    if (addr.sll_ifindex == 0 || ::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      const std::string why = std::strerror(errno);
      ::close(fd_);
      throw std::runtime_error("loopback capture: bind to interface lo: " + why);
    }
    thread_ = std::thread([this] { loop(); });
  }
  ~LoopbackCapture() {
    run_ = false;
    thread_.join();
    ::close(fd_);
  }
  LoopbackCapture(const LoopbackCapture&) = delete;
  LoopbackCapture& operator=(const LoopbackCapture&) = delete;

  std::size_t packets() {
    std::lock_guard<std::mutex> lk(m_);
    return packets_;
  }
  std::size_t bytes() {
    std::lock_guard<std::mutex> lk(m_);
    return payloads_.size();
  }
  // Whether the byte string occurs in a captured UDP payload.
  bool contains(std::string_view needle) {
    std::lock_guard<std::mutex> lk(m_);
    for (std::size_t i = 0; i < starts_.size(); ++i) {
      const std::size_t b = starts_[i], e = i + 1 < starts_.size() ? starts_[i + 1] : payloads_.size();
      if (std::search(payloads_.begin() + static_cast<std::ptrdiff_t>(b), payloads_.begin() + static_cast<std::ptrdiff_t>(e),
                      needle.begin(), needle.end()) != payloads_.begin() + static_cast<std::ptrdiff_t>(e))
        return true;
    }
    return false;
  }

 private:
  void loop() {
    std::vector<unsigned char> buf(1 << 16);
    while (run_) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      const ssize_t n = ::recv(fd_, buf.data(), buf.size(), 0);
      if (n < static_cast<ssize_t>(sizeof(iphdr))) continue;
      const auto* ip = reinterpret_cast<const iphdr*>(buf.data());
      const std::size_t ihl = ip->ihl * 4u;
      if (ip->protocol != IPPROTO_UDP || static_cast<std::size_t>(n) < ihl + sizeof(udphdr)) continue;
      const auto* udp = reinterpret_cast<const udphdr*>(buf.data() + ihl);
      if (!ports_.contains(ntohs(udp->dest)) && !ports_.contains(ntohs(udp->source))) continue;
      const std::size_t off = ihl + sizeof(udphdr);
      std::lock_guard<std::mutex> lk(m_);
      ++packets_;
      if (payloads_.size() + static_cast<std::size_t>(n) - off > max_bytes_) continue;
      starts_.push_back(payloads_.size());
      payloads_.insert(payloads_.end(), buf.data() + off, buf.data() + n);
    }
  }

  DomainPorts ports_;
  std::size_t max_bytes_;
  int fd_{-1};
  std::atomic<bool> run_{true};
  std::mutex m_;
  std::size_t packets_{0};
  std::vector<char> payloads_;      // every captured payload, one after the other
  std::vector<std::size_t> starts_;  // where each payload starts in payloads_
  std::thread thread_;
};

}  // namespace neurosim::security::testing
