// Unit tests of the service's building blocks: the ToolState filter (non-finite values, jumps
// beyond the maximum speed) and the command line. The newest-pose triple buffer is
// common::TripleBuffer (tests/common/triple_buffer_test.cpp).
#include "idl/wire/types.hpp"
#include "server/service/server.hpp"
#include "server/service/tool_filter.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using neurosim::service::ToolFilter;
using neurosim::service::Verdict;

namespace {

neurosim_ToolState tool(double x, std::int64_t t_ns) {
  neurosim_ToolState s{};
  s.position_m[0] = x;
  s.orientation[0] = 1;
  s.source_time_ns = t_ns;
  return s;
}

}  // namespace

TEST(service_tool_filter, RejectsNonFiniteAnywhere) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  ToolFilter f(2.0);
  EXPECT_EQ(f.check(tool(0.1, 0)), Verdict::Accepted);
  for (int field = 0; field < 10; ++field) {
    auto s = tool(0.1, 1000000);
    double* v = field < 3 ? &s.position_m[field] : field < 6 ? &s.velocity_m_per_s[field - 3] : &s.orientation[field - 6];
    *v = field % 2 ? nan : -inf;
    EXPECT_EQ(f.check(s), Verdict::NonFinite) << "field " << field;
  }
  auto zero_q = tool(0.1, 1000000);
  zero_q.orientation[0] = 0;
  EXPECT_EQ(f.check(zero_q), Verdict::NonFinite);
  EXPECT_EQ(f.check(tool(0.1, 2000000)), Verdict::Accepted);
}

TEST(service_tool_filter, JumpIsMeasuredFromTheLastGoodPose) {
  ToolFilter f(2.0, 0.0);  // 2 m/s, no slack: 1 ms allows 2 mm
  const std::int64_t ms = 1000000;
  EXPECT_EQ(f.check(tool(0.0, 0)), Verdict::Accepted);
  EXPECT_EQ(f.check(tool(0.0019, 1 * ms)), Verdict::Accepted);
  EXPECT_EQ(f.check(tool(0.0100, 2 * ms)), Verdict::Jump);  // 8.1 mm in 1 ms
  // Still measured from 1.9 mm at 1 ms: 3.9 mm in 2 ms is allowed.
  EXPECT_EQ(f.check(tool(0.0058, 3 * ms)), Verdict::Accepted);
  // A time that does not advance allows no motion at all.
  EXPECT_EQ(f.check(tool(0.0059, 3 * ms)), Verdict::Jump);
  EXPECT_EQ(f.check(tool(0.0058, 3 * ms)), Verdict::Accepted);
  f.reset();
  EXPECT_EQ(f.check(tool(5.0, 4 * ms)), Verdict::Accepted) << "after reset the next sample is the first";
}

TEST(service_tool_filter, RefusesBadLimits) {
  EXPECT_THROW(ToolFilter(0.0), std::invalid_argument);
  EXPECT_THROW(ToolFilter(std::numeric_limits<double>::quiet_NaN()), std::invalid_argument);
  EXPECT_THROW(ToolFilter(1.0, -1.0), std::invalid_argument);
}

TEST(service_command_line, BadArgumentsExitTwo) {
  auto never = [](const neurosim::scene::Model&) -> std::unique_ptr<neurosim::interaction::Simulation> {
    ADD_FAILURE() << "no simulation may be built";
    return nullptr;
  };
  const char* a1[] = {"neurosim-server"};
  EXPECT_EQ(neurosim::service::run_main(1, const_cast<char**>(a1), never), 2);
  const char* a2[] = {"neurosim-server", "--scene", "x.scene", "--duration", "-1"};
  EXPECT_EQ(neurosim::service::run_main(5, const_cast<char**>(a2), never), 2);
  const char* a3[] = {"neurosim-server", "--scene", "x.scene", "--bogus"};
  EXPECT_EQ(neurosim::service::run_main(4, const_cast<char**>(a3), never), 2);
  const char* a4[] = {"neurosim-server", "--scene", "/nonexistent/x.scene"};
  EXPECT_EQ(neurosim::service::run_main(3, const_cast<char**>(a4), never), 1);
}
