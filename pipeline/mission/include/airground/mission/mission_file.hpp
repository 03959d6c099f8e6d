// The mission file (YAML, docs/missions.md; example config/missions/default.yaml): datum, area, team,
// mission type with its targets or waypoints, the mission parameters, and the quadrotor's survey as data
// (a lawnmower over an area at an altitude and speed, lines spaced directly or from the image overlap).
// Every error names file:line and the key.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag::mission {

enum class MissionType : std::uint8_t { kRegions = 0, kWaypoints = 1 };

struct XY {
  double x{0}, y{0};  // [m] map frame
};
struct Area {
  double x0{0}, y0{0}, x1{0}, y1{0};  // [m] map frame
};
struct TeamMember {
  int id{1};
  int priority{1};
  double start_x{0}, start_y{0}, start_yaw{0};  // [m, m, rad] true start (the simulator places it here)
  double guess_x{0}, guess_y{0}, guess_yaw{0};  // initial pose guess given to the localizer
  double guess_sigma_m{8.0};                    // [m] its standard deviation per axis (a guess within R m: R/2)
  std::vector<XY> waypoints;                    // waypoints missions: this robot's route
};
struct Survey {
  int robot{0};
  std::string pattern{"lawnmower"};
  double altitude_m{40.0};
  double speed_mps{5.0};
  double line_spacing_m{0.0};   // > 0: used as given; else from overlap and the camera's field of view
  double overlap{0.6};          // side overlap of neighbouring lines' footprints, [0, 0.95]
  double camera_hfov_deg{70.0}; // across-track field of view
  double heading_deg{0.0};      // line direction, degrees from east (counter-clockwise); 0 = lines run east-west
  Area area;                    // defaults to the mission area
  bool return_home{true};       // after the last line fly back over the launch point and hover (RTL)
  [[nodiscard]] double spacing_m() const noexcept;
};
struct MissionParameters {
  double visit_radius_m{3.0};
  double max_sigma_m{1.5};
  double claim_timeout_s{20.0};
  double idle_return_s{60.0};
  double mission_end_s{0.0};
  double survey_end_s{0.0};     // > 0: the survey ends about then (robots wait for regions till then); 0 = the simulator estimates it
  double merge_distance_m{12.0};
  int min_region_cells{8};
  double comm_range_m{0.0};     // 0 = unlimited (simulator)
};
struct MissionFile {
  std::string name;
  MissionType type{MissionType::kRegions};
  double lat_deg{0}, lon_deg{0}, alt_m{0};
  Area area;
  std::vector<TeamMember> team;
  std::vector<XY> targets;      // regions missions: the expected targets (optional; for scoring)
  MissionParameters params;
  Survey survey;
  [[nodiscard]] const TeamMember* member(int id) const noexcept;
};

Result<MissionFile> load_mission_file(const std::string& path);
Result<MissionFile> load_mission_string(std::string_view yaml, std::string_view origin);

// The survey's waypoints (x, y in the map frame; fly them in order at survey.altitude_m): lines across the
// area spaced spacing_m(), alternating direction, the first and last half a spacing inside the edges.
std::vector<XY> survey_waypoints(const Survey& s);

}  // namespace ag::mission
