// The local waypoint tracker and obstacle check (ALGORITHMS.md §4): what the aerial map could not see.
// From each LiDAR scan: the ground plane by RANSAC, points near it ground, points above it obstacles
// (up to an overhang height), free space by ray casting from the sensor to the ground points, in a
// robot-centred obstacle grid. The local goal is a point toward the next waypoint in known free space,
// the cell around it farthest from obstacles. When that region is blocked the robot backs up to the
// last waypoint; when that fails too the path is cancelled and reported. A reflex stops the robot for
// any return above a height threshold in front of it, whatever the plan. Ground the rays crossed near
// the robot without a ground return near it (water, a drop) is an obstacle too.
//
// Everything is allocated in the constructor; update() and local_goal() never allocate.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/messages/messages.hpp"
#include "airground/planning/roadmap.hpp"

namespace ag::plan {

struct LocalTrackerParams {
  double grid_size_m{20.0};          // [m] edge of the robot-centred grid
  double cell_m{0.2};
  int ransac_iterations{60};
  double ransac_threshold_m{0.08};   // inlier distance to the plane
  double max_ground_tilt_rad{0.35};  // the plane's normal within this of vertical
  double ground_band_m{0.12};        // |height above plane| below this: ground
  double obstacle_min_m{0.2};        // above this: obstacle (curbs of 0.15 m are not)
  double overhang_m{2.0};            // above this: not an obstacle (branches, gates)
  double min_clearance_m{0.6};       // the local goal keeps this from obstacles
  double goal_distance_m{5.0};       // local goal this far along the path
  double goal_search_m{1.5};         // ... among cells within this of it
  double reflex_height_m{0.25};      // any return this high ...
  double reflex_distance_m{0.8};     // ... this close ahead (plus speed x reflex_time_s) ...
  double reflex_time_s{0.5};
  double reflex_half_width_m{0.35};  // ... within this of the centre line stops the robot
  double backup_timeout_s{8.0};      // backing up that long without a free way forward fails
  // Ground the LiDAR passed over but never hit: a cell a ray crossed (to ground beyond it) with no ground
  // return within no_ground_radius_m, between the nearest ground return + that radius and
  // no_ground_range_m of the robot (where the rings lie closer than twice the radius), is an obstacle.
  // Water gives no return, so without this the rays to the far shore made a pond free space, and the
  // local goal (the cell farthest from obstacles) went onto it (gen6's pond, session 39). 0 = off.
  double no_ground_range_m{6.0};
  double no_ground_radius_m{0.5};
  // ... and so is a cell in that ring no ray crossed: a pond whose far shore is out of reach gives no
  // return and no ray over it, and was unknown, which the local goal's clearance ignored: goals went
  // onto its edge and the robot's footprint into the water (gen6's pond, session 41).
  bool no_ground_unseen{true};
  // A no-ground cell's clearance counts from no_ground_radius_m inside it: the cells within that radius
  // of the last ground return are free although the water may begin anywhere among them. Without it a
  // goal 0.6 m from the first no-ground cell was 0.1 m from the water, and the robot's footprint touched
  // it (gen6's pond, session 41).
  bool no_ground_edge_margin{true};
  // The LiDAR cannot see the ground within about 2.5 m of the robot (its lowest beam): cells found
  // without ground are remembered (map frame) for this many updates and stay obstacles there, so a
  // shore seen from 4 m is still one when the robot is beside it. 0 = no memory.
  int no_ground_memory_updates{100};
  bool trace_each_end_cell_once{true};  // false: a line to every ground return (the reference, same grid)
};

struct Plane {
  double a{0}, b{0}, c{1}, d{0};  // a x + b y + c z + d = 0, unit normal, c > 0 (sensor frame)
  [[nodiscard]] double height(double x, double y, double z) const noexcept { return a * x + b * y + c * z + d; }
};

enum class TrackState : std::uint8_t { kIdle = 0, kTracking = 1, kBackingUp = 2, kFailed = 3, kArrived = 4 };
const char* to_string(TrackState s) noexcept;

struct LocalGoal {
  bool valid{false};
  Point2 goal;            // [m] map frame
  double clearance_m{0};  // of the chosen cell
  bool reflex_stop{false};
};

class LocalTracker {
 public:
  explicit LocalTracker(const LocalTrackerParams& p);

  // Fits the ground and rebuilds the obstacle grid from one scan (points in the sensor frame; the
  // sensor's mount in the body and the robot's pose in the map frame). Returns false when no ground
  // plane was found (the grid is then all unknown).
  bool update(std::span<const ScanReturn> pts, const Pose3& sensor_in_body, const Pose2& robot, double speed_mps) noexcept;

  // A new path to track (map frame), from its first point.
  void set_path(std::span<const Point2> path) noexcept;
  // The local goal for the robot now; advances along the path, backs up, or fails (state()).
  LocalGoal local_goal(const Pose2& robot, TimeNs now) noexcept;

  [[nodiscard]] TrackState state() const noexcept { return state_; }
  [[nodiscard]] const Plane& ground() const noexcept { return plane_; }
  [[nodiscard]] bool reflex_stop() const noexcept { return reflex_; }
  // Grid: 0 unknown, 1 free, 2 obstacle; cell (i, j) of width() x width(), robot at the centre, axes
  // along the map frame (x east = column).
  [[nodiscard]] std::uint8_t cell(int i, int j) const noexcept { return grid_[idx(i, j)]; }
  [[nodiscard]] int width() const noexcept { return n_; }
  [[nodiscard]] std::uint8_t cell_at(double x, double y) const noexcept;   // map frame
  [[nodiscard]] double clearance_at(double x, double y) const noexcept;   // [m] to the nearest obstacle cell's edge (capped)
  [[nodiscard]] std::uint64_t failures() const noexcept { return failures_; }
  [[nodiscard]] std::uint32_t waypoint() const noexcept { return wp_; }

 private:
  [[nodiscard]] std::size_t idx(int i, int j) const noexcept { return static_cast<std::size_t>(j) * static_cast<std::size_t>(n_) + static_cast<std::size_t>(i); }
  bool cell_of(double x, double y, int& i, int& j) const noexcept;
  bool fit_plane(std::span<const ScanReturn> pts) noexcept;
  void compute_clearance() noexcept;
  bool pick_goal(const Point2& target, double radius_m, LocalGoal& out) const noexcept;

  LocalTrackerParams p_;
  int n_{0};
  double cx_{0}, cy_{0};  // [m] map-frame centre of the grid (the robot at the last update)
  std::vector<std::uint8_t> grid_;
  std::vector<float> clear_;  // [m]
  std::vector<std::int32_t> inliers_;
  // Free-space rays to the same end cell trace the same line: each end cell is traced once per scan.
  // In-grid ends are marked in end_stamp_ (this update's stamp_), ends outside the grid in a small
  // open-addressed set (far_keys_/far_stamp_); when that is full a ray is traced anyway (same grid).
  std::vector<std::uint32_t> end_stamp_;
  std::vector<std::uint32_t> hit_stamp_;  // cells a ground return fell in (this update's stamp_)
  std::vector<std::uint32_t> nog_stamp_;  // obstacle cells found without ground (this update's stamp_)
  std::vector<std::int16_t> near_di_, near_dj_;  // cell offsets within no_ground_radius_m
  // Cells found without ground, by map-frame cell (X, Y) in a table of the grid's size indexed by
  // (X mod n, Y mod n): the key and the update it was last found in (0: ground seen there since).
  std::vector<std::uint64_t> memo_key_;
  std::vector<std::uint32_t> memo_at_;
  std::uint32_t updates_{0};
  void mark_no_ground(int ri, int rj, double r_min_m) noexcept;
  std::vector<std::uint64_t> far_keys_;
  std::vector<std::uint32_t> far_stamp_;
  std::uint32_t stamp_{0};
  bool first_free_ray(int ei, int ej) noexcept;
  Plane plane_;
  bool have_plane_{false}, reflex_{false};
  std::uint64_t rng_{0x9E3779B97F4A7C15ULL};
  std::array<Point2, kMaxPathPoints> path_{};
  std::uint32_t n_path_{0}, wp_{0};
  TrackState state_{TrackState::kIdle};
  TimeNs backup_since_{0};
  Point2 prev_goal_{};
  bool have_prev_{false};
  std::uint64_t failures_{0};
};

}  // namespace ag::plan
