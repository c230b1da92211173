// Priority per mesh pair (paper 2.5 step 1): the higher priority mesh is embedded.
#include "server/fusion/priority.hpp"

#include "fusion_fixtures.hpp"

#include <gtest/gtest.h>

namespace neurosim::fusion {
namespace {

TEST(fusion_priority, HigherPriorityIsEmbeddedWhateverTheOrder) {
  const auto brain = test::structured_box(Vec3::Zero(), Vec3::Ones(), 1, 1, 1);
  const auto vessel = test::structured_box(Vec3::Zero(), Vec3::Constant(0.5), 1, 1, 1);
  const PrioritizedMesh b{&brain, 0, "brain"}, v{&vessel, 5, "artery"};
  for (const FusionPair& p : {decide_roles(b, v), decide_roles(v, b)}) {
    EXPECT_EQ(p.host.mesh, &brain);
    EXPECT_EQ(p.embedded.mesh, &vessel);
    EXPECT_EQ(p.embedded.name, "artery");
  }
}

TEST(fusion_priority, AmbiguousPairsAreRejectedByName) {
  const auto m1 = test::structured_box(Vec3::Zero(), Vec3::Ones(), 1, 1, 1);
  const auto m2 = test::structured_box(Vec3::Zero(), Vec3::Ones(), 1, 1, 1);
  try {
    decide_roles({&m1, 2, "brain"}, {&m2, 2, "tumour"});
    FAIL() << "equal priorities accepted";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("brain"), std::string::npos);
    EXPECT_NE(msg.find("tumour"), std::string::npos);
  }
  EXPECT_THROW(decide_roles({&m1, 0, "a"}, {nullptr, 1, "b"}), std::invalid_argument);
  EXPECT_THROW(decide_roles({&m1, 0, "a"}, {&m1, 1, "a again"}), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fusion
