// The quadrotor's survey route as the team runner builds it, and its QGroundControl .plan file.
#include "airground/sim/survey_plan.hpp"

#include <GeographicLib/LocalCartesian.hpp>
#include <nlohmann/json.hpp>

#include <array>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>

#include "airground/sim/survey.hpp"

namespace ag::sim {

namespace {
// MAVLink numbers (common.xml): the commands, frames, autopilots and vehicle type a plan names.
constexpr int kCmdNavWaypoint = 16;
constexpr int kCmdNavReturnToLaunch = 20;
constexpr int kCmdNavTakeoff = 22;
constexpr int kCmdDoChangeSpeed = 178;
constexpr int kFrameMission = 2;              // MAV_FRAME_MISSION: a command without a position
constexpr int kFrameGlobalRelativeAlt = 3;    // MAV_FRAME_GLOBAL_RELATIVE_ALT: altitude above home
constexpr int kAutopilotArduPilot = 3;        // MAV_AUTOPILOT_ARDUPILOTMEGA
constexpr int kAutopilotPx4 = 12;             // MAV_AUTOPILOT_PX4
constexpr int kVehicleQuadrotor = 2;          // MAV_TYPE_QUADROTOR
constexpr int kSpeedTypeGround = 1;           // DO_CHANGE_SPEED param 1

nlohmann::json simple_item(int jump_id, int command, int frame, const std::array<double, 7>& params) {
  nlohmann::json p = nlohmann::json::array();
  for (double v : params) p.push_back(std::isnan(v) ? nlohmann::json(nullptr) : nlohmann::json(v));  // QGC writes NaN as null
  return {{"autoContinue", true}, {"command", command}, {"doJumpId", jump_id}, {"frame", frame}, {"params", p}, {"type", "SimpleItem"}};
}
}  // namespace

Pose3 uav_launch_pose(const World& w) noexcept {
  const Pose2& s = w.header.staging;
  const GridGeometry& g = w.grid();
  const std::int32_t c = g.col(s.x), r = g.row(s.y);
  const double z = g.contains(c, r) ? static_cast<double>(w.terrain.at<float>(r, c)) : 0.0;
  return Pose3{s.x, s.y, z, 0, 0, s.yaw};
}

MapRect survey_area(const World& w, const UavSurveyOptions& o) noexcept {
  if (o.x1 > o.x0 && o.y1 > o.y0) return MapRect{o.x0, o.y0, o.x1, o.y1};
  const GridGeometry& g = w.grid();
  return MapRect{g.origin_x + o.margin_m, g.origin_y - g.size_y() + o.margin_m, g.origin_x + g.size_x() - o.margin_m, g.origin_y - o.margin_m};
}

Result<std::vector<Waypoint>> uav_survey_route(const World& w, const UavSurveyOptions& o, double camera_hfov_rad) {
  SurveyOptions so;
  so.speed_mps = o.speed_mps;
  const GridGeometry& g = w.grid();
  const double m = o.margin_m;
  if (!(o.x1 > o.x0 && o.y1 > o.y0) && (!(m >= 0) || 2 * m >= g.size_x() || 2 * m >= g.size_y()))
    return Error::make(ErrorCode::kInvalidArgument, "uav_survey_route: a margin of " + std::to_string(m) + " m leaves no area of the " +
                                                        std::to_string(g.size_x()) + " x " + std::to_string(g.size_y()) + " m world");
  const MapRect a = survey_area(w, o);
  return survey_lawnmower(a.x0, a.y0, a.x1, a.y1, o.altitude_m, o.overlap, camera_hfov_rad, so);
}

std::string staging_outside_survey(const World& w, const UavSurveyOptions& o) {
  const bool given = o.x1 > o.x0 && o.y1 > o.y0;
  const MapRect a = survey_area(w, o);
  const double x0 = a.x0, y0 = a.y0, x1 = a.x1, y1 = a.y1;
  const Pose2& s = w.header.staging;
  const double out = std::max({x0 - s.x, s.x - x1, y0 - s.y, s.y - y1});
  if (!(out > 0)) return {};
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "the ground robots' staging pad (%.1f, %.1f) lies %.1f m outside the area the quadrotor surveys "
                "(x %.1f..%.1f, y %.1f..%.1f m%s): they start off the map they localize in and may never converge",
                s.x, s.y, out, x0, x1, y0, y1, given ? "" : ", the world less its survey margin");
  return buf;
}

Result<std::string> survey_plan_json(const SurveyPlan& plan) {
  const auto bad = [](const std::string& what) { return Error::make(ErrorCode::kInvalidArgument, "survey plan: " + what); };
  if (plan.route.empty()) return bad("the route has no waypoint");
  if (!(plan.speed_mps > 0) || !std::isfinite(plan.speed_mps)) return bad("the speed must be > 0 m/s");
  if (!(plan.acceptance_radius_m > 0) || !std::isfinite(plan.acceptance_radius_m)) return bad("the acceptance radius must be > 0 m");
  const Datum& d = plan.datum;
  if (!std::isfinite(d.lat_deg) || !std::isfinite(d.lon_deg) || !std::isfinite(d.height_m) || std::abs(d.lat_deg) > 90 || std::abs(d.lon_deg) > 180)
    return bad("the datum is not a latitude, longitude and height");
  const Pose3& home = plan.launch;
  if (!std::isfinite(home.x) || !std::isfinite(home.y) || !std::isfinite(home.z)) return bad("the launch point is not finite");
  for (std::size_t i = 0; i < plan.route.size(); ++i) {
    const Waypoint& p = plan.route[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) return bad("waypoint " + std::to_string(i + 1) + " is not finite");
  }
  const GeographicLib::LocalCartesian enu(d.lat_deg, d.lon_deg, d.height_m);
  double home_lat = 0, home_lon = 0, home_h = 0;
  enu.Reverse(home.x, home.y, home.z, home_lat, home_lon, home_h);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  nlohmann::json items = nlohmann::json::array();
  int id = 1;
  // Take-off straight up over the launch point to the first line's height (the autopilot's default pitch).
  items.push_back(simple_item(id++, kCmdNavTakeoff, kFrameGlobalRelativeAlt, {0, 0, 0, nan, home_lat, home_lon, plan.route.front().z - home.z}));
  items.push_back(simple_item(id++, kCmdDoChangeSpeed, kFrameMission, {kSpeedTypeGround, plan.speed_mps, -1, 0, 0, 0, 0}));
  for (const Waypoint& p : plan.route) {
    double lat = 0, lon = 0, h = 0;
    enu.Reverse(p.x, p.y, p.z, lat, lon, h);
    // hold 0 s, acceptance radius, pass through (0), yaw unchanged (NaN: the autopilot's heading mode)
    items.push_back(simple_item(id++, kCmdNavWaypoint, kFrameGlobalRelativeAlt, {0, plan.acceptance_radius_m, 0, nan, lat, lon, p.z - home.z}));
  }
  if (plan.return_to_launch) items.push_back(simple_item(id++, kCmdNavReturnToLaunch, kFrameMission, {0, 0, 0, 0, 0, 0, 0}));
  nlohmann::json mission = {{"version", 2},
                            {"firmwareType", plan.firmware == AutopilotFirmware::kPx4 ? kAutopilotPx4 : kAutopilotArduPilot},
                            {"vehicleType", kVehicleQuadrotor},
                            {"cruiseSpeed", plan.speed_mps},
                            {"hoverSpeed", plan.speed_mps},
                            {"plannedHomePosition", {home_lat, home_lon, d.height_m + home.z}},
                            {"items", items}};
  nlohmann::json file = {{"fileType", "Plan"},
                         {"version", 1},
                         {"groundStation", "QGroundControl"},
                         {"mission", mission},
                         {"geoFence", {{"circles", nlohmann::json::array()}, {"polygons", nlohmann::json::array()}, {"version", 2}}},
                         {"rallyPoints", {{"points", nlohmann::json::array()}, {"version", 2}}}};
  return file.dump(4) + "\n";
}

Status write_survey_plan(const std::string& path, const SurveyPlan& plan) {
  auto text = survey_plan_json(plan);
  if (!text) return text.error();
  std::ofstream f(path, std::ios::binary);
  f << text.value();
  f.close();
  if (!f) return Error::make(ErrorCode::kIo, "cannot write the survey plan " + path);
  return ok_status();
}

}  // namespace ag::sim
