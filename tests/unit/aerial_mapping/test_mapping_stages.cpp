// The UAV mapping stages on bad input: frames without odometry, odometry without frames, out-of-order
// stamps, GPS without a fix, lost tracking. Each is counted, nothing crashes, and mapping resumes.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/messages/channels.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"

namespace ag::mapping {
namespace {

constexpr StageSpec kStages[] = {
    {"pose_graph", &PoseGraphStage::make, 5.0, 150'000, 30, -1, PoseGraphStage::kParams, "pose graph"},
    {"ortho_map", &OrthoMapStage::make, 5.0, 150'000, 20, -1, OrthoMapStage::kParams, "ortho-map"},
};
constexpr ParamSection kSections[] = {{"camera_calibration", kCameraCalibrationParams, "camera"}};

const RoleDescription& role() {
  static const RoleDescription r{"mapping-test", "the two mapping stages", kStages, kSections};
  return r;
}

// What the test feeds, second by second. Straight flight east at 5 m/s, 40 m up.
struct Faults {
  double odometry_gap_from{-1}, odometry_gap_to{-1};  // [s] no odometry (images keep coming)
  double camera_gap_from{-1}, camera_gap_to{-1};      // [s] no images (odometry keeps coming)
  double no_fix_from{-1}, no_fix_to{-1};              // [s] GPS reports fix type 0
  double lost_from{-1}, lost_to{-1};                  // [s] odometry flagged tracking lost
  double out_of_order_at{-1};                         // [s] one image, one odometry sample and one fix stamped 1 s old
  double new_segment_at{-1};                          // [s] odometry restarts: segment 1, its own origin and scale
};

bool in(double t, double a, double b) { return t >= a && t < b; }

struct Run {
  Config config{Config::defaults(role_schema(role()))};
  SimClock clock{0};
  std::unique_ptr<RoleInstance> robot;
  const PoseGraphStage* pg{nullptr};
  const OrthoMapStage* om{nullptr};
};

std::unique_ptr<Run> run(const Faults& f, double duration_s, const std::vector<std::string>& sets = {}) {
  auto r = std::make_unique<Run>();
  for (const std::string& kv : sets) EXPECT_TRUE(r->config.set(kv).ok()) << kv;
  auto created = RoleInstance::create(role(), r->config, r->clock, "uav-test");
  EXPECT_TRUE(created.ok()) << created.error().message;
  if (!created.ok()) return nullptr;
  r->robot = std::move(created).value();
  for (auto& slot : r->robot->stages()) {
    if (auto* p = dynamic_cast<const PoseGraphStage*>(slot.stage.get())) r->pg = p;
    if (auto* q = dynamic_cast<const OrthoMapStage*>(slot.stage.get())) r->om = q;
  }
  auto cam = r->robot->channels().ring_writer(chan::kCamera);
  auto vo = r->robot->channels().ring_writer(chan::kVisualOdometry);
  auto gps = r->robot->channels().ring_writer(chan::kGps);
  EXPECT_TRUE(cam.ok() && vo.ok() && gps.ok());
  if (!cam.ok() || !vo.ok() || !gps.ok()) return nullptr;
  auto image = std::make_unique<CameraImageMsg>();
  // A textured image (stereo finds matches in it) with class labels.
  for (std::size_t i = 0; i < kImagePixels; ++i) {
    const auto v = static_cast<std::uint8_t>((i * 2654435761U) >> 24);
    image->rgb[3 * i] = image->rgb[3 * i + 1] = image->rgb[3 * i + 2] = v;
    image->cls[i] = 0;
  }
  image->labels = LabelSource::kGroundTruth;

  LockstepExecutor ex(r->clock, ExecTimer::kThreadCpu);
  ex.add(*r->robot);
  ex.start(0);
  const TimeNs end = static_cast<TimeNs>(duration_s * 1e9);
  TimeNs next_vo = 0, next_gps = 0, next_cam = 0;
  bool out_of_order_done = false;
  for (TimeNs t = ex.next_release(); t <= end; t = ex.next_release()) {
    auto position = [](double s) { return Eigen::Vector3d(5.0 * s, 0.0, 40.0); };
    for (; next_vo <= t; next_vo += kNsPerS / 10) {
      const double s = to_seconds(next_vo);
      if (in(s, f.odometry_gap_from, f.odometry_gap_to)) continue;
      VoMsg m;
      m.stamp = next_vo;
      m.published = next_vo;
      m.tracking = !in(s, f.lost_from, f.lost_to);
      const Eigen::Vector3d p = position(s);
      m.pose = Pose3{p.x(), p.y(), p.z(), 0.0, 0.0, 0.0};
      if (f.new_segment_at >= 0 && s >= f.new_segment_at) {  // a new frame: origin at the restart, scale 2
        m.segment = 1;
        const Eigen::Vector3d q = 2.0 * (p - position(f.new_segment_at));
        m.pose = Pose3{q.x(), q.y(), q.z(), 0.0, 0.0, 0.0};
      }
      vo.value().push(m);
    }
    for (; next_gps <= t; next_gps += kNsPerS / 5) {
      const double s = to_seconds(next_gps);
      GpsMsg g;
      g.stamp = next_gps;
      g.published = next_gps;
      g.fix_type = in(s, f.no_fix_from, f.no_fix_to) ? 0 : 3;
      const Eigen::Vector3d p = position(s);
      g.east_m = p.x();
      g.north_m = p.y();
      g.up_m = p.z();
      g.h_accuracy_m = 0.5;
      g.v_accuracy_m = 1.0;
      gps.value().push(g);
    }
    for (; next_cam <= t; next_cam += kNsPerS / 5) {
      const double s = to_seconds(next_cam);
      if (in(s, f.camera_gap_from, f.camera_gap_to)) continue;
      image->stamp = next_cam;
      image->published = next_cam;
      cam.value().push(*image);
    }
    if (f.out_of_order_at >= 0 && !out_of_order_done && to_seconds(t) >= f.out_of_order_at) {
      out_of_order_done = true;
      const TimeNs old = t - kNsPerS;
      image->stamp = old;
      cam.value().push(*image);
      VoMsg m;
      m.stamp = old;
      m.tracking = true;
      vo.value().push(m);
      GpsMsg g;
      g.stamp = old;
      g.fix_type = 3;
      g.h_accuracy_m = 0.5;
      gps.value().push(g);
    }
    ex.run_until(t);
  }
  r->robot->stop_all();
  return r;
}

TEST(MappingStages, CleanInputKeyframesEveryTwoMetresAndMatchesPairs) {
  auto r = run(Faults{}, 20.0);
  ASSERT_NE(r, nullptr);
  const PoseGraphStageCounters& c = r->pg->counters();
  // 100 m flown at 2 m keyframes once the graph is georeferenced (a few seconds of GPS baseline).
  EXPECT_GT(c.frames_keyframed, 35u);
  EXPECT_LT(c.frames_keyframed, 52u);
  EXPECT_EQ(c.frames_without_odometry, 0u);
  EXPECT_EQ(c.frames_out_of_order, 0u);
  EXPECT_EQ(c.gps_no_fix, 0u);
  EXPECT_GT(r->om->counters().pairs_matched, 25u);
  EXPECT_GT(r->om->map().cells_classified(), 1000u);
}

// After a tracking loss the new odometry segment starts with the old one's scale, a guess: no keyframes
// (so no stereo depths from guessed baselines) until GPS has seen it travel segment_settle_m (15 m: 3 s
// at 5 m/s, ~15 frames); then keyframing resumes. With the rule off, keyframing goes straight on.
TEST(MappingStages, ANewOdometrySegmentIsNotKeyframedUntilGpsPinnedItsScale) {
  Faults f;
  f.new_segment_at = 10.0;
  auto r = run(f, 25.0);
  ASSERT_NE(r, nullptr);
  const PoseGraphStageCounters& c = r->pg->counters();
  EXPECT_GE(c.frames_settling, 10u);
  EXPECT_LE(c.frames_settling, 22u);
  auto off = run(f, 25.0, {"pose_graph.segment_settle_m=0"});
  ASSERT_NE(off, nullptr);
  EXPECT_EQ(off->pg->counters().frames_settling, 0u);
  // Keyframing resumed after the settling distance: about 15 m (7 keyframes) fewer than without the rule.
  const std::uint64_t with = c.frames_keyframed, without = off->pg->counters().frames_keyframed;
  ASSERT_GT(without, with);
  EXPECT_GE(without - with, 4u);
  EXPECT_LE(without - with, 10u);
  EXPECT_GT(with, 35u) << "keyframing resumed";
}

TEST(MappingStages, EveryKindOfBadInputIsCountedAndMappingResumes) {
  Faults f;
  f.no_fix_from = 2;           // 10 fixes without a fix
  f.no_fix_to = 4;
  f.odometry_gap_from = 8;     // 3 s without odometry: the images of that time cannot be placed
  f.odometry_gap_to = 11;
  f.camera_gap_from = 14;      // 3 s of odometry without images
  f.camera_gap_to = 17;
  f.lost_from = 20;            // 1 s of tracking lost
  f.lost_to = 21;
  f.out_of_order_at = 24;
  auto r = run(f, 40.0);
  ASSERT_NE(r, nullptr);
  const PoseGraphStageCounters& c = r->pg->counters();
  const PoseGraphStats& g = r->pg->graph().stats();
  EXPECT_EQ(c.gps_no_fix, 10u);
  EXPECT_GE(c.frames_without_odometry, 10u);  // ~15 images in the gap, minus those bracketed at its ends
  EXPECT_LE(c.frames_without_odometry, 16u);
  EXPECT_EQ(c.odometry_lost, 10u);
  EXPECT_EQ(c.frames_out_of_order, 1u);
  EXPECT_EQ(g.frames_rejected, 1u);
  EXPECT_EQ(g.gps_rejected_order, 1u);
  // Keyframes kept coming after every fault (200 m flown, ~35 m of it in gaps).
  EXPECT_GT(c.frames_keyframed, 60u);
  ASSERT_GT(r->pg->keyframes(), 0u);
  EXPECT_GT(to_seconds(r->pg->keyframe_stamp(r->pg->keyframes() - 1)), 38.0);
  EXPECT_GT(r->om->counters().pairs_matched, 60u);
  EXPECT_TRUE(r->pg->graph().initialised());
}

}  // namespace
}  // namespace ag::mapping
