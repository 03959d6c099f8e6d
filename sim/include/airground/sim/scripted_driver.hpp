// Scripted motion for the simulator: routes over the world's roads from ground truth and a pure-pursuit
// follower, so robots move realistically before (and without) the robots' own planner.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <cstdint>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

class RoadRouter {
 public:
  // Drivable = road or dirt cells, eroded by the robot's clearance, on a `cell_m` grid.
  RoadRouter(const World& world, double cell_m = 1.0, double clearance_m = 0.5);
  [[nodiscard]] bool drivable(double x, double y) const noexcept;
  // A* over drivable cells (8-connected), then line-of-sight shortcutting; false if unreachable.
  bool route(double sx, double sy, double gx, double gy, std::vector<Eigen::Vector2d>& path) const;
  // The drivable cell nearest to (x, y) within `radius_m`; false if none.
  bool nearest_drivable(double x, double y, double radius_m, Eigen::Vector2d& out) const;
  // A drivable point chosen by a deterministic hash of `key` (for scripted goals).
  [[nodiscard]] Eigen::Vector2d pick_drivable(std::uint64_t key) const;
  [[nodiscard]] std::size_t drivable_cells() const noexcept { return free_cells_.size(); }

 private:
  bool free_cell(int c, int r) const noexcept { return c >= 0 && r >= 0 && c < geo_.width && r < geo_.height && free_.at<std::uint8_t>(r, c) != 0; }
  bool line_free(int c0, int r0, int c1, int r1) const noexcept;
  GridGeometry geo_;
  cv::Mat free_;  // CV_8UC1, 1 = drivable
  std::vector<std::int32_t> free_cells_;
};

// Pure pursuit on a polyline with speed and turn limits; outputs body velocities.
struct PursuitParams {
  double lookahead_m = 1.5;
  double max_speed_mps = 1.2;
  double max_yaw_rate = 1.2;    // [rad/s]
  double goal_tolerance_m = 0.8;
};

class PurePursuit {
 public:
  explicit PurePursuit(PursuitParams p = {}) : p_(p) {}
  void set_path(std::vector<Eigen::Vector2d> path) {
    path_ = std::move(path);
    next_ = 0;
    next_t_ = 0;
  }
  // Linear [m/s] and angular [rad/s] velocity toward the path; done() once at the last point.
  void command(const Pose2& pose, double& v, double& w);
  [[nodiscard]] bool done() const noexcept { return path_.empty() || next_ >= path_.size(); }
  [[nodiscard]] const std::vector<Eigen::Vector2d>& path() const noexcept { return path_; }
  // next_: the path segment (path_[next_] -> path_[next_ + 1]) the robot is on; path_.size() once done.

 private:
  PursuitParams p_;
  std::vector<Eigen::Vector2d> path_;
  std::size_t next_{0};
  double next_t_{0};  // how far along segment next_ the robot has got [0, 1]
};

}  // namespace ag::sim
