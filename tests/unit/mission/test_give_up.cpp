// Bounded retries: the team gives a region up after give_up_failures failures to reach it (by any robot),
// goes home and ends the mission; the region is tried again when its goal moves; with the rule off the
// team retries for ever (the gen6 study's pond, session 38).
#include <gtest/gtest.h>

#include "team_harness.hpp"

namespace ag::mission {
namespace {
using test::Team;

ManagerParams params(int give_up) {
  ManagerParams p;
  p.idle_return_s = 10.0;
  p.no_progress_timeout_s = 10.0;
  p.retry_after_s = 20.0;
  p.give_up_failures = give_up;
  return p;
}

std::uint32_t failures(const Team& t) {
  std::uint32_t n = 0;
  for (const auto& b : t.bots) n += b.m->status().failed_own;
  return n;
}

// Two robots, region 5 behind a wall no robot can pass (its goal on the far shore), region 6 reachable.
Team pond_team(int give_up) {
  Team t;
  t.add(1, 1, 0, 0, params(give_up));
  t.add(2, 2, -2, 0, params(give_up));
  t.wall_x = 20.0;
  t.region(5, 30, 0);
  t.region(6, -30, 5);
  t.publish_regions();
  return t;
}

TEST(GiveUp, TheTeamGivesUpARegionAfterGiveUpFailuresAndEndsTheMission) {
  Team t = pond_team(3);
  for (int i = 0; i < 5 * 600 && !t.all_done(); ++i) t.step();
  EXPECT_TRUE(t.all_done()) << "home after giving region 5 up, at " << t.seconds() << " s";
  EXPECT_EQ(failures(t), 3U) << "failures of both robots together";
  for (const auto& b : t.bots) EXPECT_EQ(b.m->counters().regions_given_up, 1U);
  EXPECT_TRUE(t.bots[0].m->visited_by_anyone(6U));
  EXPECT_FALSE(t.bots[0].m->visited_by_anyone(5U));
}

TEST(GiveUp, WithTheRuleOffTheTeamRetriesToTheEnd) {
  Team t = pond_team(0);
  for (int i = 0; i < 5 * 600 && !t.all_done(); ++i) t.step();
  EXPECT_FALSE(t.all_done());
  EXPECT_GT(failures(t), 10U) << "retried every retry_after_s for 600 s";
  for (const auto& b : t.bots) EXPECT_EQ(b.m->counters().regions_given_up, 0U);
}

TEST(GiveUp, AGivenUpRegionWhoseGoalMovedIsTriedAgain) {
  Team t = pond_team(3);
  for (int i = 0; i < 5 * 600 && !t.all_done(); ++i) t.step();
  ASSERT_TRUE(t.all_done());
  t.regions[0].goal_x = 15.0F;  // the map grew: the region's goal is now on this side of the wall, 15 m on
  t.publish_regions();
  for (int i = 0; i < 5 * 120 && !t.bots[0].m->visited_by_anyone(5U); ++i) t.step();
  EXPECT_TRUE(t.bots[0].m->visited_by_anyone(5U)) << "failures at a goal 15 m away (revisit_moved_m 10) do not count";
  for (const auto& b : t.bots) EXPECT_EQ(b.m->counters().regions_given_up, 0U);
}

}  // namespace
}  // namespace ag::mission
