// The VO's process() and the vo stage's step() never allocate after the first frame, across keyframes
// with bundle adjustment, a tracking loss and a restart (operator new counted by tests/common/counting_new.hpp).
#include <gtest/gtest.h>

#include <vector>

#include "airground/visual_odometry/visual_odometry.hpp"
#include "vo_stage_rig.hpp"

#include "../../common/counting_new.hpp"

namespace ag::vo {
namespace {
using test_alloc::AllocationWindow;

TEST(NoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(NoAllocation, ProcessAcrossKeyframesALossAndARestart) {
  VoParams p;
  const PinholeCamera& cam = p.camera;  // default 640x400, no distortion
  // Frames first (5 m/s east at 40 m, 5 Hz, a weave; frames 30-32 blank: the track is lost).
  const std::size_t n = 60, px = static_cast<std::size_t>(cam.width) * static_cast<std::size_t>(cam.height) * 3;
  std::vector<std::vector<std::uint8_t>> frames(n, std::vector<std::uint8_t>(px));
  std::vector<Eigen::Matrix3d> att(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double s = 0.2 * static_cast<double>(i);
    att[i] = test::Rig::truth_attitude(s);
    if (i >= 30 && i < 33)
      std::fill(frames[i].begin(), frames[i].end(), std::uint8_t{128});
    else
      test::render_ground(cam, test::Rig::position(s), att[i], frames[i].data());
  }
  VisualOdometry vo(p);
  (void)vo.process(0, frames[0].data(), att[0]);
  {
    AllocationWindow w;
    for (std::size_t i = 1; i < n; ++i) {
      // Half without attitude: the vision-only prediction path too.
      const std::optional<Eigen::Matrix3d> a = i % 10 < 5 ? std::optional<Eigen::Matrix3d>(att[i]) : std::nullopt;
      (void)vo.process(static_cast<TimeNs>(i) * 200'000'000, frames[i].data(), a);
    }
    EXPECT_EQ(w.allocations(), 0U) << "allocations in VisualOdometry::process";
  }
  const VoStats& st = vo.stats();
  EXPECT_GE(st.keyframes, 8U);
  EXPECT_GE(st.losses, 1U);
  EXPECT_GE(st.segments, 2U);
  EXPECT_GT(st.last_adjustment.iterations, 0) << "bundle adjustment ran";
  EXPECT_GT(st.tracked_frames, 45U);
}

TEST(NoAllocation, TheStageStepAcrossALossAndWaitsForTheAttitude) {
  test::Rig r;
  ASSERT_NE(r.stage, nullptr);
  test::Feed f;
  f.attitude_delay_s = 0.05;
  f.attitude_stop_s = 7.0;
  f.blank_from_s = 4.0;
  f.blank_to_s = 4.6;
  r.run(f, 0.3);  // the first frame (sizes the buffers)
  ASSERT_GE(r.stage->counters().frames, 1U);
  {
    test_alloc::AllocationWindow w;
    r.run(f, 9.0);
    EXPECT_EQ(w.allocations(), 0U) << "allocations in the stage's step (or the feed)";
  }
  const VoStageCounters& c = r.stage->counters();
  EXPECT_GE(c.keyframes, 10U);
  EXPECT_GE(c.lost, 2U);
  EXPECT_EQ(c.segments, 2U);
  EXPECT_GE(c.frames_without_attitude, 5U);
}

}  // namespace
}  // namespace ag::vo
