// Helpers for the neurosim::wire tests.
#pragma once

#include "common/clock.hpp"
#include "idl/wire/dds.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <string>

namespace neurosim::wire::testing {

// A topic name unique to this test and process, so tests running at once (and other people's
// processes on the same loopback domain) never see each other's samples.
inline std::string unique_topic(const char* base) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return std::string(base) + "_" + info->name() + "_" + std::to_string(::getpid());
}

using neurosim::common::seconds_since;

// Takes from r until pred(batch) is true or the timeout passes; returns whether it was.
template <class T, class Pred>
bool take_until(Reader<T>& r, Waitset& ws, dds_duration_t timeout, Pred pred) {
  const auto t0 = std::chrono::steady_clock::now();
  while (seconds_since(t0) * 1e9 < static_cast<double>(timeout)) {
    if (pred(r.take())) return true;
    ws.wait(DDS_MSECS(50));
  }
  return false;
}

}  // namespace neurosim::wire::testing
