// eval planning on the built-in world: routes against the grid optimum, driven on the simulated robot,
// metrics.json written with the keys.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "airground/sim/eval_planning.hpp"

namespace ag::sim {
namespace {

TEST(EvalPlanning, RoutesOnTheDefaultWorldKeepClearanceAndAreDrivenWithoutCollisions) {
  EvalPlanningOptions o;
  o.pairs = 5;
  o.seed = 3;
  o.out_dir = ::testing::TempDir() + "/eval-planning";
  auto m = eval_planning(o);
  ASSERT_TRUE(m.ok()) << m.error().message;
  const PlanningMetrics& r = m.value();
  EXPECT_EQ(r.pairs, 5);
  EXPECT_LE(r.path_length_ratio_mean, 1.05);
  EXPECT_LE(r.path_length_ratio_max, 1.15);
  EXPECT_GE(r.min_clearance_ratio_min, 1.0);
  EXPECT_EQ(r.through_blocked, 0);
  EXPECT_EQ(r.too_close, 0);
  EXPECT_EQ(r.reached, 5);
  EXPECT_EQ(r.collisions, 0U);
  EXPECT_EQ(r.failures, 0);
  std::ifstream in(o.out_dir + "/metrics.json");
  std::stringstream ss;
  ss << in.rdbuf();
  for (const char* key : {"path_length_ratio_mean", "path_length_ratio_max", "min_clearance_ratio_mean", "reached", "collisions", "failures"})
    EXPECT_NE(ss.str().find(std::string("\"") + key + "\""), std::string::npos) << key;
}

TEST(EvalPlanning, BadOverridesAndWorldsAreNamed) {
  EvalPlanningOptions o;
  o.out_dir = ::testing::TempDir() + "/eval-planning-bad";
  o.set = {"planner.min_clearance_m=99"};
  auto m = eval_planning(o);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.error().message.find("min_clearance_m"), std::string::npos) << m.error().message;
  o.set.clear();
  o.world = "/nonexistent/world";
  EXPECT_FALSE(eval_planning(o).ok());
}

}  // namespace
}  // namespace ag::sim
