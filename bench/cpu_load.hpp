// CPU starvation for benchmarks (--load N): N busy threads at normal priority beside the
// measured processes, for as long as the object lives, so margins are measured on a busy
// machine (a browser, a video call), not only on an idle one. Each thread spins on arithmetic
// and touches 4 MiB of memory so caches are shared too.
#pragma once

#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace neurosim::bench {

class CpuLoad {
 public:
  explicit CpuLoad(int threads) {
    for (int i = 0; i < threads; ++i)
      threads_.emplace_back([this, i] {
        std::vector<double> buf(std::size_t{1} << 19, 1.0 + i);  // 4 MiB
        std::size_t k = 0;
        double acc = 0;
        while (!stop_.load(std::memory_order_relaxed)) {
          for (int j = 0; j < 4096; ++j, k = (k + 4099) % buf.size()) {
            acc = acc * 0.999 + buf[k];
            buf[k] = acc;
          }
        }
        sink_.fetch_add(static_cast<long>(acc), std::memory_order_relaxed);
      });
  }
  ~CpuLoad() {
    stop_ = true;
    for (auto& t : threads_) t.join();
  }
  CpuLoad(const CpuLoad&) = delete;
  CpuLoad& operator=(const CpuLoad&) = delete;
  int threads() const { return static_cast<int>(threads_.size()); }

 private:
  std::atomic<bool> stop_{false};
  std::atomic<long> sink_{0};
  std::vector<std::thread> threads_;
};

}  // namespace neurosim::bench
