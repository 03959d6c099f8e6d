// The `vo` stage in a role instance: one VoMsg per camera frame with the frame's stamp, in order; a frame
// waits for the attitude after it up to attitude_max_wait_s; frames without attitude are counted; a lost
// track starts a new segment.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "vo_stage_rig.hpp"

namespace ag::vo::test {
namespace {

void expect_one_message_per_frame(Rig& r) {
  // Frames still queued (waiting for their attitude) at the end are not published yet.
  ASSERT_LE(r.published().size(), r.frame_stamps.size());
  EXPECT_GE(r.published().size() + 2, r.frame_stamps.size());
  for (std::size_t i = 0; i < r.published().size(); ++i) {
    EXPECT_EQ(r.published()[i].stamp, r.frame_stamps[i]) << "message " << i;
    EXPECT_GE(r.published()[i].published, r.published()[i].stamp);
  }
  EXPECT_EQ(r.stage->counters().frames, r.published().size());
  EXPECT_EQ(r.stage->counters().frames_dropped_busy, 0U);
}

TEST(VoStage, PublishesOneMessagePerFrameWithItsStampAndTracks) {
  Rig r;
  ASSERT_NE(r.stage, nullptr);
  Feed f;
  r.run(f, 8.0);
  expect_one_message_per_frame(r);
  const VoStageCounters& c = r.stage->counters();
  std::printf("frames %llu, tracked %llu, keyframes %llu, with attitude %llu\n", static_cast<unsigned long long>(c.frames),
              static_cast<unsigned long long>(c.tracked), static_cast<unsigned long long>(c.keyframes),
              static_cast<unsigned long long>(c.frames_with_attitude));
  EXPECT_GE(c.frames, 39U);
  EXPECT_EQ(c.frames_with_attitude, c.frames);
  EXPECT_EQ(c.frames_without_attitude, 0U);
  EXPECT_GE(c.tracked + 3, c.frames) << "all but the start";
  EXPECT_GE(c.keyframes, 10U);
  EXPECT_EQ(c.segments, 1U);
  // The pose moves east (body x): 5 m/s; in VO units, but the direction holds.
  const VoMsg& last = r.published().back();
  ASSERT_TRUE(last.tracking);
  EXPECT_GT(last.pose.x, 0.0);
  EXPECT_LT(std::abs(last.pose.y), 0.1 * last.pose.x);
  EXPECT_LT(std::abs(last.pose.z), 0.1 * last.pose.x);
}

// Attitude arriving 100 ms after its stamp: each frame waits for the sample after it, so every frame is
// processed with the attitude (interpolated), and published no earlier than that sample.
TEST(VoStage, AFrameWaitsForTheAttitudeAfterIt) {
  Rig r;
  Feed f;
  f.attitude_delay_s = 0.1;
  r.run(f, 6.0);
  expect_one_message_per_frame(r);
  const VoStageCounters& c = r.stage->counters();
  // Only the frame at t = 0 goes without: no attitude has arrived yet, so the stage does not know there
  // is an autopilot to wait for.
  EXPECT_LE(c.frames_without_attitude, 1U);
  EXPECT_EQ(c.frames_with_attitude + c.frames_without_attitude, c.frames);
  for (const VoMsg& m : r.published())
    if (m.stamp > 0) {
      EXPECT_GE(m.published - m.stamp, static_cast<TimeNs>(0.1e9)) << "published before the attitude after it arrived";
    }
}

// The attitude stops at 3 s: later frames wait attitude_max_wait_s (0.2 s), then go without it and are
// counted; nothing is dropped and the stage keeps tracking on vision.
TEST(VoStage, FramesWithoutAttitudeWaitAtMostTheMaxWaitAndAreCounted) {
  Rig r;
  Feed f;
  f.attitude_stop_s = 3.0;
  r.run(f, 7.0);
  expect_one_message_per_frame(r);
  const VoStageCounters& c = r.stage->counters();
  EXPECT_GE(c.frames_with_attitude, 14U);
  EXPECT_GE(c.frames_without_attitude, 18U);
  EXPECT_EQ(c.frames_with_attitude + c.frames_without_attitude, c.frames);
  for (const VoMsg& m : r.published()) {
    if (to_seconds(m.stamp) <= 3.1) continue;
    EXPECT_GE(m.published - m.stamp, static_cast<TimeNs>(0.2e9)) << "did not wait";
    EXPECT_LE(m.published - m.stamp, static_cast<TimeNs>(0.2e9 + 0.1e9 + 1)) << "waited longer than max_wait + one period";
  }
  EXPECT_GE(c.tracked + 3, c.frames);
}

// No autopilot at all: nothing to wait for, every frame goes at once and is counted without attitude.
TEST(VoStage, WithoutAnyAttitudeFramesGoAtOnce) {
  Rig r;
  Feed f;
  f.attitude = false;
  r.run(f, 5.0);
  expect_one_message_per_frame(r);
  const VoStageCounters& c = r.stage->counters();
  EXPECT_EQ(c.frames_with_attitude, 0U);
  EXPECT_EQ(c.frames_without_attitude, c.frames);
  for (const VoMsg& m : r.published()) EXPECT_LE(m.published - m.stamp, static_cast<TimeNs>(0.1e9 + 1));
  EXPECT_GE(c.tracked + 4, c.frames);
}

// Blank frames lose the track; it restarts on texture in a new segment, and the messages say so.
TEST(VoStage, ALostTrackStartsANewSegment) {
  Rig r;
  Feed f;
  f.blank_from_s = 3.0;
  f.blank_to_s = 3.5;
  r.run(f, 7.0);
  expect_one_message_per_frame(r);
  const VoStageCounters& c = r.stage->counters();
  EXPECT_GE(c.lost, 3U);
  EXPECT_EQ(c.segments, 2U);
  bool seen_lost = false;
  for (const VoMsg& m : r.published()) {
    if (to_seconds(m.stamp) >= 3.0 && to_seconds(m.stamp) < 3.5) {
      EXPECT_FALSE(m.tracking);
      seen_lost = true;
    }
  }
  EXPECT_TRUE(seen_lost);
  ASSERT_TRUE(r.published().back().tracking);
  EXPECT_EQ(r.published().back().segment, 1U);
}

}  // namespace
}  // namespace ag::vo::test
