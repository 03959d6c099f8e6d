// The particle filter on synthetic worlds: convergence from 16 m / 30 deg and tracking, geometric labels,
// a partial aerial map, standing still with a drifting yaw, divergence and recovery (also standing), the cost formula
// against a hand computation, the adaptive particle count, no update while standing, determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/localization/semantic_localizer.hpp"
#include "scenario.hpp"

namespace ag::loc {
namespace {

using test::LidarModel;
using test::OdometryNoise;
using test::ScenarioResult;
using test::SyntheticWorld;
using test::TruthSample;

constexpr double kDeg = kPi / 180.0;

// 16 m off (towards `dir`) and 30 deg off: the initial error.
Pose2 bad_guess(const Pose2& truth, double dir = 0.7) {
  return Pose2{truth.x + 16.0 * std::cos(dir), truth.y + 16.0 * std::sin(dir), wrap_angle(truth.yaw + 30.0 * kDeg)};
}

struct World {
  SyntheticWorld w;
  std::vector<TruthSample> truth;
  std::vector<Pose2> odom;
  explicit World(std::uint64_t seed, int rows = 2, const OdometryNoise& noise = {}) : w(test::make_world(10, 10, seed)) {
    const auto route = test::snake_route(w, test::kSlowTarget ? 1 : rows);
    truth = test::drive_route(w, route);
    odom = test::odometry(truth, noise, seed + 5);
  }
};

ScenarioResult run(const World& world, const LocalizationChannels& ch, ScanLabeller& labeller, const SyntheticWorld& aerial,
                   std::uint64_t seed, double dir = 0.7, LocalizerParams p = {}) {
  ClassDistanceFields fields(DistanceFieldParams{}, ch, aerial.extent());
  test::load_world(aerial, fields);
  SemanticLocalizer loc(p, ch, seed);
  const Pose2 t0 = world.truth[0].pose;
  loc.initialise_disc(bad_guess(t0, dir), 20.0, 35.0 * kDeg, world.truth[0].stamp);
  return test::run_scenario(loc, world.w, fields, world.truth, world.odom, labeller, LidarModel{}, seed);
}

// Step k of the world's drive: its odometry, and a labelled scan from the true pose when the filter wants one.
void drive_step(SemanticLocalizer& loc, const World& world, const ClassDistanceFields& fields, ScanLabeller& labeller, std::size_t k,
                std::vector<ScanPoint>& scan) {
  loc.on_odometry(world.odom[k], world.truth[k].stamp);
  if (!loc.wants_scan(fields)) return;
  test::ray_cast(world.w, world.truth[k].pose, LidarModel{}, k, scan);
  labeller.label(scan, LidarModel{}.rings, LidarModel{}.columns);
  loc.on_scan(scan, fields, world.truth[k].stamp);
}

// The robot stands where step k - 1 left it for up to `seconds`, with 10 Hz odometry and scans as the stage
// gets them: the seconds until the filter tracks, or -1; *err_m then its distance from the truth.
double stand_until_tracking(SemanticLocalizer& loc, const World& world, const ClassDistanceFields& fields, ScanLabeller& labeller,
                            std::size_t k, double seconds, double* err_m) {
  const TruthSample at = world.truth[k - 1];
  std::vector<ScanPoint> scan;
  for (int i = 1; i <= static_cast<int>(seconds * 10.0); ++i) {
    const TimeNs t = at.stamp + from_seconds(i / 10.0);
    loc.on_odometry(world.odom[k - 1], t);
    if (loc.wants_scan(fields)) {
      test::ray_cast(world.w, at.pose, LidarModel{}, k + static_cast<std::size_t>(i), scan);
      labeller.label(scan, LidarModel{}.rings, LidarModel{}.columns);
      loc.on_scan(scan, fields, t);
    }
    if (loc.pose().status == LocalizationStatus::kTracking) {
      *err_m = std::hypot(loc.pose().pose.x - at.pose.x, loc.pose().pose.y - at.pose.y);
      return i / 10.0;
    }
  }
  return -1.0;
}

TEST(ParticleFilter, ConvergesFrom16mAnd30DegreesAndTracks) {
  const World world(2);
  GroundTruthLabeller gt;
  for (const double dir : {0.7, 3.5}) {
    const ScenarioResult r = run(world, LocalizationChannels::per_class(), gt, world.w, 11, dir);
    test::print("ground-truth labels, full map", r);
    ASSERT_TRUE(r.converged);
    EXPECT_LE(r.convergence_time_s, 60.0);
    EXPECT_LE(r.mean_err_m, 1.5);
    EXPECT_LE(r.p95_err_m, 3.0);
    EXPECT_LE(r.yaw_mean_deg, 2.0);
    EXPECT_EQ(r.lost_samples, 0U);
    EXPECT_LT(r.mean_err_m, r.odom_mean_err_m / 3.0) << "the map must beat the odometry alone";
    EXPECT_GT(r.tracking_samples, world.truth.size() * 8 / 10);
  }
}

TEST(ParticleFilter, ConvergesWithTheGeometricTwoClassLabelling) {
  const World world(3);
  GeometricLabeller geometric(GeometricLabelParams{}, 64, 1024);
  const ScenarioResult r = run(world, LocalizationChannels::two_class(), geometric, world.w, 12);
  test::print("geometric labels, full map", r);
  ASSERT_TRUE(r.converged);
  EXPECT_LE(r.convergence_time_s, 60.0);
  EXPECT_LE(r.mean_err_m, 1.5);  // the issue asks <= 3 m
  EXPECT_LE(r.p95_err_m, 3.0);
  EXPECT_LE(r.yaw_mean_deg, 2.0);
}

TEST(ParticleFilter, TracksOnAPartialMapWithUnknownCells) {
  const World world(1);
  SyntheticWorld aerial = world.w;  // the quadrotor has seen only part of the area
  test::TestRng rng(78);
  for (int i = 0; i < 130; ++i) {
    const double x = rng.uniform(0, 320), y = rng.uniform(0, 320);
    aerial.fill_rect(x, y, x + rng.uniform(10, 30), y + rng.uniform(10, 30), ClassId::kUnknown, 0.0F);
  }
  std::size_t unknown = 0;
  for (const std::uint8_t c : aerial.cls) unknown += c == 255 ? 1U : 0U;
  const double share = static_cast<double>(unknown) / static_cast<double>(aerial.cls.size());
  ASSERT_GT(share, 0.3);
  GroundTruthLabeller gt;
  const ScenarioResult r = run(world, LocalizationChannels::per_class(), gt, aerial, 13);
  std::printf("unknown share of the aerial map: %.2f\n", share);
  test::print("ground-truth labels, partial map", r);
  ASSERT_TRUE(r.converged);
  EXPECT_LE(r.convergence_time_s, 60.0);
  EXPECT_LE(r.mean_err_m, 1.5);
  EXPECT_LE(r.p95_err_m, 3.0);
}

// The quadrotor has mapped nothing west of the mission area's edge, 6 m west of the robot, and the guess
// straddles the edge. A particle over unmapped ground scores neutral, which beats a poor match on the
// map, so without the area the unmapped half of the guess keeps about half the weight, where the robot
// cannot be (on an imported world whose staging pose is 5 m from its edge the filter settled out there).
// With the area (the stage's area_*) a particle outside has no weight: only the uniform mix is left.
TEST(ParticleFilter, ParticlesOutsideTheMissionAreaHaveNoWeight) {
  SyntheticWorld w = test::make_world(8, 8, 7);
  const Pose2 truth{w.road_x[3], w.road_y[3] + 4.0, 0.3};
  const double edge = truth.x - 6.0;
  SyntheticWorld aerial = w;
  aerial.fill_rect(0, 0, edge, 8 * 32.0, ClassId::kUnknown, 0.0F);
  const LocalizationChannels ch = LocalizationChannels::two_class();  // the shipped labelling
  ClassDistanceFields fields(DistanceFieldParams{}, ch, aerial.extent());
  test::load_world(aerial, fields);
  std::vector<ScanPoint> scan;
  test::ray_cast(w, truth, LidarModel{}, 3, scan);
  GeometricLabeller(GeometricLabelParams{}, 64, 1024).label(scan, LidarModel{}.rings, LidarModel{}.columns);
  double share[2] = {0, 0};
  for (const bool with_area : {false, true}) {
    ParticleFilterParams p;
    if (with_area) p.area = {edge, 0.0, 8 * 32.0, 8 * 32.0};
    ParticleFilter filter(p, PolarRenderParams{}, 5);
    filter.initialise_gaussian(Pose2{edge, truth.y, truth.yaw}, 8.0, 0.3);
    ScanRenderPolar render(PolarRenderParams{}, ch);
    render.render(scan, filter.range_bin_m());
    ASSERT_TRUE(filter.update(render, fields, true).updated);
    double outside = 0, total = 0;
    for (std::size_t i = 0; i < filter.size(); ++i) {
      total += filter.weight(i);
      if (filter.particle(i).x < edge) outside += filter.weight(i);
    }
    share[with_area ? 1 : 0] = outside / total;
    if (with_area) {
      EXPECT_GT(filter.estimate().outside_area, filter.size() / 4) << "about half the guess lay outside";
    }
  }
  std::printf("weight outside the mission area after one update: %.3f without the area, %.3f with it\n", share[0], share[1]);
  EXPECT_GT(share[0], 0.3) << "what the area removes";
  EXPECT_LT(share[1], 0.05) << "only the uniform mix (1 %) and what resampling drew from it";
}

TEST(ParticleFilter, StandingStillWithADriftingYawDoesNotDiverge) {
  // Drive a block, stand 5 minutes while the odometry's yaw drifts 0.002 rad/s (34 deg), drive on.
  SyntheticWorld w = test::make_world(10, 10, 4);
  const auto route = test::snake_route(w, test::kSlowTarget ? 1 : 2);
  const std::vector<TruthSample> drive = test::drive_route(w, route);
  const std::size_t stop = drive.size() / 3;
  std::vector<TruthSample> truth(drive.begin(), drive.begin() + static_cast<std::ptrdiff_t>(stop));
  test::stand(truth, 300.0);
  const std::size_t stand_end = truth.size();
  const TimeNs shift = truth.back().stamp - drive[stop - 1].stamp;
  for (std::size_t k = stop; k < drive.size(); ++k) truth.push_back({drive[k].stamp + shift, drive[k].pose});
  OdometryNoise noise;
  noise.yaw_drift_at_rest_rad_per_s = 0.002;
  const std::vector<Pose2> odom = test::odometry(truth, noise, 9);
  const double odom_yaw_drift = wrap_angle(odom[stand_end - 1].yaw - odom[stop - 1].yaw);
  ASSERT_NEAR(odom_yaw_drift, 0.6, 0.01) << "the odometry did drift";

  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields fields(DistanceFieldParams{}, ch, w.extent());
  test::load_world(w, fields);
  SemanticLocalizer loc(LocalizerParams{}, ch, 21);
  loc.initialise_disc(bad_guess(truth[0].pose), 20.0, 35.0 * kDeg, truth[0].stamp);
  GroundTruthLabeller gt;
  const ScenarioResult r = test::run_scenario(loc, w, fields, truth, odom, gt, LidarModel{}, 21);
  test::print("stand 5 min with yaw drift", r);
  ASSERT_TRUE(r.converged);
  EXPECT_EQ(r.lost_samples, 0U);
  EXPECT_EQ(r.recoveries, 0U);
  EXPECT_LE(r.mean_err_m, 1.5);
  EXPECT_LE(r.max_err_m, 3.0);
  EXPECT_GT(loc.gate().dropped_yaw_rad(), 0.55) << "the drift at rest was dropped";
  // The published pose did not turn while the robot stood, and is right after it drove on.
  double max_err_after = 0.0;
  for (std::size_t k = stand_end; k < truth.size(); ++k) max_err_after = std::max(max_err_after, r.err[k]);
  EXPECT_LE(max_err_after, 3.0);
}

TEST(ParticleFilter, StandingStillPublishesAFixedYaw) {
  // The same drift, and the published yaw while standing: the gate keeps it still.
  SyntheticWorld w = test::make_world(10, 10, 5);
  const auto route = test::snake_route(w, 1);
  std::vector<TruthSample> truth = test::drive_route(w, route);
  truth.resize(truth.size() / 2);
  const std::size_t stop = truth.size();
  test::stand(truth, 120.0);
  OdometryNoise noise;
  noise.yaw_drift_at_rest_rad_per_s = 0.002;
  const std::vector<Pose2> odom = test::odometry(truth, noise, 3);
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields fields(DistanceFieldParams{}, ch, w.extent());
  test::load_world(w, fields);
  for (const bool gated : {true, false}) {
    LocalizerParams p;
    if (!gated) p.gate.standstill_speed_mps = p.gate.standstill_yaw_rate_rad_s = 0.0;  // every increment is motion
    SemanticLocalizer loc(p, ch, 5);
    loc.initialise_gaussian(truth[0].pose, 1.0, 2.0 * kDeg, truth[0].stamp);
    GroundTruthLabeller gt;
    std::vector<ScanPoint> scan;
    double yaw_at_stop = 0.0, max_turn = 0.0;
    for (std::size_t k = 0; k < truth.size(); ++k) {
      loc.on_odometry(odom[k], truth[k].stamp);
      if (loc.wants_scan(fields)) {
        test::ray_cast(w, truth[k].pose, LidarModel{}, k, scan);
        gt.label(scan, LidarModel{}.rings, LidarModel{}.columns);
        loc.on_scan(scan, fields, truth[k].stamp);
      }
      if (k == stop + 50) yaw_at_stop = loc.pose().pose.yaw;  // 5 s after stopping: any easing is over
      if (k > stop + 50) max_turn = std::max(max_turn, std::fabs(wrap_angle(loc.pose().pose.yaw - yaw_at_stop)));
    }
    std::printf("%s: the published yaw turned by up to %.2f deg while standing\n", gated ? "gated" : "not gated", max_turn / kDeg);
    if (gated) {
      EXPECT_LT(max_turn, 0.2 * kDeg);
    } else {
      EXPECT_GT(max_turn, 2.0 * kDeg) << "without the gate the drift shows: the test can fail";
    }
  }
}

TEST(ParticleFilter, DivergenceIsDetectedAndRecovered) {
  World world(6);
  // The odometry jumps 20 m sideways and 25 deg (a slipping wheel, a bad loop closure) a third of the way.
  const std::size_t jump_at = world.truth.size() / 3;
  for (std::size_t k = jump_at; k < world.odom.size(); ++k)
    world.odom[k] = compose(Pose2{world.odom[jump_at - 1].x, world.odom[jump_at - 1].y, world.odom[jump_at - 1].yaw},
                            compose(Pose2{0.0, 20.0, 25.0 * kDeg}, between(world.odom[jump_at - 1], world.odom[k])));
  GroundTruthLabeller gt;
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields fields(DistanceFieldParams{}, ch, world.w.extent());
  test::load_world(world.w, fields);
  SemanticLocalizer loc(LocalizerParams{}, ch, 31);
  loc.initialise_disc(bad_guess(world.truth[0].pose), 20.0, 35.0 * kDeg, world.truth[0].stamp);
  const ScenarioResult r = test::run_scenario(loc, world.w, fields, world.truth, world.odom, gt, LidarModel{}, 31);
  test::print("odometry jump", r);
  ASSERT_TRUE(r.converged);
  EXPECT_GE(r.recoveries, 1U);
  EXPECT_GT(r.lost_samples, 0U);
  // lost soon after the jump, tracking again within 60 s, and right at the end
  std::size_t first_lost = 0, back = 0;
  for (std::size_t k = jump_at; k < r.status.size(); ++k)
    if (r.status[k] == LocalizationStatus::kLost) {
      first_lost = k;
      break;
    }
  ASSERT_GT(first_lost, 0U);
  EXPECT_LT(first_lost - jump_at, 100U) << "detected within 10 s";
  for (std::size_t k = first_lost; k < r.status.size(); ++k)
    if (r.status[k] == LocalizationStatus::kTracking) {
      back = k;
      break;
    }
  ASSERT_GT(back, 0U);
  EXPECT_LT(back - first_lost, 600U) << "recovered within 60 s";
  double err_end = 0.0;
  for (std::size_t k = r.err.size() - 300; k < r.err.size(); ++k) err_end = std::max(err_end, r.err[k]);
  EXPECT_LT(err_end, 1.5);
  EXPECT_EQ(loc.pose().status, LocalizationStatus::kTracking);
}

// A robot that loses track stops (the drive stage halts without a tracking pose) and so would never move
// again to give the filter an update: lost and standing, a scan is matched every lost_standing_update_s
// anyway, so the re-spreads around the last good pose go on until it is tracking again, where it stands.
// The study's 3-robot missions had a robot stand lost in this way from 312 s to the 5400 s cap.
TEST(ParticleFilter, ALostRobotThatStopsIsMatchedAgainWhereItStands) {
  struct Outcome {
    bool lost{false}, back{false};
    double back_after_s{-1}, err_m{-1};
  };
  auto run_lost_then_stand = [](double standing_update_s) {
    World world(6);
    // The odometry jumps 20 m sideways and 25 deg a third of the way (as in the test above): tracking is lost.
    const std::size_t jump_at = world.truth.size() / 3;
    for (std::size_t k = jump_at; k < world.odom.size(); ++k)
      world.odom[k] = compose(world.odom[jump_at - 1], compose(Pose2{0.0, 20.0, 25.0 * kDeg}, between(world.odom[jump_at - 1], world.odom[k])));
    GroundTruthLabeller gt;
    const LocalizationChannels ch = LocalizationChannels::per_class();
    ClassDistanceFields fields(DistanceFieldParams{}, ch, world.w.extent());
    test::load_world(world.w, fields);
    LocalizerParams p;
    p.filter.lost_standing_update_s = standing_update_s;
    SemanticLocalizer loc(p, ch, 31);
    loc.initialise_gaussian(world.truth[0].pose, 1.0, 2.0 * kDeg, world.truth[0].stamp);
    std::vector<ScanPoint> scan;
    Outcome out;
    std::size_t k = 0;
    for (; k < world.truth.size() && !out.lost; ++k) {  // drive until it is lost ...
      drive_step(loc, world, fields, gt, k, scan);
      out.lost = k > jump_at && loc.pose().status == LocalizationStatus::kLost;
    }
    if (!out.lost) return out;
    out.back_after_s = stand_until_tracking(loc, world, fields, gt, k, 180.0, &out.err_m);  // ... then stand there for 180 s
    out.back = out.back_after_s >= 0.0;
    return out;
  };
  const Outcome with = run_lost_then_stand(ParticleFilterParams{}.lost_standing_update_s);
  std::printf("lost and standing: tracking again after %.1f s, %.2f m from the truth\n", with.back_after_s, with.err_m);
  ASSERT_TRUE(with.lost) << "the odometry jump must lose track while driving";
  ASSERT_TRUE(with.back) << "still lost after 180 s of standing";
  EXPECT_LT(with.back_after_s, 120.0);
  EXPECT_LT(with.err_m, 1.5);
  const Outcome without = run_lost_then_stand(0.0);  // matched only after motion: lost for good
  ASSERT_TRUE(without.lost);
  EXPECT_FALSE(without.back) << "without the standing updates nothing can bring it back: the test can fail";
}

// A robot that reaches its goal on the estimate of a filter that is still converging stops there:
// standing updates as when lost, once it has driven pf_converging_standing_after_m; on the start pad
// (nothing driven yet) none, as before. The HIL mission's first waypoint ended like this (18 m driven on
// a sparse map); here the robot stops after 2 m (the threshold set to 1.5 m), before it converged.
TEST(ParticleFilter, ARobotThatStopsBeforeItConvergedConvergesWhereItStands) {
  auto run = [](double after_m, bool& stopped_converging) {
    const World world(2);
    GeometricLabeller gt(GeometricLabelParams{}, 64, 1024);  // the shipped ground robot's labeller
    const LocalizationChannels ch = LocalizationChannels::two_class();
    ClassDistanceFields fields(DistanceFieldParams{}, ch, world.w.extent());
    test::load_world(world.w, fields);
    LocalizerParams p;
    p.filter.converging_standing_after_m = after_m;
    SemanticLocalizer loc(p, ch, 11);
    loc.initialise_disc(bad_guess(world.truth[0].pose), 20.0, 35.0 * kDeg, world.truth[0].stamp);
    std::vector<ScanPoint> scan;
    std::size_t k = 0;
    for (; k < world.truth.size() && loc.filter().driven_m() < 2.0; ++k) drive_step(loc, world, fields, gt, k, scan);
    stopped_converging = loc.pose().status == LocalizationStatus::kInitialising;
    double err = -1.0;
    stand_until_tracking(loc, world, fields, gt, k, 120.0, &err);
    return err;  // -1: still converging after 120 s of standing
  };
  bool converging = false;
  const double err = run(1.5, converging);
  ASSERT_TRUE(converging) << "not converged after 2 m: the case under test";
  std::printf("stopped after 2 m still converging: tracking where it stands, %.2f m from the truth\n", err);
  ASSERT_GE(err, 0.0) << "still converging after 120 s of standing";
  EXPECT_LT(err, 1.5);
  EXPECT_LT(run(1e6, converging), 0.0) << "without the standing updates it never converges there: the test can fail";
}

// The cost of a pose by hand: every bin's centre in the map by trigonometry, distances and classes by
// the fields' accessors, bins on unknown cells left out.
double hand_cost(const Pose2& p, const ScanRenderPolar& r, const ClassDistanceFields& f, double* known_fraction) {
  double sum = 0.0, known = 0.0;
  for (const ScanRenderPolar::Bin& b : r.bins()) {
    const double a = p.yaw + (b.angle + 0.5) * r.angle_bin_rad(), rr = (b.range + 0.5) * r.range_bin_m();
    const double x = p.x + rr * std::cos(a), y = p.y + rr * std::sin(a);
    if (f.class_at(x, y) == 255) continue;
    known += static_cast<double>(b.weight);
    for (std::uint32_t k = 0; k < b.entries; ++k) {
      const ScanRenderPolar::Entry& e = r.entries()[b.first + k];
      sum += static_cast<double>(e.value) * f.distance_m(x, y, static_cast<int>(e.channel));
    }
  }
  *known_fraction = known / r.total_weight();
  return known > 0.0 ? sum / known : 0.0;
}

TEST(ParticleFilter, CostOfAPoseIsTheFormulaAndLeavesUnknownCellsOut) {
  SyntheticWorld w = test::make_world(8, 8, 7);
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields fields(DistanceFieldParams{}, ch, w.extent());
  test::load_world(w, fields);
  const Pose2 truth{w.road_x[1] + 1.3, w.road_y[1] - 7.1, 0.4};
  std::vector<ScanPoint> scan;
  test::ray_cast(w, truth, LidarModel{}, 3, scan);
  ScanRenderPolar render(PolarRenderParams{}, ch);
  render.render(scan, 2.0);
  ParticleFilter filter(ParticleFilterParams{}, PolarRenderParams{}, 1);
  for (const Pose2& p : {truth, Pose2{truth.x + 3.0, truth.y - 2.0, truth.yaw + 0.1}, Pose2{truth.x, truth.y, truth.yaw + 0.3}}) {
    double kf = 0.0, kf_hand = 0.0;
    const double c = filter.pose_cost(p, render, fields, &kf);
    const double want = hand_cost(p, render, fields, &kf_hand);
    EXPECT_NEAR(c, want, 0.02 * want + 1e-3);
    EXPECT_NEAR(kf, kf_hand, 0.01);
    EXPECT_NEAR(kf, 1.0, 1e-9);
  }
  const double at_truth = filter.pose_cost(truth, render, fields);  // not 0: bin centres are not the points
  EXPECT_LT(at_truth, 0.3);
  EXPECT_GT(filter.pose_cost(Pose2{truth.x + 3.0, truth.y - 2.0, truth.yaw}, render, fields), 3.0 * at_truth);
  EXPECT_GT(filter.pose_cost(Pose2{truth.x, truth.y, truth.yaw + 0.3}, render, fields), 3.0 * at_truth);

  // Half the area becomes unknown: the bins there drop out of the cost and of the known share.
  for (int ty = 0; ty < w.tiles_y(); ++ty)
    for (int tx = 0; tx < w.tiles_x(); ++tx) {
      const double cx = (tx + 0.5) * 32.0;
      if (cx < truth.x) fields.set_tile(tx, ty, 2, std::vector<std::uint8_t>(64 * 64, 255));
    }
  fields.update();
  double kf = 0.0, kf_hand = 0.0;
  const Pose2 off{truth.x + 3.0, truth.y - 2.0, truth.yaw + 0.1};
  const double c = filter.pose_cost(off, render, fields, &kf);
  const double want = hand_cost(off, render, fields, &kf_hand);
  EXPECT_NEAR(c, want, 0.02 * want + 1e-3);
  EXPECT_NEAR(kf, kf_hand, 0.01);
  EXPECT_GT(kf, 0.1);
  EXPECT_LT(kf, 0.9);
}

TEST(ParticleFilter, ParticleCountAdaptsBetweenMinAndMax) {
  const World world(2, 1);
  GroundTruthLabeller gt;
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields fields(DistanceFieldParams{}, ch, world.w.extent());
  test::load_world(world.w, fields);
  LocalizerParams p;
  SemanticLocalizer loc(p, ch, 41);
  loc.initialise_disc(bad_guess(world.truth[0].pose), 20.0, 35.0 * kDeg, world.truth[0].stamp);
  EXPECT_EQ(loc.filter().size(), static_cast<std::size_t>(p.filter.max_particles));
  std::vector<ScanPoint> scan;
  std::size_t smallest = loc.filter().size();
  for (std::size_t k = 0; k < world.truth.size(); ++k) {
    loc.on_odometry(world.odom[k], world.truth[k].stamp);
    if (!loc.wants_scan(fields)) continue;
    test::ray_cast(world.w, world.truth[k].pose, LidarModel{}, k, scan);
    gt.label(scan, LidarModel{}.rings, LidarModel{}.columns);
    loc.on_scan(scan, fields, world.truth[k].stamp);
    smallest = std::min(smallest, loc.filter().size());
    EXPECT_GE(loc.filter().size(), static_cast<std::size_t>(p.filter.min_particles));
    EXPECT_LE(loc.filter().size(), static_cast<std::size_t>(p.filter.max_particles));
  }
  std::printf("particles: %d at the start, %zu at the fewest\n", p.filter.max_particles, smallest);
  EXPECT_LE(smallest, static_cast<std::size_t>(p.filter.max_particles) / 4);
  EXPECT_EQ(loc.filter().status(), FilterStatus::kTracking);
  // the render followed the spread: the smallest range bins once converged
  EXPECT_NEAR(loc.filter().range_bin_m(), p.filter.range_bin_min_m, 0.5);
}

TEST(ParticleFilter, NoUpdateAndNoNoiseWhileStandingStill) {
  SyntheticWorld w = test::make_world(6, 6, 8);
  const LocalizationChannels ch = LocalizationChannels::per_class();
  ClassDistanceFields fields(DistanceFieldParams{}, ch, w.extent());
  test::load_world(w, fields);
  const Pose2 truth{w.road_x[1], w.road_y[1], 0.2};
  std::vector<ScanPoint> scan;
  test::ray_cast(w, truth, LidarModel{}, 1, scan);
  SemanticLocalizer loc(LocalizerParams{}, ch, 3);
  loc.on_odometry(Pose2{}, 0);
  loc.initialise_gaussian(truth, 2.0, 0.05, 0);
  EXPECT_TRUE(loc.wants_scan(fields)) << "one update at the start";
  EXPECT_TRUE(loc.on_scan(scan, fields, 0).updated);
  std::vector<Pose2> before;
  for (std::size_t i = 0; i < loc.filter().size(); ++i) before.push_back(loc.filter().particle(i));
  // 60 s of standing, with a drifting yaw
  for (int k = 1; k <= 600; ++k) {
    loc.on_odometry(Pose2{0.0, 0.0, 0.001 * k / 10.0}, from_seconds(k / 10.0));
    EXPECT_FALSE(loc.wants_scan(fields));
    EXPECT_FALSE(loc.on_scan(scan, fields, from_seconds(k / 10.0)).updated);
  }
  ASSERT_EQ(before.size(), loc.filter().size());
  for (std::size_t i = 0; i < before.size(); ++i) {
    EXPECT_EQ(before[i].x, loc.filter().particle(i).x);
    EXPECT_EQ(before[i].yaw, loc.filter().particle(i).yaw);
  }
  // a real turn in place is motion
  for (int k = 1; k <= 10; ++k) loc.on_odometry(Pose2{0.0, 0.0, 0.06 + 0.03 * k}, from_seconds(60.0 + k / 10.0));
  EXPECT_TRUE(loc.wants_scan(fields));
  // the channel's message
  LocalizationMsg m;
  loc.fill(m);
  EXPECT_EQ(m.stamp, from_seconds(61.0));
  EXPECT_EQ(m.status, LocalizationStatus::kInitialising);  // one update: not converged yet
  EXPECT_EQ(m.updates, 1U);
  EXPECT_EQ(m.particles, static_cast<std::uint32_t>(loc.filter().size()));
  EXPECT_NEAR(m.pose.yaw, wrap_angle(truth.yaw + 0.3), 0.1);  // the turn, from the filter's estimate
  EXPECT_GT(m.covariance[0], 0.0);
}

TEST(ParticleFilter, DeterministicForASeed) {
  const World world(2, 1);
  auto final_particles = [&](std::uint64_t seed) {
    const LocalizationChannels ch = LocalizationChannels::per_class();
    ClassDistanceFields fields(DistanceFieldParams{}, ch, world.w.extent());
    test::load_world(world.w, fields);
    SemanticLocalizer loc(LocalizerParams{}, ch, seed);
    loc.initialise_disc(bad_guess(world.truth[0].pose), 20.0, 35.0 * kDeg, world.truth[0].stamp);
    GroundTruthLabeller gt;
    std::vector<ScanPoint> scan;
    for (std::size_t k = 0; k < 400; ++k) {
      loc.on_odometry(world.odom[k], world.truth[k].stamp);
      if (!loc.wants_scan(fields)) continue;
      test::ray_cast(world.w, world.truth[k].pose, LidarModel{}, k, scan);
      gt.label(scan, LidarModel{}.rings, LidarModel{}.columns);
      loc.on_scan(scan, fields, world.truth[k].stamp);
    }
    std::vector<double> out;
    for (std::size_t i = 0; i < loc.filter().size(); ++i) {
      const Pose2 q = loc.filter().particle(i);
      out.insert(out.end(), {q.x, q.y, q.yaw, loc.filter().weight(i)});
    }
    return out;
  };
  const std::vector<double> a = final_particles(5), b = final_particles(5), c = final_particles(6);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
}

}  // namespace
}  // namespace ag::loc
