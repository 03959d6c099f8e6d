// airground-sim survey-plan: the quadrotor's lawnmower survey over a world as a QGroundControl .plan file,
// the route the simulator flies, for a field team to load into its PX4 or ArduPilot autopilot.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "airground/sim/camera.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/survey_plan.hpp"

namespace {

constexpr const char* kSurveyPlanHelp =
    "airground-sim survey-plan --world W --out FILE.plan [options]\n\n"
    "Writes the quadrotor's lawnmower survey over the world (the route 'mission' and 'run' fly, which also\n"
    "write it as DIR/survey.plan) as a QGroundControl plan file: take-off over the launch point (the\n"
    "world's staging pad), a speed change, one waypoint per line end at the survey height above the launch\n"
    "point (MAV_FRAME_GLOBAL_RELATIVE_ALT, WGS84 from the world's datum), then return to launch. Open it in\n"
    "QGroundControl (Plan view, Open) and upload it to a PX4 or ArduPilot multirotor. Lines run east-west from\n"
    "the south-west corner, spaced by the camera footprint and the side overlap.\n"
    "Defaults are the mission's: --world default, --altitude 40, --overlap 0.6, --speed 5, --margin 20.\n\n"
    "Options:\n"
    "  --world W              a world directory or 'default' (the built-in 400 m world)\n"
    "  --out FILE.plan        the plan file (required)\n"
    "  --altitude M           flying height above the datum, as the simulator's --altitude [m] (40)\n"
    "  --overlap F            side overlap of neighbouring camera footprints, 0 .. 0.95 (0.6)\n"
    "  --speed V              cruise speed [m/s] (5)\n"
    "  --area X0,Y0,X1,Y1     the area to survey in the world's map frame [m] (x east, y north)\n"
    "  --margin M             without --area: the world minus M metres on every side (20)\n"
    "  --camera FILE.yaml     the camera whose footprint spaces the lines (the simulator's default camera)\n"
    "  --firmware px4|ardupilot  the plan's autopilot (px4)\n"
    "  --no-rtl               end hovering over the last waypoint instead of returning to launch (as 'run')\n"
    "Exit status: 0 written, 1 the world or the file failed, 2 bad usage.\n";

[[noreturn]] void usage(const std::string& msg) {
  std::fprintf(stderr, "airground-sim survey-plan: %s (see airground-sim survey-plan --help)\n", msg.c_str());
  std::exit(2);
}

double number(const std::map<std::string, std::string>& o, const std::string& k, double def) {
  const auto it = o.find(k);
  if (it == o.end()) return def;
  char* end = nullptr;
  const double d = std::strtod(it->second.c_str(), &end);
  if (it->second.empty() || *end != '\0' || !std::isfinite(d)) usage("--" + k + " needs a number, got '" + it->second + "'");
  return d;
}

}  // namespace

int survey_plan_cmd(int argc, char** argv) {
  static const std::set<std::string> valued = {"world", "out", "altitude", "overlap", "speed", "area", "margin", "camera", "firmware"};
  std::map<std::string, std::string> o;
  bool rtl = true;
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    if (s == "--help" || s == "-h") {
      std::fputs(kSurveyPlanHelp, stdout);
      return 0;
    }
  }
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    if (s.rfind("--", 0) != 0) usage("unexpected argument '" + s + "'");
    const std::string k = s.substr(2);
    if (k == "no-rtl") {
      rtl = false;
      continue;
    }
    if (!valued.count(k)) usage("unknown option '--" + k + "'");
    if (i + 1 >= argc) usage("--" + k + " needs a value");
    o[k] = argv[++i];
  }
  if (!o.count("out") || o.at("out").empty()) usage("--out FILE.plan is required");
  using namespace ag::sim;
  UavSurveyOptions so;  // the team runner's defaults
  so.altitude_m = number(o, "altitude", so.altitude_m);
  so.overlap = number(o, "overlap", so.overlap);
  so.speed_mps = number(o, "speed", so.speed_mps);
  so.margin_m = number(o, "margin", so.margin_m);
  if (!(so.altitude_m > 0)) usage("--altitude must be > 0 m");
  if (!(so.overlap >= 0 && so.overlap <= 0.95)) usage("--overlap must be in [0, 0.95]");
  if (!(so.speed_mps > 0 && so.speed_mps <= 30)) usage("--speed must be in (0, 30] m/s");
  if (!(so.margin_m >= 0)) usage("--margin must be >= 0 m");
  if (o.count("area")) {
    const std::string& a = o.at("area");
    char tail = 0;
    if (std::sscanf(a.c_str(), "%lf,%lf,%lf,%lf%c", &so.x0, &so.y0, &so.x1, &so.y1, &tail) != 4 || !std::isfinite(so.x0) || !std::isfinite(so.y0) ||
        !std::isfinite(so.x1) || !std::isfinite(so.y1) || !(so.x1 > so.x0) || !(so.y1 > so.y0))
      usage("--area needs X0,Y0,X1,Y1 in metres with X1 > X0 and Y1 > Y0, got '" + a + "'");
  }
  const std::string fw = o.count("firmware") ? o.at("firmware") : "px4";
  if (fw != "px4" && fw != "ardupilot") usage("--firmware must be px4 or ardupilot, got '" + fw + "'");

  CameraModel cam;  // as the team runner without --config-dir
  if (o.count("camera")) {
    auto c = CameraModel::load_file(o.at("camera"));
    if (!c) {
      std::fprintf(stderr, "airground-sim survey-plan: %s\n", c.error().message.c_str());
      return 1;
    }
    cam = c.value();
  }
  const std::string world_arg = o.count("world") ? o.at("world") : "default";
  auto world = resolve_world(world_arg);
  if (!world) {
    std::fprintf(stderr, "airground-sim survey-plan: %s\n", world.error().message.c_str());
    return 1;
  }
  const World& w = *world.value();
  const double hfov = 2.0 * std::atan(0.5 * cam.width / cam.fx);  // as the team runner's camera
  auto route = uav_survey_route(w, so, hfov);
  if (!route) {
    std::fprintf(stderr, "airground-sim survey-plan: %s\n", route.error().message.c_str());
    return 1;
  }
  if (const std::string off = staging_outside_survey(w, so); !off.empty()) std::fprintf(stderr, "airground-sim survey-plan: warning: %s\n", off.c_str());
  SurveyPlan plan;
  plan.route = route.value();
  plan.launch = uav_launch_pose(w);
  plan.datum = w.header.datum;
  plan.firmware = fw == "px4" ? AutopilotFirmware::kPx4 : AutopilotFirmware::kArduPilot;
  plan.speed_mps = so.speed_mps;
  plan.acceptance_radius_m = QuadrotorConfig{}.waypoint_tolerance_m;
  plan.return_to_launch = rtl;
  if (auto st = write_survey_plan(o.at("out"), plan); !st) {
    std::fprintf(stderr, "airground-sim survey-plan: %s\n", st.error().message.c_str());
    return 1;
  }
  double length = 0;
  for (std::size_t i = 1; i < plan.route.size(); ++i)
    length += std::hypot(plan.route[i].x - plan.route[i - 1].x, plan.route[i].y - plan.route[i - 1].y);
  std::printf("survey plan %s: %zu lines %.1f m apart at %.1f m above the launch point, %zu waypoints, %.0f m of route at %.1f m/s (%s%s)\n",
              o.at("out").c_str(), plan.route.size() / 2, survey_line_spacing(so.altitude_m, so.overlap, hfov),
              plan.route.front().z - plan.launch.z, plan.route.size(), length, so.speed_mps, fw == "px4" ? "PX4" : "ArduPilot",
              rtl ? ", then return to launch" : "");
  return 0;
}
