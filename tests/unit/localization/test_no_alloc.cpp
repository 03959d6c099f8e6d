// The localizer's real-time calls never allocate once constructed (operator new counted by
// tests/common/counting_new.hpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <vector>

#include "airground/localization/semantic_localizer.hpp"
#include "scenario.hpp"
#include "stage_rig.hpp"

#include "../../common/counting_new.hpp"

namespace ag::loc {
namespace {
using test_alloc::AllocationWindow;

TEST(NoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(NoAllocation, LabellingRenderingFilteringFusingAndFieldUpdates) {
  // Everything is built first (constructors may allocate) ...
  test::SyntheticWorld w = test::make_world(8, 8, 3);
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields fields(DistanceFieldParams{}, ch, w.extent());
  test::load_world(w, fields);
  const auto route = test::snake_route(w, 1);
  const std::vector<test::TruthSample> truth = test::drive_route(w, route);
  std::vector<Pose2> odom = test::odometry(truth, test::OdometryNoise{}, 2);
  // ... including a jump of the odometry, so that the filter also diverges and re-spreads in the window
  const std::size_t jump = truth.size() / 2;
  for (std::size_t k = jump; k < odom.size(); ++k)
    odom[k] = compose(odom[jump - 1], compose(Pose2{0.0, 20.0, 0.4}, between(odom[jump - 1], odom[k])));
  std::vector<std::vector<ScanPoint>> scans;
  for (std::size_t k = 0; k < truth.size(); k += 3) {
    scans.emplace_back();
    test::ray_cast(w, truth[k].pose, test::LidarModel{}, k, scans.back());
  }
  std::vector<std::uint8_t> changed = w.tile(3, 3);
  for (std::size_t i = 0; i < 200; ++i) changed[i] = raw(ClassId::kBuilding);
  GroundTruthLabeller gt;
  GeometricLabeller geometric(GeometricLabelParams{}, 32, 512);
  std::vector<ScanPoint> geo = scans[0];
  SemanticLocalizer loc(LocalizerParams{}, ch, 7);
  loc.on_odometry(odom[0], truth[0].stamp);
  loc.initialise_disc(Pose2{truth[0].pose.x + 10.0, truth[0].pose.y - 10.0, truth[0].pose.yaw + 0.4}, 20.0, 0.6,
                      truth[0].stamp);

  std::uint64_t updates = 0;
  {
    AllocationWindow window;
    geometric.label(geo, test::LidarModel{}.rings, test::LidarModel{}.columns);
    for (std::size_t k = 1; k < truth.size(); ++k) {
      loc.on_odometry(odom[k], truth[k].stamp);
      if (loc.wants_scan(fields)) {
        std::vector<ScanPoint>& scan = scans[k / 3];
        gt.label(scan, test::LidarModel{}.rings, test::LidarModel{}.columns);
        updates += loc.on_scan(scan, fields, truth[k].stamp).updated ? 1U : 0U;
      }
      const FusedPoseSample s = loc.pose();
      (void)s;
    }
    EXPECT_TRUE(fields.set_tile(3, 3, 5, changed));
    EXPECT_EQ(fields.update(), 1U);
    fields.recompute_all();
    EXPECT_EQ(window.allocations(), 0U) << "allocations in the localizer's real-time calls";
  }
  EXPECT_GT(updates, 100U);
  EXPECT_GE(loc.filter().estimate().recoveries, 1U) << "the recovery path ran inside the window";
  EXPECT_EQ(loc.filter().status(), FilterStatus::kTracking);
}

TEST(NoAllocation, TheStageStepTakingTilesOdometryScansAndANewInitialPose) {
  test::SyntheticWorld w = test::make_world(test::kSlowTarget ? 5 : 6, test::kSlowTarget ? 5 : 6, 9);
  auto rig = test::StageRig::make(w, {"localization.field_tiles_per_step=2"});
  ASSERT_NE(rig, nullptr);
  const auto route = test::snake_route(w, 1);
  const std::vector<test::TruthSample> truth = test::drive_route(w, route);
  const std::vector<Pose2> odom = test::odometry(truth, test::OdometryNoise{}, 3);
  const test::LidarModel lidar;
  std::vector<std::vector<ScanPoint>> scans;
  for (std::size_t k = 0; k < truth.size(); k += 3) {
    scans.emplace_back();
    test::ray_cast(w, truth[k].pose, lidar, k, scans.back());
  }
  std::vector<std::uint8_t> changed = w.tile(2, 2);
  for (std::size_t i = 0; i < 300; ++i) changed[i] = raw(ClassId::kBuilding);
  // Start-up outside the window: the map, the first odometry, the guess, a few updates.
  rig->push_world(w, 0);
  for (int i = 0; i < 20; ++i) rig->step(0);
  rig->push_odometry(odom[0], truth[0].stamp);
  rig->initial_pose(Pose2{truth[0].pose.x + 4.0, truth[0].pose.y - 3.0, truth[0].pose.yaw + 0.2}, 6.0, 0.3, 1);
  rig->step(truth[0].stamp);
  const std::size_t warm = 30;
  for (std::size_t k = 1; k < warm; ++k) {
    rig->push_odometry(odom[k], truth[k].stamp);
    if (k % 3 == 0) rig->push_scan(scans[k / 3], truth[k].stamp, lidar.rings, lidar.columns);
    rig->step(truth[k].stamp);
  }
  const std::uint64_t matched0 = rig->stage->counters().scans_matched;
  {
    AllocationWindow window;
    for (std::size_t k = warm; k < truth.size(); ++k) {
      rig->push_odometry(odom[k], truth[k].stamp);
      if (k % 3 == 0) rig->push_scan(scans[k / 3], truth[k].stamp, lidar.rings, lidar.columns);
      if (k == truth.size() / 2) {
        rig->push_tile(2, 2, 7, changed);  // a changed tile mid-drive
        rig->initial_pose(truth[k].pose, 2.0, 0.1, 2);  // and an operator's new guess
      }
      rig->step(truth[k].stamp);
    }
    EXPECT_EQ(window.allocations(), 0U) << "allocations in LocalizationStage::step()";
  }
  EXPECT_GT(rig->stage->counters().scans_matched, matched0 + 50) << "the window did real work";
  EXPECT_EQ(rig->stage->counters().initial_poses, 2U);
  EXPECT_EQ(rig->stage->fields().tile_version(2, 2), 7U);
  EXPECT_EQ(rig->latest().status, LocalizationStatus::kTracking);
}

}  // namespace
}  // namespace ag::loc
