// The ground robot's planning stages (thin wrappers):
//   planner: map_tiles -> roadmap (a few tiles per step, each only around itself); goal + localization ->
//            route on "planned_path" when the goal is new, the map changed, or replan_period_s passed.
//   drive:   planned_path + localization -> path follower -> "wheel_command" every step; it stops
//            (within its deceleration limits) without a tracking pose, a route or a goal.
// Everything is allocated in init(); step() never allocates and never blocks.
#pragma once

#include <array>
#include <memory>
#include <span>

#include "airground/core/drive_messages.hpp"
#include "airground/core/messages.hpp"
#include "airground/planning/drive_control.hpp"
#include "airground/planning/roadmap.hpp"
#include "airground/platform/stage.hpp"

namespace ag::plan {

namespace detail {
template <std::size_t... N>
constexpr auto concat(const ParamSpec (&... parts)[N]) {
  std::array<ParamSpec, (N + ...)> out{};
  std::size_t k = 0;
  ((std::copy(std::begin(parts), std::end(parts), out.begin() + static_cast<std::ptrdiff_t>(k)), k += N), ...);
  return out;
}
}  // namespace detail

inline constexpr ParamSpec kPlannerOwnParams[] = {
    ParamSpec::real("area_x0_m", -500.0, -1e6, 1e6, "m", "mission area in the map frame: west edge (the roadmap covers it)"),
    ParamSpec::real("area_y0_m", -500.0, -1e6, 1e6, "m", "mission area: south edge"),
    ParamSpec::real("area_x1_m", 500.0, -1e6, 1e6, "m", "mission area: east edge"),
    ParamSpec::real("area_y1_m", 500.0, -1e6, 1e6, "m", "mission area: north edge"),
    ParamSpec::integer("tiles_per_step", 2, 1, 256, "tiles", "changed map tiles folded into the roadmap per step"),
    ParamSpec::real("replan_period_s", 2.0, 0.1, 60.0, "s", "re-plan from the current pose this often while a goal is active"),
    ParamSpec::real("snap_radius_m", 2.0, 0.0, 10.0, "m", "a start or goal off the free cells snaps to one within this"),
};
inline constexpr auto kPlannerParamArray = detail::concat(kPlannerOwnParams, kRoadmapParamSpecs);

struct PlannerCounters {
  std::uint64_t tiles_in{0}, tiles_applied{0}, tiles_outside{0}, tiles_stale{0};
  std::uint64_t goals{0}, goals_non_finite{0}, plans{0}, plans_failed{0};
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

 private:
  void plan_now(TimeNs now) noexcept;
  std::unique_ptr<Roadmap> map_;
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
  TimeNs replan_period_{0};
  std::size_t tiles_per_step_{2};
  double snap_{2.0};
  std::uint32_t seq_{0};
  PlannerCounters c_;
};

inline constexpr ParamSpec kDriveOwnParams[] = {
    ParamSpec::real("pose_timeout_s", 0.5, 0.05, 10.0, "s", "a localization older than this stops the robot"),
};
inline constexpr auto kDriveParamArray = detail::concat(kDriveOwnParams, kDriveParamSpecs);

class DriveStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kDriveParamArray};
  static std::unique_ptr<Stage> make() { return std::make_unique<DriveStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const PathFollower& follower() const noexcept { return *follow_; }
  [[nodiscard]] const WheelCommandMsg& published() const noexcept { return cmd_; }

 private:
  std::unique_ptr<PathFollower> follow_;
  std::unique_ptr<PlannedPathMsg> path_;
  std::unique_ptr<std::array<Point2, kMaxPathPoints>> pts_;
  LatestReader<PlannedPathMsg> path_in_;
  LatestReader<LocalizationMsg> loc_;
  LatestWriter<WheelCommandMsg> out_;
  WheelCommandMsg cmd_{};
  LocalizationMsg pose_{};
  std::uint32_t path_seq_{0};
  bool have_path_{false};
  TimeNs last_{-1}, pose_timeout_{0};
};

}  // namespace ag::plan
