// The quadrotor's survey as the team runner flies it, and the same survey as a QGroundControl plan file
// (.plan, JSON), which is how a field team loads a mission into its PX4 or ArduPilot autopilot.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// The survey's parameters; the defaults are the team runner's (RunOptions).
struct UavSurveyOptions {
  double altitude_m{40};    // [m] flying height: every waypoint's map z (the map frame's z = 0 is the datum height)
  double overlap{0.6};      // side overlap of neighbouring camera footprints, [0, 0.95]
  double speed_mps{5};      // [m/s] written into every waypoint
  double margin_m{20};      // [m] without an area: the world minus this margin on every side
  double x0{0}, y0{0}, x1{0}, y1{0};  // [m] the area in the map frame, used when x1 > x0 and y1 > y0
};

// Where the quadrotor takes off: the staging pad at the terrain's height, with the pad's heading.
[[nodiscard]] Pose3 uav_launch_pose(const World& w) noexcept;

// The lawnmower the team runner's quadrotor flies (east-west lines from the south-west corner, without
// its return to launch). Errors as survey_lawnmower's, and a margin that leaves no area.
Result<std::vector<Waypoint>> uav_survey_route(const World& w, const UavSurveyOptions& o, double camera_hfov_rad);

// The area the survey covers [m, map frame]: the given one, or the world less margin_m on every side.
// The quadrotor's map exists there; the ground robots localize in it (team runner: localization.area_*).
[[nodiscard]] MapRect survey_area(const World& w, const UavSurveyOptions& o) noexcept;

// Empty when the ground robots' staging pad lies inside the area the survey covers; else a warning that
// names the pad, the area and by how far it is out: robots starting there start off the map they localize
// in (a generated world can put its pad inside the survey's border; docs/simulator.md, "Staging pad").
[[nodiscard]] std::string staging_outside_survey(const World& w, const UavSurveyOptions& o);

enum class AutopilotFirmware : std::uint8_t { kPx4, kArduPilot };

// What a plan file carries: the route in the map frame, the launch point, and how the autopilot flies it.
struct SurveyPlan {
  std::vector<Waypoint> route;         // map frame [m]; z above the datum height
  Pose3 launch;                        // the planned home position (map frame)
  Datum datum;                         // the map frame's origin (the world's)
  AutopilotFirmware firmware{AutopilotFirmware::kPx4};
  double speed_mps{5};                 // [m/s] cruise and hover speed, and the DO_CHANGE_SPEED after take-off
  double acceptance_radius_m{1};       // [m] a waypoint counts as reached within this (the quadrotor model's tolerance)
  bool return_to_launch{true};         // end with RTL (the simulated quadrotor flies back over its launch point)
};

// The plan as QGroundControl writes it (file version 1, mission version 2, multirotor): take-off over the
// launch point to the first waypoint's height, DO_CHANGE_SPEED, one NAV_WAYPOINT per route point in
// MAV_FRAME_GLOBAL_RELATIVE_ALT (altitude above the launch point), then RTL if asked; empty geofence and
// rally points. Latitude and longitude from the map frame's local ENU at the datum (WGS84); the planned
// home altitude is the datum's height plus the launch point's (ellipsoidal, as the world's datum).
// Errors (kInvalidArgument): an empty route, a non-finite coordinate, speed or radius not > 0.
Result<std::string> survey_plan_json(const SurveyPlan& plan);
// survey_plan_json() written to `path`; an I/O error names the path.
Status write_survey_plan(const std::string& path, const SurveyPlan& plan);

}  // namespace ag::sim
