// Tests of the strict mission scoring: visits judged at the moment they were marked, localization error over
// every sample from the first good one on, with the tracking-only figures and the fractions beside them.
#include <gtest/gtest.h>

#include <vector>

#include "airground/sim/eval_scoring.hpp"

namespace ag::sim {
namespace {

LocErrorSample tracking(double e) { return {true, true, e}; }
LocErrorSample lost(double e) { return {true, false, e}; }

TEST(VisitScoring, JudgedByTheTruePositionWhenMarkedNotByThePathBeforeOrAfter) {
  // The robot's path passed over the goal earlier, but when it marked the visit it stood 4 m away.
  EXPECT_EQ(judge_visit(4.0, 0.0, 0.0, 0.0, 3.0, true), VisitVerdict::kFalse);
  EXPECT_EQ(judge_visit(2.9, 0.5, 0.0, 0.0, 3.0, true), VisitVerdict::kTrue);
  EXPECT_EQ(judge_visit(0.0, 3.0, 0.0, 0.0, 3.0, true), VisitVerdict::kTrue);  // on the radius: inside
  EXPECT_EQ(judge_visit(0.0, 3.0, 0.0, 0.0, 2.5, true), VisitVerdict::kFalse);  // the robot's own radius counts
}

TEST(VisitScoring, ATrueVisitToARegionWithNoTargetIsCountedApart) {
  EXPECT_EQ(judge_visit(1.0, 1.0, 0.0, 0.0, 3.0, false), VisitVerdict::kNonTarget);
  EXPECT_EQ(judge_visit(10.0, 1.0, 0.0, 0.0, 3.0, false), VisitVerdict::kFalse) << "false first: it was not there";
  EXPECT_STREQ(verdict_name(VisitVerdict::kNonTarget), "non_target");
}

// A target counts when any of its cars lies in the surveyed area, even with its centre outside; one with
// every car outside is not part of the mission.
TEST(TargetScoring, OnlyTargetsWithACarInTheSurveyedAreaAreScored) {
  const MapRect survey{-80.0, -80.0, 80.0, 80.0};
  std::vector<TargetCluster> world(3);
  world[0] = {1, 10.0, 10.0, 1, {Pose2{10.0, 10.0, 0.0}}};
  world[1] = {2, -81.0, 0.0, 2, {Pose2{-84.0, 0.0, 0.0}, Pose2{-78.0, 0.0, 0.0}}};  // straddles the edge
  world[2] = {6, -56.6, 84.1, 2, {Pose2{-56.6, 81.5, 0.0}, Pose2{-56.6, 86.7, 0.0}}};  // the imported world's
  std::vector<int> outside;
  const std::vector<TargetCluster> in = targets_in_area(world, survey, outside);
  ASSERT_EQ(in.size(), 2U);
  EXPECT_EQ(in[0].id, 1);
  EXPECT_EQ(in[1].id, 2);
  EXPECT_EQ(outside, std::vector<int>{6});
}

TEST(LocErrorScoring, SamplesBeforeTheFirstGoodOneAreNotScored) {
  LocErrorScore s(3.0);
  const std::vector<LocErrorSample> v{{false, false, -1}, lost(15.0), tracking(8.0), tracking(1.0), tracking(2.0)};
  EXPECT_EQ(s.add_robot(v), 3u);
  const LocErrorStats r = s.stats();
  EXPECT_EQ(r.samples, 2u);
  EXPECT_DOUBLE_EQ(r.mean_m, 1.5);
  EXPECT_DOUBLE_EQ(r.max_m, 2.0);
  EXPECT_DOUBLE_EQ(r.tracking_fraction, 1.0);
  EXPECT_DOUBLE_EQ(r.within_fraction, 1.0);
}

TEST(LocErrorScoring, AnExcursionCountsInsteadOfRestartingTheStatistics) {
  // 99 % within 3 m along a long route, one excursion to 12 m (lost) in the middle: the old scoring kept
  // only the samples after the excursion; this one keeps all of them.
  std::vector<LocErrorSample> v;
  for (int i = 0; i < 500; ++i) v.push_back(tracking(0.5));
  for (int i = 0; i < 10; ++i) v.push_back(lost(12.0));
  for (int i = 0; i < 490; ++i) v.push_back(tracking(1.0));
  LocErrorScore s(3.0);
  EXPECT_EQ(s.add_robot(v), 0u);
  const LocErrorStats r = s.stats();
  EXPECT_EQ(r.samples, 1000u);
  EXPECT_NEAR(r.mean_m, (500 * 0.5 + 10 * 12.0 + 490 * 1.0) / 1000.0, 1e-12);
  EXPECT_DOUBLE_EQ(r.max_m, 12.0);
  EXPECT_DOUBLE_EQ(r.p95_m, 1.0);
  EXPECT_NEAR(r.tracking_mean_m, (500 * 0.5 + 490 * 1.0) / 990.0, 1e-12);
  EXPECT_DOUBLE_EQ(r.tracking_max_m, 1.0);
  EXPECT_DOUBLE_EQ(r.tracking_fraction, 0.99);
  EXPECT_DOUBLE_EQ(r.within_fraction, 0.99);
}

TEST(LocErrorScoring, TrackingFarFromTheTruthIsTrackingButNotWithin) {
  LocErrorScore s(3.0);
  s.add_robot(std::vector<LocErrorSample>{tracking(1.0), tracking(9.0), tracking(9.0), tracking(1.0)});
  const LocErrorStats r = s.stats();
  EXPECT_DOUBLE_EQ(r.tracking_fraction, 1.0);
  EXPECT_DOUBLE_EQ(r.within_fraction, 0.5);
  EXPECT_DOUBLE_EQ(r.tracking_mean_m, 5.0);
}

TEST(LocErrorScoring, RobotsArePooledEachFromItsOwnFirstGoodSample) {
  LocErrorScore s(3.0);
  s.add_robot(std::vector<LocErrorSample>{lost(20.0), tracking(1.0), tracking(1.0)});
  s.add_robot(std::vector<LocErrorSample>{tracking(2.0), lost(6.0)});
  s.add_robot(std::vector<LocErrorSample>{lost(30.0), tracking(30.0)});  // never good: not scored
  const LocErrorStats r = s.stats();
  EXPECT_EQ(r.samples, 4u);
  EXPECT_DOUBLE_EQ(r.mean_m, 2.5);
  EXPECT_DOUBLE_EQ(r.tracking_fraction, 0.75);
  EXPECT_DOUBLE_EQ(r.within_fraction, 0.75);
}

TEST(LocErrorScoring, NothingGoodGivesNoFigures) {
  LocErrorScore s(3.0);
  EXPECT_EQ(s.add_robot(std::vector<LocErrorSample>{lost(5.0), tracking(4.0)}), 2u);
  const LocErrorStats r = s.stats();
  EXPECT_EQ(r.samples, 0u);
  EXPECT_LT(r.mean_m, 0);
  EXPECT_LT(r.tracking_mean_m, 0);
  EXPECT_DOUBLE_EQ(r.tracking_fraction, 0.0);
}

TEST(LocErrorScoring, PercentileIsNearestRank) {
  EXPECT_DOUBLE_EQ(percentile_nearest_rank({1, 2, 3, 4, 5, 6, 7, 8, 9, 10}, 0.95), 10.0);
  EXPECT_DOUBLE_EQ(percentile_nearest_rank({3, 1, 2}, 0.5), 2.0);
  EXPECT_DOUBLE_EQ(percentile_nearest_rank({}, 0.5), -1.0);
}

}  // namespace
}  // namespace ag::sim
