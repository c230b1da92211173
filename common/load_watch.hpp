// The load of a program (reading the scene, generating meshes, building the simulation) run on
// a worker thread while the calling thread watches it: a stop flag (set by a SIGINT/SIGTERM
// handler) or the load-time limit ends the process at once with a line naming the phase, and
// std::bad_alloc in the load becomes an error naming the phase. The process ends with
// std::_Exit: the worker may be blocked in a system call or deep inside a mesher, and nothing it
// holds is needed any more.
#pragma once

#include "common/clock.hpp"

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>

namespace neurosim::common {

struct LoadWatchDef {
  std::string program;                    // names the lines it prints ("neurosim-server")
  double limit_s{0.0};                    // the whole load, all phases, unit s; 0: no limit
  std::string limit_option{"--load-timeout"};  // named when the limit ends the load
  const std::atomic<bool>* stop{nullptr};  // set by the signal handler; null: none
  std::string on_stop{"exiting"};           // "signal received while <phase>: <on_stop>"
  int stop_status{0};                       // exit status after a signal
  int limit_status{1};                      // exit status after the limit
};

class LoadWatch {
 public:
  explicit LoadWatch(LoadWatchDef def) : def_(std::move(def)), start_(Clock::now()) {}

  // work() on a worker thread; its result, or what it threw (std::bad_alloc as
  // std::runtime_error "out of memory while <phase>"). Ends the process on a stop or when the
  // load (since construction) passes the limit.
  template <class Work>
  auto run(const std::string& phase, Work&& work) -> decltype(work()) {
    using R = decltype(work());
    std::optional<R> result;
    std::exception_ptr error;
    std::atomic<bool> done{false};
    std::thread worker([&] {
      try {
        result.emplace(work());
      } catch (const std::bad_alloc&) {
        error = std::make_exception_ptr(std::runtime_error("out of memory while " + phase));
      } catch (...) {
        error = std::current_exception();
      }
      done.store(true);
    });
    while (!done.load()) {
      if (def_.stop != nullptr && def_.stop->load()) {
        std::cerr << def_.program << ": signal received while " << phase << ": " << def_.on_stop
                  << "\n" << std::flush;
        std::_Exit(def_.stop_status);
      }
      if (def_.limit_s > 0 && seconds_since(start_) > def_.limit_s) {
        std::cerr << def_.program << ": error: the load took longer than " << def_.limit_s
                  << " s (" << def_.limit_option << ") while " << phase << ": exiting\n"
                  << std::flush;
        std::_Exit(def_.limit_status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    worker.join();
    if (error) std::rethrow_exception(error);
    return std::move(*result);
  }

  double elapsed_s() const { return seconds_since(start_); }

 private:
  LoadWatchDef def_;
  Clock::time_point start_;
};

}  // namespace neurosim::common
