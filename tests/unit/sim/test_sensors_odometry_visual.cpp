// Tests of the simulated visual odometry: scaled shape within a segment, drift, tracking losses, config.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "airground/sim/visual_odometry.hpp"

namespace ag::sim {
namespace {

// A survey-like flight: a wide circle with a slow climb, nose along the motion.
Pose3 flight(double t) {
  const double w = 0.05, r = 100.0;
  return Pose3{r * std::cos(w * t), r * std::sin(w * t), 40.0 + 0.05 * t, 0.02, -0.01, wrap_angle(w * t + kPi / 2)};
}

VoConfig exact() {
  VoConfig c;
  c.scale_drift_per_s = c.yaw_drift_rad_per_s = 0.0;
  c.position_noise_m = c.rotation_noise_rad = 0.0;
  c.tracking_loss_rate_per_s = 0.0;
  return c;
}

double dist(const Pose3& a, const Pose3& b) {
  return std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) + (a.z - b.z) * (a.z - b.z));
}

TEST(VisualOdometry, SegmentIsTheTruthScaledAndRotated) {
  VisualOdometrySimulator vo(exact(), 7);
  VoSample s;
  std::vector<VoSample> out;
  std::vector<Pose3> truth;
  for (TimeNs t = 0; t < 120 * kNsPerS; t += 10 * kNsPerMs) {
    if (vo.sample(t, flight(to_seconds(t)), s)) {
      out.push_back(s);
      truth.push_back(flight(to_seconds(t)));
    }
  }
  ASSERT_EQ(out.size(), 1200u);  // 10 Hz
  const double scale = vo.scale();
  EXPECT_GE(scale, 0.3);
  EXPECT_LE(scale, 3.0);
  const double off = vo.yaw_offset(), c = std::cos(off), sn = std::sin(off);
  EXPECT_NEAR(out[0].pose.x, 0.0, 1e-12);  // the segment starts at its origin
  for (std::size_t k = 0; k < out.size(); ++k) {
    EXPECT_EQ(out[k].segment, 0u);
    EXPECT_TRUE(out[k].tracking);
    const double dx = truth[k].x - truth[0].x, dy = truth[k].y - truth[0].y, dz = truth[k].z - truth[0].z;
    EXPECT_NEAR(out[k].pose.x, scale * (c * dx - sn * dy), 1e-6);
    EXPECT_NEAR(out[k].pose.y, scale * (sn * dx + c * dy), 1e-6);
    EXPECT_NEAR(out[k].pose.z, scale * dz, 1e-6);
    EXPECT_NEAR(wrap_angle(out[k].pose.yaw - truth[k].yaw - off), 0.0, 1e-9);
    EXPECT_DOUBLE_EQ(out[k].pose.roll, truth[k].roll);  // gravity-aligned frame
    if (k > 0) {
      EXPECT_NEAR(dist(out[k].pose, out[k - 1].pose), scale * dist(truth[k], truth[k - 1]), 1e-9);
    }
  }
}

TEST(VisualOdometry, RelativeMotionFollowsTheDriftingScale) {
  VoConfig c;  // default drift and noise, no losses
  c.tracking_loss_rate_per_s = 0.0;
  VisualOdometrySimulator vo(c, 3);
  VoSample s;
  Pose3 last_truth{}, last_vo{};
  double scale0 = 0, last_scale = 0;
  int n = 0;
  for (TimeNs t = 0; t < 300 * kNsPerS; t += 100 * kNsPerMs) {
    const Pose3 truth = flight(to_seconds(t));
    ASSERT_TRUE(vo.sample(t, truth, s));
    if (n == 0) scale0 = vo.scale();
    // Over 10 s (~50 m) the VO displacement is the true one times the current scale, within the
    // position noise (2 cm per frame) and the drift over those 10 s.
    if (n > 0 && n % 100 == 0) {
      const double ratio = dist(s.pose, last_vo) / dist(truth, last_truth);
      EXPECT_NEAR(ratio / (0.5 * (vo.scale() + last_scale)), 1.0, 0.01) << "t=" << to_seconds(t);
    }
    if (n % 100 == 0) {
      last_truth = truth;
      last_vo = s.pose;
      last_scale = vo.scale();
    }
    ++n;
  }
  // The log scale wanders by ~0.002 * sqrt(300) = 3.5% (1 sigma) over the run: it moved, not much.
  EXPECT_NE(vo.scale(), scale0);
  EXPECT_NEAR(std::log(vo.scale() / scale0), 0.0, 0.15);
  EXPECT_EQ(s.segment, 0u);
}

TEST(VisualOdometry, TrackingLossStartsANewSegmentInANewFrame) {
  VoConfig c = exact();
  c.tracking_loss_rate_per_s = 0.05;
  c.tracking_loss_duration_s = 2.0;
  VisualOdometrySimulator vo(c, 11);
  VoSample s;
  std::uint32_t segment = 0;
  double scale = 0, offset = 0;
  bool was_tracking = true;
  int new_segments = 0, lost_frames = 0, frames = 0;
  std::vector<double> scales;
  for (TimeNs t = 0; t < 1200 * kNsPerS; t += 10 * kNsPerMs) {
    if (!vo.sample(t, flight(to_seconds(t)), s)) continue;
    ++frames;
    if (frames == 1) {
      scale = vo.scale();
      offset = vo.yaw_offset();
      scales.push_back(scale);
    }
    if (!s.tracking) {
      ++lost_frames;
      EXPECT_EQ(s.segment, segment);  // still the old one while lost
      was_tracking = false;
      continue;
    }
    if (s.segment != segment) {
      EXPECT_EQ(s.segment, segment + 1);
      ++new_segments;
      // A fresh frame: origin at the restart, a new scale and yaw.
      EXPECT_NEAR(s.pose.x, 0.0, 1e-12);
      EXPECT_NEAR(s.pose.y, 0.0, 1e-12);
      EXPECT_NE(vo.scale(), scale);
      EXPECT_NE(vo.yaw_offset(), offset);
      segment = s.segment;
      scale = vo.scale();
      offset = vo.yaw_offset();
      scales.push_back(scale);
    } else {
      EXPECT_TRUE(was_tracking) << "tracking resumed without a new segment";
      EXPECT_DOUBLE_EQ(vo.scale(), scale);  // no drift configured
    }
    was_tracking = true;
  }
  // ~0.05/s over 1200 s: about 60 losses, each making one new segment (some may end between frames).
  EXPECT_GT(new_segments, 35);
  EXPECT_LT(new_segments, 90);
  // Every loss makes a new segment, except one still running at the end or two between the same frames.
  EXPECT_LE(static_cast<std::uint64_t>(new_segments), vo.tracking_losses());
  EXPECT_GE(static_cast<std::uint64_t>(new_segments) + 2, vo.tracking_losses());
  EXPECT_GT(lost_frames, 0);
  for (double sc : scales) {
    EXPECT_GE(sc, 0.3);
    EXPECT_LE(sc, 3.0);
  }
}

TEST(VisualOdometry, ShortLossBetweenFramesStillBreaksTheSegment) {
  VoConfig c = exact();
  c.rate_hz = 0.5;  // a frame every 2 s
  c.tracking_loss_rate_per_s = 0.2;
  c.tracking_loss_duration_s = 0.05;  // usually over before the next frame
  VisualOdometrySimulator vo(c, 5);
  VoSample s;
  std::uint32_t last_segment = 0;
  std::uint64_t breaks = 0;
  for (TimeNs t = 0; t < 2000 * kNsPerS; t += 100 * kNsPerMs) {
    if (!vo.sample(t, flight(to_seconds(t)), s) || !s.tracking) continue;
    if (s.segment != last_segment) breaks += s.segment - last_segment;
    last_segment = s.segment;
  }
  EXPECT_GT(vo.tracking_losses(), 200u);
  // Several losses between two frames make one restart.
  EXPECT_GT(breaks, vo.tracking_losses() / 2);
  EXPECT_LE(breaks, vo.tracking_losses());
}

TEST(VisualOdometry, InitialScaleIsLogUniformInItsRange) {
  std::vector<double> logs;
  for (std::uint64_t seed = 0; seed < 4000; ++seed) {
    VisualOdometrySimulator vo(exact(), seed);
    VoSample s;
    vo.sample(0, Pose3{}, s);
    logs.push_back(std::log(vo.scale()));
  }
  const double lo = std::log(0.3), hi = std::log(3.0);
  int below_mid = 0;
  for (double l : logs) {
    EXPECT_GE(l, lo);
    EXPECT_LE(l, hi);
    below_mid += l < 0.5 * (lo + hi) ? 1 : 0;
  }
  EXPECT_NEAR(below_mid, 2000, 150);
}

TEST(VisualOdometry, DeterministicBySeed) {
  auto run = [](std::uint64_t seed) {
    VoConfig c;
    c.tracking_loss_rate_per_s = 0.02;
    VisualOdometrySimulator vo(c, seed);
    std::vector<double> xs;
    VoSample s;
    for (TimeNs t = 0; t < 600 * kNsPerS; t += 20 * kNsPerMs)
      if (vo.sample(t, flight(to_seconds(t)), s)) xs.push_back(s.pose.x + 1000.0 * s.segment);
    return xs;
  };
  EXPECT_EQ(run(1), run(1));
  EXPECT_NE(run(1), run(2));
}

TEST(VoConfigYaml, LoadsAndValidatesEveryKey) {
  auto ok = load_vo_config("scale_min: 0.5\nscale_max: 2\nrandom_initial_yaw: false\n", "vo.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_DOUBLE_EQ(ok->scale_min, 0.5);
  EXPECT_FALSE(ok->random_initial_yaw);
  auto order = load_vo_config("scale_min: 2\nscale_max: 1\n", "vo.yaml");
  ASSERT_FALSE(order.ok());
  EXPECT_NE(order.error().message.find("scale_min"), std::string::npos) << order.error().message;
  auto unknown = load_vo_config("scale: 1\n", "vo.yaml");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.error().message.find("visual_odometry.scale"), std::string::npos);
  auto range = load_vo_config("tracking_loss_rate_per_s: -1\n", "vo.yaml");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.error().message.find("[0, 10] 1/s"), std::string::npos) << range.error().message;
}

}  // namespace
}  // namespace ag::sim
