// Tests of the survey quadrotor and the lawnmower survey generator.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "airground/sim/quadrotor.hpp"
#include "airground/sim/survey.hpp"

namespace ag::sim {
namespace {

constexpr double kDt = 0.02;

TEST(Survey, FootprintAndSpacingFormulas) {
  EXPECT_NEAR(survey_footprint_width(40.0, kPi / 2), 80.0, 1e-9);
  EXPECT_NEAR(survey_line_spacing(40.0, 0.3, kPi / 2), 56.0, 1e-9);
  const double hfov = 2 * std::atan(0.5);  // footprint = altitude
  EXPECT_NEAR(survey_footprint_width(60.0, hfov), 60.0, 1e-9);
  EXPECT_NEAR(survey_line_spacing(60.0, 0.0, hfov), 60.0, 1e-9);
}

TEST(Survey, LinesAreSpacedByTheOverlapAndCoverTheArea) {
  const double alt = 40.0, overlap = 0.25, hfov = 1.2;
  const double width = survey_footprint_width(alt, hfov), spacing = survey_line_spacing(alt, overlap, hfov);
  auto route = survey_lawnmower(-100, -50, 300, 250, alt, overlap, hfov);
  ASSERT_TRUE(route.ok()) << route.error().message;
  const auto& wps = route.value();
  ASSERT_EQ(wps.size() % 2, 0u);
  const std::size_t n = wps.size() / 2;
  EXPECT_EQ(n, static_cast<std::size_t>(std::ceil((300.0 - width) / spacing)) + 1);
  for (std::size_t i = 0; i < n; ++i) {
    const Waypoint& a = wps[2 * i];
    const Waypoint& b = wps[2 * i + 1];
    EXPECT_DOUBLE_EQ(a.y, b.y);  // east-west lines
    EXPECT_DOUBLE_EQ(a.z, alt);
    EXPECT_DOUBLE_EQ(std::min(a.x, b.x), -100.0);
    EXPECT_DOUBLE_EQ(std::max(a.x, b.x), 300.0);
    if (i > 0) {
      EXPECT_NEAR(a.y - wps[2 * i - 2].y, spacing, 1e-9);
      EXPECT_DOUBLE_EQ(a.x, wps[2 * i - 1].x);  // boustrophedon: start where the last line ended
    }
  }
  // Centred: the outer footprints reach equally past both edges.
  EXPECT_NEAR((wps.front().y - width / 2) - (-50.0), 250.0 - (wps.back().y + width / 2), 1e-9);
  // Every point of the area lies under some line's footprint.
  for (double y = -50; y <= 250; y += 0.5) {
    bool covered = false;
    for (std::size_t i = 0; i < n && !covered; ++i) covered = std::abs(y - wps[2 * i].y) <= width / 2 + 1e-9;
    EXPECT_TRUE(covered) << "y=" << y;
  }
  // Neighbouring footprints overlap by the requested fraction.
  EXPECT_NEAR((width - spacing) / width, overlap, 1e-12);
}

TEST(Survey, StartCornerAndDirection) {
  auto sw = survey_lawnmower(0, 0, 200, 200, 40, 0.3, 1.0).value();
  EXPECT_DOUBLE_EQ(sw.front().x, 0.0);
  EXPECT_LT(sw.front().y, 100.0);
  EXPECT_GT(sw.back().y, 100.0);
  SurveyOptions ne;
  ne.start_corner = SurveyCorner::kNorthEast;
  auto r = survey_lawnmower(0, 0, 200, 200, 40, 0.3, 1.0, ne).value();
  EXPECT_DOUBLE_EQ(r.front().x, 200.0);
  EXPECT_GT(r.front().y, 100.0);
  SurveyOptions ns;
  ns.lines_along_x = false;
  ns.start_corner = SurveyCorner::kSouthEast;
  ns.ground_height_m = 12.0;
  ns.speed_mps = 7.0;
  auto v = survey_lawnmower(0, 0, 200, 100, 40, 0.3, 1.0, ns).value();
  EXPECT_DOUBLE_EQ(v[0].x, v[1].x);  // north-south lines
  EXPECT_DOUBLE_EQ(v[0].y, 0.0);     // from the south
  EXPECT_GT(v[0].x, 100.0);          // east side first
  EXPECT_LT(v.back().x, 100.0);
  EXPECT_DOUBLE_EQ(v[0].z, 52.0);
  EXPECT_DOUBLE_EQ(v[0].speed_mps, 7.0);
  // An area narrower than one footprint: a single line down the middle.
  auto one = survey_lawnmower(0, 0, 500, 20, 40, 0.3, 1.0).value();
  ASSERT_EQ(one.size(), 2u);
  EXPECT_DOUBLE_EQ(one[0].y, 10.0);
}

TEST(Survey, RejectsInvalidArguments) {
  EXPECT_FALSE(survey_lawnmower(0, 0, 0, 10, 40, 0.3, 1.0).ok());
  EXPECT_FALSE(survey_lawnmower(0, 10, 10, 0, 40, 0.3, 1.0).ok());
  EXPECT_FALSE(survey_lawnmower(0, 0, 10, 10, 0, 0.3, 1.0).ok());
  EXPECT_FALSE(survey_lawnmower(0, 0, 10, 10, 40, 0.96, 1.0).ok());
  EXPECT_FALSE(survey_lawnmower(0, 0, 10, 10, 40, -0.1, 1.0).ok());
  EXPECT_FALSE(survey_lawnmower(0, 0, 10, 10, 40, 0.3, 0.0).ok());
  EXPECT_FALSE(survey_lawnmower(0, 0, std::nan(""), 10, 40, 0.3, 1.0).ok());
  const auto e = survey_lawnmower(0, 0, 10, 10, 40, 0.99, 1.0);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(e.error().message.find("side_overlap"), std::string::npos);
}

TEST(Quadrotor, FliesTheSurveyWithinLimits) {
  QuadrotorConfig c;
  c.cruise_speed_mps = 6.0;
  Quadrotor uav(c, Pose3{-20, -20, 0, 0, 0, 0});
  auto route = survey_lawnmower(0, 0, 300, 200, 50, 0.3, 1.2).value();
  uav.set_waypoints(route);
  double max_speed = 0, max_dv = 0, max_vz = 0;
  double prev[3] = {0, 0, 0};
  std::size_t last_index = 0;
  std::vector<double> reached_error;
  double max_cross = 0;
  double t = 0;
  while (!uav.finished() && t < 3600) {
    uav.step(kDt);
    t += kDt;
    max_speed = std::max(max_speed, uav.speed());
    max_vz = std::max(max_vz, std::abs(uav.vz()));
    const double dv = std::sqrt((uav.vx() - prev[0]) * (uav.vx() - prev[0]) + (uav.vy() - prev[1]) * (uav.vy() - prev[1]) +
                                (uav.vz() - prev[2]) * (uav.vz() - prev[2]));
    max_dv = std::max(max_dv, dv);
    prev[0] = uav.vx();
    prev[1] = uav.vy();
    prev[2] = uav.vz();
    if (uav.current_waypoint() != last_index) {  // just reached last_index
      const Waypoint& w = route[last_index];
      reached_error.push_back(std::hypot(uav.pose().x - w.x, uav.pose().y - w.y, uav.pose().z - w.z));
      last_index = uav.current_waypoint();
    }
    // On the straight part of a survey line (odd waypoint = line end; 30 m after its start) the track
    // stays on the line.
    const std::size_t k = uav.current_waypoint();
    if (k % 2 == 1 && k < route.size() && std::abs(uav.pose().x - route[k - 1].x) > 30.0)
      max_cross = std::max(max_cross, std::abs(uav.pose().y - route[k].y));
  }
  ASSERT_TRUE(uav.finished()) << "stuck at waypoint " << uav.current_waypoint();
  EXPECT_EQ(reached_error.size(), route.size());
  for (double e : reached_error) EXPECT_LE(e, c.waypoint_tolerance_m + 6.0 * kDt);
  EXPECT_LE(max_speed, c.cruise_speed_mps + 1e-9);
  EXPECT_LE(max_dv, c.max_accel_mps2 * kDt + 1e-9);
  EXPECT_LE(max_vz, c.max_vertical_speed_mps + 1e-9);
  EXPECT_LT(max_cross, 0.1);
  // The lines are flown at cruise speed: total time not far above distance / speed.
  EXPECT_LT(t, 1.3 * uav.distance_flown() / c.cruise_speed_mps + 60.0);
  // Then it hovers where it ended.
  const Pose3 end = uav.pose();
  for (int i = 0; i < 500; ++i) uav.step(kDt);
  EXPECT_NEAR(uav.pose().x, end.x, 3.0);
  EXPECT_LT(uav.speed(), 0.05);
}

// The ground robots wait for the survey's regions until its estimated end: the estimate must be close to
// the flight, for a survey with its climb and its return to launch, at two speeds, and for short legs.
TEST(Quadrotor, RouteTimeEstimateMatchesTheFlight) {
  for (const double speed : {5.0, 9.0}) {
    QuadrotorConfig c;
    c.cruise_speed_mps = speed;
    const Pose3 start{-20, -20, 0, 0, 0, 0};
    auto route = survey_lawnmower(0, 0, 300, 200, 60, 0.6, 1.2).value();
    route.push_back(Waypoint{start.x, start.y, route.back().z, 0});  // back over the launch point
    route.push_back(Waypoint{start.x + 4, start.y, route.back().z, 0});  // a short leg (no cruise)
    Quadrotor uav(c, start);
    uav.set_waypoints(route);
    double t = 0;
    while (!uav.finished() && t < 7200) {
      uav.step(kDt);
      t += kDt;
    }
    ASSERT_TRUE(uav.finished());
    const double est = estimate_route_time_s(c, start, route);
    EXPECT_NEAR(est, t, 0.03 * t) << "speed " << speed << ": flown in " << t << " s, estimated " << est << " s";
    EXPECT_GT(t, uav.distance_flown() / speed) << "the estimate is not just distance / speed";
  }
}

TEST(Quadrotor, WaypointSpeedIsCappedAndYawFollowsMotion) {
  QuadrotorConfig c;
  c.cruise_speed_mps = 5.0;
  c.max_speed_mps = 8.0;
  Quadrotor uav(c, Pose3{0, 0, 40, 0, 0, 0});
  uav.set_waypoints({Waypoint{0, 500, 40, 20.0}});  // asks for 20 m/s
  double max_speed = 0;
  bool leaned = false;
  for (int i = 0; i < 1500; ++i) {
    uav.step(kDt);
    max_speed = std::max(max_speed, uav.speed());
    if (i == 10) {
      // Accelerating north with the nose turning north: leaning forward is positive pitch.
      leaned = uav.pose().pitch > 0.05 || std::abs(uav.pose().roll) > 0.05;
    }
  }
  EXPECT_NEAR(max_speed, 8.0, 1e-9);
  EXPECT_TRUE(leaned);
  EXPECT_NEAR(uav.pose().yaw, kPi / 2, 1e-6);  // heading north
  EXPECT_NEAR(uav.pose().pitch, 0.0, 1e-9);    // constant speed: level
  EXPECT_NEAR(uav.pose().z, 40.0, 1e-9);
}

TEST(Quadrotor, FixedYawAndClimbLimit) {
  QuadrotorConfig c;
  c.yaw_mode = YawMode::kFixed;
  c.fixed_yaw_rad = 1.0;
  c.max_vertical_speed_mps = 2.0;
  Quadrotor uav(c, Pose3{0, 0, 0, 0, 0, 0});
  uav.set_waypoints({Waypoint{0, 0, 60, 0}, Waypoint{100, 0, 60, 0}});
  double max_vz = 0;
  for (int i = 0; i < 5000 && !uav.finished(); ++i) {
    uav.step(kDt);
    max_vz = std::max(max_vz, std::abs(uav.vz()));
  }
  EXPECT_TRUE(uav.finished());
  EXPECT_NEAR(max_vz, 2.0, 1e-9);
  EXPECT_NEAR(uav.pose().yaw, 1.0, 1e-9);
}

TEST(QuadrotorConfigYaml, LoadsAndValidatesEveryKey) {
  auto ok = load_quadrotor_config("cruise_speed_mps: 8\nyaw_mode: fixed\nfixed_yaw_rad: 0.5\n", "uav.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_DOUBLE_EQ(ok->cruise_speed_mps, 8.0);
  EXPECT_EQ(ok->yaw_mode, YawMode::kFixed);
  auto order = load_quadrotor_config("cruise_speed_mps: 20\nmax_speed_mps: 10\n", "uav.yaml");
  ASSERT_FALSE(order.ok());
  EXPECT_NE(order.error().message.find("cruise_speed_mps"), std::string::npos);
  auto mode = load_quadrotor_config("yaw_mode: spin\n", "uav.yaml");
  ASSERT_FALSE(mode.ok());
  EXPECT_NE(mode.error().message.find("motion|fixed"), std::string::npos);
  auto range = load_quadrotor_config("max_accel_mps2: 50\n", "uav.yaml");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.error().message.find("[0.1, 20] m/s^2"), std::string::npos) << range.error().message;
}

}  // namespace
}  // namespace ag::sim
