// neurosim-server's contact switches: unset keeps the library's defaults, each switch reaches
// its SimulationOptions field, and switches that contradict each other (or that the library
// would refuse at build) are refused with a message naming them.
#include "server/service/contact_switches.hpp"

#include <gtest/gtest.h>

#include <limits>
#include <stdexcept>
#include <string>

namespace {

using neurosim::interaction::SimulationOptions;
using neurosim::service::ContactSwitches;

std::string refusal(const ContactSwitches& c) {
  try {
    c.validate();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(accepted)";
}

}  // namespace

TEST(service_contact_switches, UnsetKeepsTheLibraryDefaults) {
  const ContactSwitches c;
  EXPECT_FALSE(c.any());
  EXPECT_NO_THROW(c.validate());
  const SimulationOptions defaults;
  SimulationOptions o;
  o.contact_spread = 2.5;  // not the default: apply must leave it as it is
  c.apply(o);
  EXPECT_EQ(o.contact_spread, 2.5);
  EXPECT_EQ(o.contact_smooth_normals, defaults.contact_smooth_normals);
  EXPECT_EQ(o.contact_near_field, defaults.contact_near_field);
  EXPECT_NE(c.describe().find("the library's defaults"), std::string::npos) << c.describe();
}

TEST(service_contact_switches, BarycentricIsSpreadZeroWithoutSmoothNormalsOrNearField) {
  ContactSwitches c;
  c.barycentric = true;
  EXPECT_NO_THROW(c.validate());
  SimulationOptions o;
  c.apply(o);
  EXPECT_EQ(o.contact_spread, 0.0);
  EXPECT_FALSE(o.contact_smooth_normals);
  EXPECT_FALSE(o.contact_near_field);
  EXPECT_NE(c.describe().find("--barycentric-contact"), std::string::npos) << c.describe();
  // Saying the same thing twice is not a contradiction.
  c.spread = 0.0;
  c.smooth_normals = false;
  c.near_field = false;
  EXPECT_NO_THROW(c.validate());
}

TEST(service_contact_switches, EachSwitchReachesItsField) {
  ContactSwitches c;
  c.spread = 1.5;
  c.smooth_normals = false;
  c.near_field = false;
  EXPECT_NO_THROW(c.validate());
  SimulationOptions o;
  c.apply(o);
  EXPECT_EQ(o.contact_spread, 1.5);
  EXPECT_FALSE(o.contact_smooth_normals);
  EXPECT_FALSE(o.contact_near_field);
  ContactSwitches on;
  on.smooth_normals = true;
  on.near_field = true;
  SimulationOptions p;
  p.contact_smooth_normals = false;
  p.contact_near_field = false;
  on.apply(p);
  EXPECT_TRUE(p.contact_smooth_normals);
  EXPECT_TRUE(p.contact_near_field);
}

TEST(service_contact_switches, ContradictionsAreRefusedNamingTheSwitches) {
  ContactSwitches a;
  a.barycentric = true;
  a.spread = 1.0;
  const std::string ea = refusal(a);
  EXPECT_NE(ea.find("--barycentric-contact"), std::string::npos) << ea;
  EXPECT_NE(ea.find("--contact-spread 1"), std::string::npos) << ea;

  ContactSwitches b;
  b.barycentric = true;
  b.smooth_normals = true;
  EXPECT_NE(refusal(b).find("--contact-smooth-normals on"), std::string::npos) << refusal(b);

  ContactSwitches c;
  c.barycentric = true;
  c.near_field = true;
  EXPECT_NE(refusal(c).find("--contact-near-field on"), std::string::npos) << refusal(c);

  // Spread 0 with the near field on (its default): Simulation::build would refuse it.
  ContactSwitches d;
  d.spread = 0.0;
  const std::string ed = refusal(d);
  EXPECT_NE(ed.find("--contact-near-field off"), std::string::npos) << ed;
  d.near_field = false;
  EXPECT_NO_THROW(d.validate());
}

TEST(service_contact_switches, SpreadOutOfRangeIsRefused) {
  for (double s : {-0.1, 4.5, std::numeric_limits<double>::quiet_NaN(),
                   std::numeric_limits<double>::infinity()}) {
    ContactSwitches c;
    c.spread = s;
    EXPECT_NE(refusal(c).find("outside [0, 4]"), std::string::npos) << s << ": " << refusal(c);
  }
}

// --contact-max-rows and --lcp-max-iterations: each reaches its field and the start-up line;
// outside its range it is refused naming the switch; unset keeps the library's limits.
TEST(service_contact_switches, RowAndPivotLimitsReachTheirFields) {
  const SimulationOptions defaults;
  SimulationOptions o;
  ContactSwitches none;
  none.apply(o);
  EXPECT_EQ(o.max_contact_nodes_per_tool, defaults.max_contact_nodes_per_tool);
  EXPECT_EQ(o.lcp_max_iterations, defaults.lcp_max_iterations);

  ContactSwitches c;
  c.max_rows = 1200;
  c.lcp_max_iterations = 4000;
  EXPECT_TRUE(c.any());
  EXPECT_NO_THROW(c.validate());
  c.apply(o);
  EXPECT_EQ(o.max_contact_nodes_per_tool, 1200);
  EXPECT_EQ(o.lcp_max_iterations, 4000);
  const std::string line = c.describe();
  EXPECT_NE(line.find("at most 1200 rows per tool"), std::string::npos) << line;
  EXPECT_NE(line.find("--contact-max-rows 1200 --lcp-max-iterations 4000"), std::string::npos) << line;

  for (int bad : {0, -3, 100001}) {
    ContactSwitches r;
    r.max_rows = bad;
    EXPECT_NE(refusal(r).find("--contact-max-rows"), std::string::npos) << bad << ": " << refusal(r);
    ContactSwitches l;
    l.lcp_max_iterations = bad == 100001 ? 1000001 : bad;
    EXPECT_NE(refusal(l).find("--lcp-max-iterations"), std::string::npos) << bad << ": " << refusal(l);
  }
}
