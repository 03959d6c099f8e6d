// The ground robot's planning stages (thin wrappers):
//   planner: map_tiles -> roadmap (a few tiles per step, each only around itself); goal + localization ->
//            route on "planned_path" when the goal is new, the map changed, or replan_period_s passed.
//   drive:   planned_path + localization -> path follower -> "wheel_command" every step; it stops
//            (within its deceleration limits) without a tracking pose, a route or a goal, at once
//            on the tracker's reflex, and until a new route when the tracker cancels the route; while
//            the localizer converges, and for lost_coast_m after it loses track, it drives slowly.
//   tracker: lidar_scan + localization + planned_path -> local tracker -> "local_goal" (the local
//            goal, its state, the reflex). The drive stage does not yet steer to the local goal.
// Everything is allocated in init(); step() never allocates and never blocks.
#pragma once

#include <array>
#include <memory>
#include <span>

#include "airground/messages/drive_messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/planning/drive_control.hpp"
#include "airground/planning/local_tracker.hpp"
#include "airground/messages/mission_area.hpp"
#include "airground/planning/roadmap.hpp"
#include "airground/planning/stall_marks.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag::plan {

// The planner's own parameters (the roadmap's follow them in the same section).
inline constexpr auto kPlannerAreaFields = mission_area_fields("mission area in the map frame: west edge (the roadmap covers it)");
struct PlannerSettings {
  double geofence_margin_m{1.0};
  int tiles_per_step{2};
  double replan_period_s{2.0};
  double snap_radius_m{2.0};
  bool plan_while_initialising{true};
  double initialising_snap_m{20.0};
};
inline constexpr ParamField<PlannerSettings> kPlannerFields[] = {
    field::real("geofence_margin_m", &PlannerSettings::geofence_margin_m, 0.0, 100.0, "m",
                "the mission area is a geofence: routes keep min_clearance_m inside the area shrunk by this"),
    field::integer("tiles_per_step", &PlannerSettings::tiles_per_step, 1, 256, "tiles", "changed map tiles folded into the roadmap per step"),
    field::real("replan_period_s", &PlannerSettings::replan_period_s, 0.1, 60.0, "s", "re-plan from the current pose this often while a goal is active"),
    field::real("snap_radius_m", &PlannerSettings::snap_radius_m, 0.0, 10.0, "m", "a start or goal off the free cells snaps to one within this"),
    field::boolean("plan_while_initialising", &PlannerSettings::plan_while_initialising,
                   "plan from the localizer's best estimate while it is still converging (it converges by driving)"),
    field::real("initialising_snap_m", &PlannerSettings::initialising_snap_m, 0.0, 100.0, "m", "... and snap its start to a free cell within 2 sigma, at most this far"),
};
inline constexpr auto kPlannerParamArray = param_specs(kPlannerAreaFields, kPlannerFields, kRoadmapFields, kStallFields);

struct PlannerCounters {
  std::uint64_t tiles_in{0}, tiles_applied{0}, tiles_outside{0}, tiles_stale{0};
  std::uint64_t goals{0}, goals_non_finite{0}, plans{0}, plans_failed{0};
  std::uint64_t stalls{0};  // stood on the route stall_s: the ground ahead marked blocked
  std::uint64_t start_escapes{0};  // routes whose start joined the free cells across grass (start_escape_m)
};

class PlannerStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kPlannerParamArray};
  static std::unique_ptr<Stage> make() { return std::make_unique<PlannerStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const Roadmap& roadmap() const noexcept { return *map_; }
  [[nodiscard]] const PlannedPathMsg& published() const noexcept { return *msg_; }
  [[nodiscard]] const PlannerCounters& counters() const noexcept { return c_; }
  [[nodiscard]] const StallMarks& stall_marks() const noexcept { return *stall_; }

 private:
  void plan_now(TimeNs now) noexcept;
  std::unique_ptr<Roadmap> map_;
  std::unique_ptr<StallMarks> stall_;
  std::unique_ptr<PlannedPath> path_;
  std::unique_ptr<PlannedPathMsg> msg_;
  RingReader<MapTileMsg, kMapTileRing> tiles_;
  LatestReader<LocalizationMsg> loc_;
  LatestReader<GoalMsg> goal_in_;
  LatestWriter<PlannedPathMsg> out_;
  LocalizationMsg pose_{};
  GoalMsg goal_{};
  bool have_pose_{false}, have_goal_{false}, map_changed_{false};
  TimeNs goal_stamp_{-1}, last_plan_{0};
  PlannerSettings cfg_{};
  TimeNs replan_period_{0};
  std::uint32_t seq_{0};
  PlannerCounters c_;
};

// The drive stage's own parameters (the path follower's follow them in the same section).
struct DriveSettings {
  double pose_timeout_s{0.5};
  double local_goal_timeout_s{0.3};
  double initialising_speed_mps{0.6};
  bool steer_to_local_goal{true};
  double reflex_turn_after_s{1.0};
  double lost_speed_mps{0.5};
  double lost_coast_m{15.0};
};
inline constexpr ParamField<DriveSettings> kDriveStageFields[] = {
    field::real("pose_timeout_s", &DriveSettings::pose_timeout_s, 0.05, 10.0, "s", "a localization older than this stops the robot"),
    field::real("local_goal_timeout_s", &DriveSettings::local_goal_timeout_s, 0.05, 5.0, "s", "a local goal older than this is ignored"),
    field::real("initialising_speed_mps", &DriveSettings::initialising_speed_mps, 0.0, 5.0, "m/s",
                "top speed while the localizer is still converging (it needs motion to converge); 0 = wait for tracking"),
    field::boolean("steer_to_local_goal", &DriveSettings::steer_to_local_goal, "steer at the local tracker's goal (clear of what the LiDAR sees) when it has one"),
    field::real("reflex_turn_after_s", &DriveSettings::reflex_turn_after_s, 0.0, 60.0, "s",
                "under a reflex stop this long: turn on the spot toward the local goal (never forward); else it could stand facing a car for ever"),
    field::real("lost_speed_mps", &DriveSettings::lost_speed_mps, 0.0, 5.0, "m/s",
                "the localizer lost track: go on along the route on its dead-reckoned pose at most this fast (it finds itself "
                "again only from new views: a robot that stops there stays lost); 0 = stop at once"),
    field::real("lost_coast_m", &DriveSettings::lost_coast_m, 0.0, 500.0, "m", "... for at most this far from where it was lost, then stop"),
};
inline constexpr auto kDriveParamArray = param_specs(kDriveStageFields, kDriveFields);

class DriveStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kDriveParamArray};
  static std::unique_ptr<Stage> make() { return std::make_unique<DriveStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const PathFollower& follower() const noexcept { return *follow_; }
  [[nodiscard]] const WheelCommandMsg& published() const noexcept { return cmd_; }
  [[nodiscard]] std::uint64_t reflex_stops() const noexcept { return reflex_stops_; }

 private:
  std::unique_ptr<PathFollower> follow_;
  std::unique_ptr<PlannedPathMsg> path_;
  std::unique_ptr<std::array<Point2, kMaxPathPoints>> pts_;
  LatestReader<PlannedPathMsg> path_in_;
  LatestReader<LocalizationMsg> loc_;
  LatestReader<LocalGoalMsg> local_in_;
  LatestWriter<WheelCommandMsg> out_;
  WheelCommandMsg cmd_{};
  LocalizationMsg pose_{};
  LocalGoalMsg local_{};
  std::uint32_t path_seq_{0}, n_pts_{0};
  bool have_path_{false}, blocked_{false};
  TimeNs last_{-1}, pose_timeout_{0}, local_timeout_{0};
  TimeNs reflex_since_{-1}, reflex_hold_{0};
  double coast_m_{0.0};   // [m] driven on the dead-reckoned pose since the localizer lost track
  Pose2 coast_last_{};
  bool coasting_{false};
  DriveSettings cfg_{};
  std::uint64_t reflex_stops_{0};
};

inline constexpr ParamField<LocalTrackerParams> kTrackerFields[] = {
    field::real("obstacle_min_m", &LocalTrackerParams::obstacle_min_m, 0.05, 2.0, "m", "returns this high above the ground plane are obstacles (a 15 cm curb is not)"),
    field::real("overhang_m", &LocalTrackerParams::overhang_m, 0.5, 10.0, "m", "returns higher than this above the ground are not obstacles"),
    field::real("min_clearance_m", &LocalTrackerParams::min_clearance_m, 0.0, 5.0, "m", "the local goal keeps this from obstacles"),
    field::real("goal_distance_m", &LocalTrackerParams::goal_distance_m, 1.0, 15.0, "m", "the local goal is this far along the route"),
    field::real("reflex_height_m", &LocalTrackerParams::reflex_height_m, 0.05, 2.0, "m", "a return this high right ahead stops the robot"),
    field::real("reflex_distance_m", &LocalTrackerParams::reflex_distance_m, 0.1, 5.0, "m", "... within this ahead (plus speed x 0.5 s)"),
    field::real("reflex_half_width_m", &LocalTrackerParams::reflex_half_width_m, 0.1, 2.0, "m", "... and this of the centre line"),
    field::real("backup_timeout_s", &LocalTrackerParams::backup_timeout_s, 0.5, 60.0, "s", "backing up this long without a way forward cancels the route"),
    field::real("no_ground_range_m", &LocalTrackerParams::no_ground_range_m, 0.0, 10.0, "m",
                "within this of the robot, ground the rays crossed with no ground return near it (water, a drop) is an obstacle; 0 = off"),
    field::real("no_ground_radius_m", &LocalTrackerParams::no_ground_radius_m, 0.2, 2.0, "m", "... no ground return within this of the cell"),
    field::boolean("no_ground_unseen", &LocalTrackerParams::no_ground_unseen,
                   "... and so is a cell in that ring no ray crossed (water out to beyond the LiDAR's reach, a drop)"),
    field::boolean("no_ground_edge_margin", &LocalTrackerParams::no_ground_edge_margin,
                   "clearance from a no-ground cell counts from no_ground_radius_m inside it (the water may begin that much nearer)"),
    field::integer("no_ground_memory_updates", &LocalTrackerParams::no_ground_memory_updates, 0, 100000, "scans",
                   "cells found without ground stay obstacles this many scans while too near the robot for its LiDAR to see (0 = no memory)"),
};
inline constexpr auto kTrackerParamArray = param_specs(kTrackerFields);

// tracker: lidar_scan + localization + planned_path -> local tracker -> "local_goal" once per scan.
class TrackerStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kTrackerParamArray};
  static std::unique_ptr<Stage> make() { return std::make_unique<TrackerStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const LocalTracker& tracker() const noexcept { return *tracker_; }
  [[nodiscard]] const LocalGoalMsg& published() const noexcept { return msg_; }
  [[nodiscard]] std::uint64_t scans() const noexcept { return scans_in_; }

 private:
  std::unique_ptr<LocalTracker> tracker_;
  std::unique_ptr<PlannedPathMsg> path_;
  std::unique_ptr<std::array<Point2, kMaxPathPoints>> pts_;
  RingReader<LidarScanMsg, kLidarRing> scans_;
  LatestReader<LocalizationMsg> loc_;
  LatestReader<PlannedPathMsg> path_in_;
  LatestReader<WheelCommandMsg> cmd_in_;
  LatestWriter<LocalGoalMsg> out_;
  LocalizationMsg pose_{};
  WheelCommandMsg cmd_{};
  LocalGoalMsg msg_{};
  std::uint32_t path_seq_{0};
  std::uint64_t scans_in_{0}, scans_malformed_{0};
};

}  // namespace ag::plan
