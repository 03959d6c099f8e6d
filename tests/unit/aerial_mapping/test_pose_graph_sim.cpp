// The ASOOM pose graph against the simulator's own models: a quadrotor flying a lawnmower survey at 40 m
// and 5 m/s, stepped at 50 Hz; its monocular visual odometry (10 Hz frames, unknown scale and yaw, per
// segment) goes to add_frame and its GPS (5 Hz, 0.5 m) to add_gps; update() after every frame.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <vector>

#include "airground/aerial_mapping/pose_graph.hpp"
#include "airground/core/pose_math.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/world.hpp"

namespace {

using ag::Pose3;
using ag::TimeNs;
using ag::mapping::kNoNode;
using ag::mapping::NodeId;
using ag::mapping::PoseGraph;
using ag::mapping::PoseGraphParams;

// The simulated VO's rotation noise is 0.001 rad per frame: ASOOM's 0.05 rad between-factor leaves
// yaw to the noisy direction of travel (about 0.03 rad rms); 0.005 keeps what the odometry knows.
PoseGraphParams test_params() {
  PoseGraphParams p;
  p.between_sigma_rad = 0.005;
  return p;
}

struct Flight {
  double duration_s{70.0};
  std::uint64_t seed{1};
  double vo_scale{1.0};            // forced VO scale (VO units per metre) of the first segment
  double vo_scale_after_loss{1.0}; // ... and of the segment after the forced loss
  double loss_at_s{-1.0};          // a forced tracking loss starts here (< 0: none) ...
  double loss_length_s{2.0};       // ... and lasts this long; odometry restarts as segment 1
  double outlier_at_s{-1.0};       // the first fix at or after this time is moved 50 m east (< 0: none)
  double vo_loss_rate_per_s{0.0};  // the VO model's own random tracking losses (and then random scales)
  bool gps{true};
  PoseGraphParams params{test_params()};
};

struct NodeTruth {
  Pose3 truth;
  double t_s{0};
  std::uint32_t segment{0};
  Eigen::Vector3d at_add{Eigen::Vector3d::Zero()};  // pose() right after add_frame (the prediction)
  bool initialised_at_add{false};                   // graph.initialised() then
};

struct FlightResult {
  std::vector<NodeTruth> nodes;          // by node id
  std::map<std::uint32_t, double> vo_scale;  // true VO units per metre, per segment
  int outliers_injected{0};
};

ag::sim::VoConfig vo_config(double scale, double loss_rate) {
  ag::sim::VoConfig c;
  if (loss_rate <= 0) c.scale_min = c.scale_max = scale;  // else the model's random scale per segment
  c.scale_drift_per_s = 0.0;           // one scale per segment is the model: keep the truth constant
  c.tracking_loss_rate_per_s = loss_rate;
  return c;
}

// Flies the survey and feeds the graph; returns the truth of every node.
FlightResult fly(const Flight& f, PoseGraph& graph) {
  ag::sim::QuadrotorConfig qc;
  auto route = ag::sim::survey_lawnmower(-120.0, -80.0, 120.0, 80.0, 40.0, 0.3, 1.2);
  EXPECT_TRUE(route.ok());
  ag::sim::Quadrotor quad(qc, Pose3{route.value()[0].x, route.value()[0].y, 40.0, 0, 0, 0.3});
  quad.set_waypoints(route.value());
  ag::sim::VisualOdometrySimulator vo0(vo_config(f.vo_scale, f.vo_loss_rate_per_s), f.seed);
  ag::sim::VisualOdometrySimulator vo1(vo_config(f.vo_scale_after_loss, 0.0), f.seed + 100);
  ag::sim::GpsConfig gc;
  gc.sigma_m = 0.5;
  gc.dropout_rate_per_s = 0.0;
  ag::sim::GpsSimulator gps(gc, ag::sim::Datum{}, f.seed + 7);

  FlightResult r;
  const TimeNs dt = ag::period_from_hz(50.0);
  const auto steps = static_cast<std::int64_t>(f.duration_s * 50.0);
  bool outlier_done = false;
  for (std::int64_t k = 0; k <= steps; ++k) {
    const TimeNs t = k * dt;
    const double ts = ag::to_seconds(t);
    if (k > 0) quad.step(0.02);
    const Pose3 truth = quad.pose();
    const bool lost = f.loss_at_s >= 0 && ts >= f.loss_at_s && ts < f.loss_at_s + f.loss_length_s;
    const bool second = f.loss_at_s >= 0 && ts >= f.loss_at_s + f.loss_length_s;
    ag::sim::VoSample vs;
    ag::sim::VisualOdometrySimulator& vo = second ? vo1 : vo0;
    if (!lost && vo.sample(t, truth, vs) && vs.tracking) {
      const std::uint32_t seg = second ? 1U : vs.segment;
      const NodeId id = graph.add_frame(vs.stamp, seg, vs.pose);
      EXPECT_NE(id, kNoNode);
      if (id != kNoNode) {
        r.nodes.resize(static_cast<std::size_t>(id) + 1);
        r.nodes[static_cast<std::size_t>(id)] = NodeTruth{truth, ts, seg, graph.pose(id).translation(), graph.initialised()};
        r.vo_scale[seg] = vo.scale();
      }
      graph.update();
    }
    ag::sim::GpsFix fix;
    if (f.gps && gps.sample(t, truth, fix) && fix.fix_type != ag::sim::GpsFixType::kNoFix) {
      Eigen::Vector3d enu(fix.east_m, fix.north_m, fix.up_m);
      if (f.outlier_at_s >= 0 && !outlier_done && ts >= f.outlier_at_s) {
        enu.x() += 50.0;
        outlier_done = true;
        ++r.outliers_injected;
      }
      graph.add_gps(fix.stamp, enu, fix.h_accuracy_m);
    }
  }
  graph.update(true);
  return r;
}

struct Errors {
  double rms_m{0};
  double max_m{0};
  double rms_yaw{0};
  double max_yaw{0};
  double max_tilt{0};
  std::size_t n{0};
};

// Position and yaw errors of the nodes with t in [t0, t1] (and of segment `seg` if >= 0).
Errors errors(const PoseGraph& g, const FlightResult& r, double t0, double t1, int seg = -1) {
  Errors e;
  double se = 0, sy = 0;
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    const NodeTruth& nt = r.nodes[i];
    if (nt.t_s < t0 || nt.t_s > t1 || (seg >= 0 && nt.segment != static_cast<std::uint32_t>(seg))) continue;
    const Eigen::Isometry3d p = g.pose(static_cast<NodeId>(i));
    const Eigen::Isometry3d t = ag::to_isometry(nt.truth);
    const double d = (p.translation() - t.translation()).norm();
    const Pose3 pe = ag::to_pose3(p);
    const double dy = std::abs(ag::wrap_angle(pe.yaw - nt.truth.yaw));
    const double tilt = Eigen::AngleAxisd(Eigen::Quaterniond(p.linear() * t.linear().transpose())).angle();
    se += d * d;
    sy += dy * dy;
    e.max_m = std::max(e.max_m, d);
    e.max_yaw = std::max(e.max_yaw, dy);
    e.max_tilt = std::max(e.max_tilt, tilt);
    ++e.n;
  }
  if (e.n > 0) {
    e.rms_m = std::sqrt(se / static_cast<double>(e.n));
    e.rms_yaw = std::sqrt(sy / static_cast<double>(e.n));
  }
  return e;
}

void print(const char* what, const Errors& e, const PoseGraph& g) {
  std::printf("%s: %zu nodes, position rms %.3f max %.3f m, yaw rms %.4f max %.4f rad, rotation max %.4f rad; "
              "%llu solves, last %.1f ms\n",
              what, e.n, e.rms_m, e.max_m, e.rms_yaw, e.max_yaw, e.max_tilt,
              static_cast<unsigned long long>(g.stats().solves), g.stats().last_solve_ms);
}

// Largest error of pose() right after add_frame (the prediction the mapper gets at once), over the
// frames added while the graph was initialised, and over those added >= 10 s after their segment was.
struct Prediction {
  double max_m{0};
  double max_settled_m{0};
  std::size_t n{0};
  std::size_t n_settled{0};
};

Prediction prediction_errors(const FlightResult& r) {
  Prediction p;
  std::map<std::uint32_t, double> init_at;
  for (const NodeTruth& nt : r.nodes) {
    if (!nt.initialised_at_add) continue;
    if (init_at.count(nt.segment) == 0) init_at[nt.segment] = nt.t_s;
    const double d = (nt.at_add - Eigen::Vector3d(nt.truth.x, nt.truth.y, nt.truth.z)).norm();
    p.max_m = std::max(p.max_m, d);
    ++p.n;
    if (nt.t_s >= init_at[nt.segment] + 10.0) {
      p.max_settled_m = std::max(p.max_settled_m, d);
      ++p.n_settled;
    }
  }
  return p;
}

// |metres per VO unit x VO units per metre - 1|
double scale_error(const PoseGraph& g, const FlightResult& r, std::uint32_t seg) {
  return std::abs(g.scale(seg) * r.vo_scale.at(seg) - 1.0);
}

class PoseGraphScale : public ::testing::TestWithParam<double> {};

TEST_P(PoseGraphScale, RecoversScaleYawAndPositions) {
  Flight f;
  f.vo_scale = GetParam();
  f.duration_s = 70.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  ASSERT_TRUE(g.initialised());
  EXPECT_EQ(g.stats().segments, 1U);
  EXPECT_EQ(g.stats().frames_rejected, 0U);
  EXPECT_EQ(g.stats().scale_flips, 0U);
  EXPECT_GT(g.stats().gps_factors, 0U);
  const Errors e = errors(g, r, f.duration_s - 30.0, f.duration_s);
  print(GetParam() < 1 ? "scale 0.3" : "scale 3.0", e, g);
  std::printf("  scale error %.5f\n", scale_error(g, r, 0));
  EXPECT_LE(scale_error(g, r, 0), 0.01);
  EXPECT_GT(e.n, 250U);
  EXPECT_LE(e.rms_m, 0.3);
  EXPECT_LE(e.rms_yaw, 0.01);
  EXPECT_LE(e.max_tilt, 0.05);
  const Prediction pred = prediction_errors(r);
  std::printf("  prediction at add_frame: max error %.3f m over %zu frames, %.3f m from 10 s after initialisation\n", pred.max_m,
              pred.n, pred.max_settled_m);
  EXPECT_GT(pred.n_settled, 500U);
  EXPECT_LE(pred.max_m, 2.0);
  EXPECT_LE(pred.max_settled_m, 1.0);
}

INSTANTIATE_TEST_SUITE_P(ForcedVoScale, PoseGraphScale, ::testing::Values(0.3, 3.0));

TEST(PoseGraph, TrackingLossStartsASegmentThatGpsPlaces) {
  Flight f;
  f.duration_s = 80.0;
  f.vo_scale = 0.5;
  f.vo_scale_after_loss = 2.0;
  f.loss_at_s = 40.0;
  f.loss_length_s = 2.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  EXPECT_EQ(g.stats().segments, 2U);
  EXPECT_TRUE(g.segment_initialised(0));
  EXPECT_TRUE(g.segment_initialised(1));
  EXPECT_TRUE(g.initialised());
  std::printf("scale errors: segment 0 %.5f, segment 1 %.5f\n", scale_error(g, r, 0), scale_error(g, r, 1));
  EXPECT_LE(scale_error(g, r, 1), 0.01);
  const Errors e1 = errors(g, r, f.loss_at_s + f.loss_length_s + 5.0, f.duration_s, 1);
  print("segment 1", e1, g);
  EXPECT_GT(e1.n, 250U);
  EXPECT_LE(e1.rms_m, 0.3);
  EXPECT_LE(e1.rms_yaw, 0.01);
}

TEST(PoseGraph, RandomTrackingLossesOfTheVoModel) {
  Flight f;
  f.duration_s = 90.0;
  f.seed = 3;
  f.vo_loss_rate_per_s = 1.0 / 15.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  std::printf("%llu segments\n", static_cast<unsigned long long>(g.stats().segments));
  EXPECT_GE(g.stats().segments, 4U);
  EXPECT_EQ(g.stats().segments, r.vo_scale.size());
  for (const auto& [seg, vo_scale] : r.vo_scale) {
    double t0 = 1e9, t1 = -1;
    for (const NodeTruth& nt : r.nodes) {
      if (nt.segment != seg) continue;
      t0 = std::min(t0, nt.t_s);
      t1 = std::max(t1, nt.t_s);
    }
    const Errors e = errors(g, r, t0 + 2.0, t1, static_cast<int>(seg));
    std::printf("segment %u: %.1f-%.1f s, VO scale %.3f, initialised %d, scale error %.4f, position rms %.3f max %.3f m, yaw rms %.4f\n", seg,
                t0, t1, vo_scale, g.segment_initialised(seg) ? 1 : 0, scale_error(g, r, seg), e.rms_m, e.max_m, e.rms_yaw);
    if (t1 - t0 < 5.0) continue;  // too short to judge
    EXPECT_TRUE(g.segment_initialised(seg)) << seg;
    EXPECT_LE(scale_error(g, r, seg), 0.02) << seg;
    EXPECT_LE(e.rms_m, 0.4) << seg;
    EXPECT_LE(e.max_m, 1.0) << seg;
  }
}

TEST(PoseGraph, GpsOutlierBeforeInitialisationIsTrimmed) {
  for (const double at : {0.0, 0.4}) {
    Flight f;
    f.duration_s = 30.0;
    f.vo_scale = 0.6;
    f.outlier_at_s = at;
    PoseGraph g(f.params);
    const FlightResult r = fly(f, g);
    ASSERT_EQ(r.outliers_injected, 1);
    EXPECT_TRUE(g.initialised());
    EXPECT_GE(g.stats().gps_rejected_gate, 1U) << at;
    const Errors e = errors(g, r, 0.0, f.duration_s);
    print("outlier before initialisation", e, g);
    EXPECT_LE(e.max_m, 1.0) << at;
    EXPECT_LE(scale_error(g, r, 0), 0.01) << at;
  }
}

TEST(PoseGraph, GpsOutlierIsGatedAndDoesNotMoveTheMap) {
  Flight f;
  f.duration_s = 60.0;
  f.vo_scale = 1.7;
  f.outlier_at_s = 35.0;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  ASSERT_EQ(r.outliers_injected, 1);
  EXPECT_GE(g.stats().gps_rejected_gate, 1U);
  const Errors e = errors(g, r, 25.0, f.duration_s);
  print("outlier", e, g);
  EXPECT_LE(e.max_m, 0.5);
}

TEST(PoseGraph, RefusesOutOfOrderInputAndStaysUninitialisedWithoutGps) {
  PoseGraph g;
  const Pose3 p{1, 2, 3, 0, 0, 0.5};
  EXPECT_EQ(g.last(), kNoNode);
  EXPECT_EQ(g.add_frame(ag::kNsPerS, 0, p), 0);
  EXPECT_EQ(g.add_frame(ag::kNsPerS, 0, p), kNoNode);      // same stamp
  EXPECT_EQ(g.add_frame(ag::kNsPerS / 2, 0, p), kNoNode);  // earlier
  EXPECT_EQ(g.stats().frames_rejected, 2U);
  EXPECT_EQ(g.stats().frames, 1U);
  EXPECT_TRUE(g.add_gps(ag::kNsPerS, Eigen::Vector3d(5, 5, 40), 0.5));
  EXPECT_FALSE(g.add_gps(ag::kNsPerS, Eigen::Vector3d(5, 5, 40), 0.5));
  EXPECT_FALSE(g.add_gps(ag::kNsPerS - 1, Eigen::Vector3d(5, 5, 40), 0.5));
  EXPECT_EQ(g.stats().gps_rejected_order, 2U);
  EXPECT_EQ(g.stats().gps_fixes, 3U);

  // A whole flight with no GPS: nothing crashes, poses stay finite, never initialised.
  Flight f;
  f.duration_s = 20.0;
  f.gps = false;
  f.vo_scale = 0.8;
  PoseGraph h(f.params);
  const FlightResult r = fly(f, h);
  EXPECT_FALSE(h.initialised());
  EXPECT_FALSE(h.segment_initialised(0));
  EXPECT_EQ(h.size(), r.nodes.size());
  EXPECT_GT(h.size(), 150U);
  for (std::size_t i = 0; i < h.size(); ++i) ASSERT_TRUE(h.pose(static_cast<NodeId>(i)).matrix().allFinite());
  EXPECT_TRUE(h.pose(12345678).isApprox(Eigen::Isometry3d::Identity()));
}

TEST(PoseGraph, WindowBoundsTheSolve) {
  Flight f;
  f.duration_s = 300.5;  // 3000 frames at 10 Hz
  f.vo_scale = 1.3;
  f.params.window_frames = 300;
  PoseGraph g(f.params);
  const FlightResult r = fly(f, g);
  EXPECT_GE(g.size(), 3000U);
  EXPECT_TRUE(g.initialised());
  EXPECT_GT(g.stats().solves, 90U);
  EXPECT_GT(g.stats().last_solve_ms, 0.0);
  EXPECT_EQ(g.stats().last_free_nodes, 300U);
  EXPECT_GE(g.stats().last_iterations, 1U);
  const Errors e = errors(g, r, f.duration_s - 30.0, f.duration_s);
  print("window 300", e, g);
  EXPECT_LE(e.rms_m, 0.3);
  EXPECT_LE(scale_error(g, r, 0), 0.01);
}

}  // namespace
