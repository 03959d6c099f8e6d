// The scripted drivers' pure pursuit: it follows a path to its end, including one that doubles back on
// itself at a dead end (where it once turned in place for ever).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "airground/sim/scripted_driver.hpp"

namespace ag::sim {
namespace {

// Drives a unicycle with the pursuit's commands at 50 Hz; returns the steps until done (or the cap).
int drive(PurePursuit& pp, Pose2 pose, int max_steps, double& turned) {
  constexpr double dt = 0.02;
  turned = 0;
  for (int k = 0; k < max_steps; ++k) {
    if (pp.done()) return k;
    double v = 0, w = 0;
    pp.command(pose, v, w);
    pose.x += v * dt * std::cos(pose.yaw);
    pose.y += v * dt * std::sin(pose.yaw);
    pose.yaw = wrap_angle(pose.yaw + w * dt);
    turned += std::abs(w) * dt;
  }
  return max_steps;
}

std::vector<Eigen::Vector2d> line(Eigen::Vector2d a, Eigen::Vector2d b) {  // 1 m points, b excluded
  std::vector<Eigen::Vector2d> out;
  const double n = std::ceil((b - a).norm());
  for (int i = 0; i < static_cast<int>(n); ++i) out.push_back(a + (b - a) * (i / n));
  return out;
}

TEST(Pursuit, FollowsAnLShapedPathToItsEnd) {
  std::vector<Eigen::Vector2d> path = line({0, 0}, {20, 0});
  for (const auto& p : line({20, 0}, {20, 20})) path.push_back(p);
  path.emplace_back(20, 20);
  PurePursuit pp(PursuitParams{});
  pp.set_path(path);
  double turned = 0;
  const int steps = drive(pp, Pose2{0, 0, 0}, 50 * 120, turned);
  EXPECT_TRUE(pp.done());
  EXPECT_LT(steps, 50 * 60) << "40 m at 1.2 m/s";
  EXPECT_LT(turned, 3.0) << "one 90 deg turn and small corrections";
}

TEST(Pursuit, TurnsBackAtADeadEndAndFinishesTheWayBack) {
  // Out 15 m and back along the same line (an out-and-back road loop ends like this at a dead end).
  std::vector<Eigen::Vector2d> path = line({0, 0}, {15, 0});
  for (const auto& p : line({15, 0}, {0, 0})) path.push_back(p);
  path.emplace_back(0, 0);
  for (const auto& p : line({0, 0}, {0, 10})) path.push_back(p);
  path.emplace_back(0, 10);
  PurePursuit pp(PursuitParams{});
  pp.set_path(path);
  double turned = 0;
  const int steps = drive(pp, Pose2{0, 0, 0}, 50 * 300, turned);
  EXPECT_TRUE(pp.done()) << "it must not spin at the dead end";
  EXPECT_LT(steps, 50 * 90);
  EXPECT_LT(turned, 2.0 * 3.2) << "a half turn at the dead end, a quarter at the start, small corrections";
}

}  // namespace
}  // namespace ag::sim
