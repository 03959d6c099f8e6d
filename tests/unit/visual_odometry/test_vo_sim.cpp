// The VO end to end on rendered frames: the quadrotor flies a straight line and a 90-degree turn over the
// default world at 40 m and 5 m/s, the camera (noise, auto-exposure, blur, vignetting) renders at 5 Hz and
// the simulated autopilot gives the attitude, as `airground-sim eval vo` does. Tracked fraction, relative
// rotation and translation-direction errors over 2 m pairs, vision only on the straight line, determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <vector>

#include "airground/messages/camera.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/sim/attitude.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/visual_odometry/visual_odometry.hpp"

namespace ag::sim {
namespace {

struct Shot {
  TimeNs stamp{0};
  std::vector<std::uint8_t> rgb;
  std::optional<Eigen::Matrix3d> attitude;
  Eigen::Isometry3d truth{Eigen::Isometry3d::Identity()};
  double dist{0};
};

const CameraModel& model() {
  static const CameraModel m = CameraModel{}.scaled(0.5);
  return m;
}

// Flies east 60 m at cruise speed (after 15 m to get there: a survey line, not a take-off), then north 40 m
// when turning, around the world's centre, and renders every 0.2 s.
std::vector<Shot> fly(bool turn) {
  const World& w = default_world();
  const GridGeometry& g = w.grid();
  const double cx = g.origin_x + 0.5 * g.size_x(), cy = g.origin_y - 0.5 * g.size_y();
  std::vector<Waypoint> wps{{cx + 20.0, cy - 20.0, 40.0, 5.0}};
  if (turn) wps.push_back(Waypoint{cx + 20.0, cy + 20.0, 40.0, 5.0});
  QuadrotorConfig qc;
  Quadrotor quad(qc, Pose3{cx - 55.0, cy - 20.0, 40.0, 0, 0, 0});
  quad.set_waypoints(wps);
  CameraSensor sensor;
  sensor.noise = sensor.auto_exposure = sensor.motion_blur = sensor.vignetting = true;
  CameraRenderer renderer(w, model(), CameraShading{}, sensor);
  CameraAutoExposure ae(sensor);
  AttitudeSimulator attitude(AttitudeConfig{}, 7 ^ 0x617474ULL);
  std::optional<Eigen::Matrix3d> att;
  CameraFrame frame;
  std::vector<Shot> shots;
  const double dt = 0.02, frame_dt = 0.2;
  double t = 0, next_frame = 0, dist = 0, yaw_rate = 0;
  Pose3 last = quad.pose();
  std::uint64_t n = 0;
  while (!quad.finished() && t < 60.0) {
    const double yaw0 = quad.pose().yaw;
    quad.step(dt);
    t += dt;
    yaw_rate = std::remainder(quad.pose().yaw - yaw0, 2 * M_PI) / dt;
    const Pose3& p = quad.pose();
    dist += std::hypot(std::hypot(p.x - last.x, p.y - last.y), p.z - last.z);
    last = p;
    const TimeNs stamp = static_cast<TimeNs>(std::llround(t * 1e9));
    AttitudeSample as;
    if (attitude.sample(stamp, p, as)) att = rotation_matrix(as.roll, as.pitch, as.yaw);
    if (dist < 15.0) {
      next_frame = t;
      continue;
    }
    if (t + 1e-9 < next_frame) continue;
    next_frame += frame_dt;
    CameraShot shot;
    shot.seed = 7;
    shot.frame = n++;
    shot.exposure = ae.next();
    shot.velocity = Eigen::Vector3d(quad.vx(), quad.vy(), quad.vz());
    shot.yaw_rate = yaw_rate;
    renderer.render(p, frame, stamp, shot);
    ae.observe(frame);
    Shot s;
    s.stamp = stamp;
    s.rgb.assign(frame.rgb.ptr<std::uint8_t>(0), frame.rgb.ptr<std::uint8_t>(0) + frame.rgb.total() * 3);
    s.attitude = att;
    s.truth = to_isometry(p);
    s.dist = dist;
    shots.push_back(std::move(s));
  }
  return shots;
}

const std::vector<Shot>& turn_flight() {
  static const std::vector<Shot> s = fly(true);
  return s;
}

struct Scores {
  double tracked_fraction{0}, rot_p95{0}, dir_p95{0};
  std::size_t pairs{0};
  std::uint64_t segments{0}, keyframes{0};
  std::vector<vo::VoFrame> frames;
};

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

// Runs the VO over the shots and scores it as eval vo does (pairs ~2 m apart, same segment).
Scores run(const std::vector<Shot>& shots, bool with_attitude, std::size_t count) {
  vo::VoParams p;
  p.camera = model().pinhole();
  vo::VisualOdometry odo(p);
  Scores s;
  count = std::min(count, shots.size());
  for (std::size_t i = 0; i < count; ++i)
    s.frames.push_back(odo.process(shots[i].stamp, shots[i].rgb.data(), with_attitude ? shots[i].attitude : std::nullopt));
  std::size_t tracked = 0;
  for (const vo::VoFrame& f : s.frames) tracked += f.tracking ? 1 : 0;
  s.tracked_fraction = static_cast<double>(tracked) / static_cast<double>(count);
  std::vector<double> rot, dir;
  for (std::size_t i = 0; i < count;) {
    if (!s.frames[i].tracking) {
      ++i;
      continue;
    }
    std::size_t j = i + 1;
    while (j < count && s.frames[j].tracking && s.frames[j].segment == s.frames[i].segment && shots[j].dist - shots[i].dist < 2.0) ++j;
    if (j >= count || !s.frames[j].tracking || s.frames[j].segment != s.frames[i].segment) {
      i = j;
      continue;
    }
    const Eigen::Isometry3d& a = s.frames[i].body_in_segment;
    const Eigen::Isometry3d& b = s.frames[j].body_in_segment;
    const Eigen::Matrix3d dv = a.linear().transpose() * b.linear();
    const Eigen::Matrix3d dt = shots[i].truth.linear().transpose() * shots[j].truth.linear();
    rot.push_back(Eigen::AngleAxisd(dv.transpose() * dt).angle() * 180.0 / M_PI);
    const Eigen::Vector3d tv = a.linear().transpose() * (b.translation() - a.translation());
    const Eigen::Vector3d tt = shots[i].truth.linear().transpose() * (shots[j].truth.translation() - shots[i].truth.translation());
    if (tv.norm() > 1e-9 && tt.norm() > 1e-9)
      dir.push_back(std::acos(std::clamp(tv.normalized().dot(tt.normalized()), -1.0, 1.0)) * 180.0 / M_PI);
    i = j;
  }
  s.pairs = rot.size();
  s.rot_p95 = quantile(rot, 0.95);
  s.dir_p95 = quantile(dir, 0.95);
  s.segments = odo.stats().segments;
  s.keyframes = odo.stats().keyframes;
  return s;
}

TEST(VisualOdometrySim, TracksALineAndATurnWithTheAutopilotsAttitude) {
  const std::vector<Shot>& shots = turn_flight();
  ASSERT_GT(shots.size(), 100U);
  const Scores s = run(shots, true, shots.size());
  std::printf("line + turn, %zu frames over %.0f m: tracked %.3f, %llu segments, %llu keyframes, %zu pairs, rotation p95 %.3f deg, "
              "direction p95 %.2f deg\n",
              shots.size(), shots.back().dist, s.tracked_fraction, static_cast<unsigned long long>(s.segments),
              static_cast<unsigned long long>(s.keyframes), s.pairs, s.rot_p95, s.dir_p95);
  EXPECT_GE(s.tracked_fraction, 0.95);
  EXPECT_GT(s.pairs, 30U);
  EXPECT_LE(s.rot_p95, 0.2);
  EXPECT_LE(s.dir_p95, 2.0);
  EXPECT_GT(s.keyframes, 20U);
}

// Without the autopilot (no gravity, no rotation prediction) a straight line still tracks.
TEST(VisualOdometrySim, TracksAStraightLineWithoutAttitude) {
  const std::vector<Shot>& shots = turn_flight();
  // The first leg at cruise speed, up to the corner's braking.
  std::size_t n = 0;
  while (n < shots.size() && shots[n].dist < 15.0 + 50.0) ++n;
  const Scores s = run(shots, false, n);
  std::printf("line without attitude, %zu frames: tracked %.3f, %llu segments, rotation p95 %.3f deg, direction p95 %.2f deg\n", n,
              s.tracked_fraction, static_cast<unsigned long long>(s.segments), s.rot_p95, s.dir_p95);
  EXPECT_GE(s.tracked_fraction, 0.95);
  EXPECT_EQ(s.segments, 1U);
  EXPECT_LE(s.dir_p95, 5.0);
}

// A camera whose reader is late drops frames (HIL on a busy machine delivers 2-3 of its 5 Hz): the
// frames come 0.2 to 0.6 s apart, and the motion guesses must follow the interval, not the count.
TEST(VisualOdometrySim, TracksFramesThatComeUnevenly) {
  const std::vector<Shot>& all = turn_flight();
  std::vector<Shot> shots;
  constexpr std::size_t kGaps[] = {1, 3, 1, 2, 1, 3, 2, 1};
  for (std::size_t i = 0, k = 0; i < all.size(); i += kGaps[k++ % std::size(kGaps)]) shots.push_back(all[i]);
  ASSERT_GT(shots.size(), 60U);
  const Scores s = run(shots, true, shots.size());
  std::printf("uneven frames, %zu of %zu: tracked %.3f, %llu segments, %llu keyframes, rotation p95 %.3f deg, direction p95 %.2f deg\n",
              shots.size(), all.size(), s.tracked_fraction, static_cast<unsigned long long>(s.segments),
              static_cast<unsigned long long>(s.keyframes), s.rot_p95, s.dir_p95);
  // With the guesses per frame it tracked 0.864 in 5 segments. What still breaks it is the corner: the
  // quadrotor yaws, and 0.6 s apart a 15x15 window has turned more than Lucas-Kanade's shift-only model
  // follows.
  EXPECT_GE(s.tracked_fraction, 0.90);
  EXPECT_LE(s.segments, 3U) << "tracking losses where the frames came late";
  EXPECT_LE(s.dir_p95, 3.0);
}

TEST(VisualOdometrySim, TheSameFramesGiveTheSamePoses) {
  const std::vector<Shot>& shots = turn_flight();
  const Scores a = run(shots, true, 80), b = run(shots, true, 80);
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (std::size_t i = 0; i < a.frames.size(); ++i) {
    EXPECT_EQ(a.frames[i].tracking, b.frames[i].tracking) << i;
    EXPECT_EQ(a.frames[i].keyframe, b.frames[i].keyframe) << i;
    EXPECT_EQ(a.frames[i].segment, b.frames[i].segment) << i;
    EXPECT_EQ(a.frames[i].inliers, b.frames[i].inliers) << i;
    EXPECT_TRUE(a.frames[i].body_in_segment.matrix() == b.frames[i].body_in_segment.matrix()) << "frame " << i << " differs";
  }
}

}  // namespace
}  // namespace ag::sim
