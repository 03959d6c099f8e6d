// Messages of the ground robot's drive path: goal -> planner -> planned path -> drive control ->
// wheel command -> base (CAN) -> base status. Plain fixed-size structs, units in comments, stamps [ns].
#pragma once

#include <array>
#include <cstdint>

#include "airground/platform/time.hpp"

namespace ag {

inline constexpr std::size_t kMaxRoutePoints = 512;

struct RoutePoint {
  double x{0}, y{0};  // [m] map frame
};

// Channel "goal" (latest value): where the robot should go (mission manager, operator). A new stamp is a
// new goal; cancel = true stops following.
struct GoalMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t id{0};
  RoutePoint goal;
  bool cancel{false};
};

enum class RouteStatus : std::uint8_t { kNone = 0, kOk = 1, kNoRoute = 2, kBadEnds = 3, kNoMap = 4, kCancelled = 5 };
// PlannedPathMsg::plan_status when the planner found no free cell near the start (plan::PlanStatus::
// kStartBlocked): the localizer takes it as the planner's word that the robot cannot be where its pose says.
inline constexpr std::uint8_t kPlanStatusStartBlocked = 3;

// Channel "planned_path" (latest value): the global planner's route from the robot to the goal.
struct PlannedPathMsg {
  TimeNs stamp{0};             // [ns] pose stamp it was planned from
  TimeNs published{0};
  std::uint32_t seq{0};        // a new value for every new route
  std::uint32_t goal_id{0};
  RouteStatus status{RouteStatus::kNone};
  std::uint8_t plan_status{0}; // plan::PlanStatus when not ok
  std::uint32_t count{0};
  std::array<RoutePoint, kMaxRoutePoints> points{};
  double length_m{0};
  double min_clearance_m{0};
};

// Channel "local_goal" (latest value): the local tracker's view of the way ahead, once per scan.
struct LocalGoalMsg {
  TimeNs stamp{0};               // [ns] of the scan
  TimeNs published{0};
  bool valid{false};             // goal is a point to drive to
  RoutePoint goal;               // [m] map frame
  double clearance_m{0};
  std::uint8_t state{0};         // plan::TrackState (3: blocked, the path is cancelled)
  bool reflex_stop{false};       // a return above the reflex height right ahead: stop now
  std::uint32_t path_seq{0};     // the planned_path it tracks
  std::uint64_t failures{0};
};

// Channel "wheel_command" (latest value): the drive controller's wheel speeds for the base.
struct WheelCommandMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  double left_mps{0}, right_mps{0};  // [m/s] forward positive
  double v_mps{0}, w_radps{0};       // the twist they come from
  std::uint8_t follow_state{0};      // plan::FollowState
};

// Channel "base_arm" (latest value): an operator's arm / re-arm request (a new stamp is a request).
struct BaseArmMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  bool arm{true};  // false: disarm
};

// Channel "base_status" (latest value): the base driver's state, every step.
struct BaseStatusMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint8_t state{0};        // base::BaseState
  std::uint8_t fault{0};        // base::BaseFault
  std::uint8_t fault_node{0};
  std::uint32_t fault_axis_error{0};
  std::uint8_t estop{0};        // gpio::EStopState
  double left_cmd_mps{0}, right_cmd_mps{0};  // what was sent this step (0 when stopped)
  std::uint64_t watchdog_trips{0};
  std::uint64_t estop_assertions{0};
};

}  // namespace ag
