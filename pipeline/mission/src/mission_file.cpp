// Loading and validating the mission file.
#include "airground/mission/mission_file.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <type_traits>

#include "airground/mission/stages.hpp"
#include "airground/platform/param_binding.hpp"

namespace ag::mission {

namespace {
constexpr double kPi = 3.14159265358979323846;

struct Ctx {
  std::string origin;
  Error err(const YAML::Node& n, const std::string& key, const std::string& what) const {
    const int line = n.IsDefined() && n.Mark().line >= 0 ? n.Mark().line + 1 : 0;
    return Error::make(ErrorCode::kConfig, "mission file " + origin + (line > 0 ? ":" + std::to_string(line) : "") + ": " + key + ": " + what);
  }
};

// Reads a scalar; false (with err set) when the type is wrong or the value outside [lo, hi].
template <typename T>
bool get(const Ctx& c, const YAML::Node& parent, const char* key, const std::string& path, T& out, bool required, double lo, double hi,
         Error& err) {
  const YAML::Node n = parent[key];
  if (!n.IsDefined() || n.IsNull()) {
    if (required) err = c.err(parent, path + key, "missing (required)");
    return !required;
  }
  if (!n.IsScalar()) {
    err = c.err(n, path + key, "must be a number");
    return false;
  }
  try {
    out = n.as<T>();
  } catch (const YAML::Exception&) {
    err = c.err(n, path + key, "'" + n.Scalar() + "' is not a number");
    return false;
  }
  const double v = static_cast<double>(out);
  if (!std::isfinite(v) || v < lo || v > hi) {
    std::ostringstream s;
    s << n.Scalar() << " outside [" << lo << ", " << hi << "]";
    err = c.err(n, path + key, s.str());
    return false;
  }
  return true;
}

// A mission parameter a stage owns: its range is that stage's own spec row (type checked by T).
template <typename T>
bool get_stage_param(const Ctx& c, const YAML::Node& parent, std::span<const ParamSpec> rows, const char* key, T& out, Error& err) {
  const ParamSpec* row = find_param(rows, key);
  const ParamType want = std::is_integral_v<T> ? ParamType::kInt : ParamType::kReal;
  if (row == nullptr || row->type != want) {
    err = c.err(parent, std::string("parameters.") + key, "not a parameter of its stage (a build error)");
    return false;
  }
  return get(c, parent, key, "parameters.", out, false, row->min, row->max, err);
}

void check_keys(const Ctx& c, const YAML::Node& n, const std::string& path, std::initializer_list<const char*> known, Error& err, bool& bad) {
  if (bad || !n.IsMap()) return;
  for (const auto& kv : n) {
    const std::string k = kv.first.as<std::string>();
    bool ok = false;
    for (const char* s : known) ok = ok || k == s;
    if (!ok) {
      std::string list;
      for (const char* s : known) list += std::string(list.empty() ? "" : ", ") + s;
      err = c.err(kv.first, path + k, "unknown key (known: " + list + ")");
      bad = true;
      return;
    }
  }
}
bool get_area(const Ctx& c, const YAML::Node& n, const std::string& path, Area& a, Error& err) {
  if (!n.IsMap()) {
    err = c.err(n, path, "must be a map {x0, y0, x1, y1}");
    return false;
  }
  bool bad = false;
  check_keys(c, n, path + ".", {"x0", "y0", "x1", "y1"}, err, bad);
  if (bad) return false;
  const double L = 1e6;
  if (!get(c, n, "x0", path + ".", a.x0, true, -L, L, err) || !get(c, n, "y0", path + ".", a.y0, true, -L, L, err) ||
      !get(c, n, "x1", path + ".", a.x1, true, -L, L, err) || !get(c, n, "y1", path + ".", a.y1, true, -L, L, err))
    return false;
  if (!(a.x1 > a.x0) || !(a.y1 > a.y0)) {
    err = c.err(n, path, "x1/y1 must be east/north of x0/y0");
    return false;
  }
  return true;
}

bool get_xy(const Ctx& c, const YAML::Node& n, const std::string& path, std::size_t min_len, double* v, Error& err) {
  if (!n.IsSequence() || n.size() < min_len || n.size() > 3) {
    err = c.err(n, path, min_len == 3 ? "must be [x, y, yaw]" : "must be [x, y] or [x, y, yaw]");
    return false;
  }
  for (std::size_t i = 0; i < n.size(); ++i) {
    try {
      v[i] = n[i].as<double>();
    } catch (const YAML::Exception&) {
      err = c.err(n[i], path, "'" + (n[i].IsScalar() ? n[i].Scalar() : std::string("?")) + "' is not a number");
      return false;
    }
    if (!std::isfinite(v[i]) || std::fabs(v[i]) > 1e6) {
      err = c.err(n[i], path, "value outside [-1e6, 1e6]");
      return false;
    }
  }
  return true;
}

bool get_points(const Ctx& c, const YAML::Node& n, const std::string& path, std::vector<XY>& out, Error& err) {
  if (!n.IsSequence()) {
    err = c.err(n, path, "must be a list of [x, y]");
    return false;
  }
  for (std::size_t i = 0; i < n.size(); ++i) {
    double v[3] = {0, 0, 0};
    if (!get_xy(c, n[i], path + "[" + std::to_string(i) + "]", 2, v, err)) return false;
    out.push_back(XY{v[0], v[1]});
  }
  return true;
}

}  // namespace

double Survey::spacing_m() const noexcept {
  if (line_spacing_m > 0) return line_spacing_m;
  const double footprint = 2.0 * altitude_m * std::tan(0.5 * camera_hfov_deg * kPi / 180.0);
  return std::max(1.0, (1.0 - overlap) * footprint);
}

const TeamMember* MissionFile::member(int id) const noexcept {
  for (const TeamMember& m : team)
    if (m.id == id) return &m;
  return nullptr;
}

Result<MissionFile> load_mission_string(std::string_view yaml, std::string_view origin) {
  Ctx c{std::string(origin)};
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml));
  } catch (const YAML::Exception& e) {
    return Error::make(ErrorCode::kConfig, "mission file " + c.origin + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
  if (!root.IsMap()) return c.err(root, "(top level)", "must be a map (mission, datum, area, team, ...)");
  Error err = Error::make(ErrorCode::kConfig, "");
  bool bad = false;
  check_keys(c, root, "", {"mission", "datum", "area", "team", "targets", "parameters", "survey"}, err, bad);
  if (bad) return err;
  MissionFile f;

  const YAML::Node m = root["mission"];
  if (m.IsDefined()) {
    check_keys(c, m, "mission.", {"name", "type"}, err, bad);
    if (bad) return err;
    if (m["name"].IsDefined()) f.name = m["name"].as<std::string>("");
    if (m["type"].IsDefined()) {
      const std::string t = m["type"].IsScalar() ? m["type"].Scalar() : "";
      if (t == "regions")
        f.type = MissionType::kRegions;
      else if (t == "waypoints")
        f.type = MissionType::kWaypoints;
      else
        return c.err(m["type"], "mission.type", "'" + t + "' is not one of regions|waypoints");
    }
  }

  const YAML::Node d = root["datum"];
  if (!d.IsDefined()) return c.err(root, "datum", "missing (required: {lat, lon, alt})");
  if (!d.IsMap()) return c.err(d, "datum", "must be a map {lat, lon, alt}");
  check_keys(c, d, "datum.", {"lat", "lon", "alt"}, err, bad);
  if (bad) return err;
  if (!get(c, d, "lat", "datum.", f.lat_deg, true, -90, 90, err) || !get(c, d, "lon", "datum.", f.lon_deg, true, -180, 180, err) ||
      !get(c, d, "alt", "datum.", f.alt_m, false, -500, 9000, err))
    return err;

  if (!root["area"].IsDefined()) return c.err(root, "area", "missing (required: {x0, y0, x1, y1})");
  if (!get_area(c, root["area"], "area", f.area, err)) return err;

  const YAML::Node team = root["team"];
  if (!team.IsDefined()) return c.err(root, "team", "missing (required: a list of robots)");
  if (!team.IsSequence() || team.size() == 0) return c.err(team, "team", "must be a non-empty list of {id, priority, start, ...}");
  std::set<int> ids, prios;
  for (std::size_t i = 0; i < team.size(); ++i) {
    const YAML::Node t = team[i];
    const std::string p = "team[" + std::to_string(i) + "].";
    if (!t.IsMap()) return c.err(t, "team[" + std::to_string(i) + "]", "must be a map {id, priority, start, ...}");
    check_keys(c, t, p, {"id", "priority", "start", "initial_guess", "initial_sigma_m", "waypoints"}, err, bad);
    if (bad) return err;
    TeamMember tm;
    if (!get(c, t, "id", p, tm.id, true, 1, 199, err)) return err;
    tm.priority = tm.id;
    if (!get(c, t, "priority", p, tm.priority, false, 0, 255, err)) return err;
    if (!ids.insert(tm.id).second) return c.err(t["id"], p + "id", "duplicate robot id " + std::to_string(tm.id));
    if (!prios.insert(tm.priority).second)
      return c.err(t["priority"].IsDefined() ? t["priority"] : t, p + "priority", "duplicate priority " + std::to_string(tm.priority) + " (a clash needs a winner)");
    if (!t["start"].IsDefined()) return c.err(t, p + "start", "missing (required: [x, y, yaw])");
    double s[3] = {0, 0, 0};
    if (!get_xy(c, t["start"], p + "start", 2, s, err)) return err;
    tm.start_x = s[0];
    tm.start_y = s[1];
    tm.start_yaw = s[2];
    double g[3] = {s[0], s[1], s[2]};
    if (t["initial_guess"].IsDefined() && !get_xy(c, t["initial_guess"], p + "initial_guess", 2, g, err)) return err;
    tm.guess_x = g[0];
    tm.guess_y = g[1];
    tm.guess_yaw = g[2];
    if (!get(c, t, "initial_sigma_m", p, tm.guess_sigma_m, false, 0.1, 1000, err)) return err;
    if (t["waypoints"].IsDefined() && !get_points(c, t["waypoints"], p + "waypoints", tm.waypoints, err)) return err;
    f.team.push_back(std::move(tm));
  }

  if (root["targets"].IsDefined() && !get_points(c, root["targets"], "targets", f.targets, err)) return err;
  if (f.type == MissionType::kWaypoints) {
    bool any = false;
    for (const TeamMember& tm : f.team) any = any || !tm.waypoints.empty();
    if (!any) return c.err(team, "team[].waypoints", "a waypoints mission needs waypoints for at least one robot");
  }

  const YAML::Node pm = root["parameters"];
  if (pm.IsDefined()) {
    if (!pm.IsMap()) return c.err(pm, "parameters", "must be a map");
    check_keys(c, pm, "parameters.",
               {"visit_radius_m", "max_sigma_m", "claim_timeout_s", "idle_return_s", "mission_end_s", "survey_end_s", "merge_distance_m",
                "min_region_cells", "comm_range_m"},
               err, bad);
    if (bad) return err;
    MissionParameters& q = f.params;
    const std::string pp = "parameters.";
    const std::span<const ParamSpec> ms = MissionStage::kParams, rs = RegionsStage::kParams;
    if (!get_stage_param(c, pm, ms, "visit_radius_m", q.visit_radius_m, err) || !get_stage_param(c, pm, ms, "max_sigma_m", q.max_sigma_m, err) ||
        !get_stage_param(c, pm, ms, "claim_timeout_s", q.claim_timeout_s, err) ||
        !get_stage_param(c, pm, ms, "idle_return_s", q.idle_return_s, err) ||
        !get_stage_param(c, pm, ms, "mission_end_s", q.mission_end_s, err) ||
        !get_stage_param(c, pm, ms, "survey_end_s", q.survey_end_s, err) ||
        !get_stage_param(c, pm, rs, "merge_distance_m", q.merge_distance_m, err) ||
        !get_stage_param(c, pm, rs, "min_region_cells", q.min_region_cells, err) ||
        !get(c, pm, "comm_range_m", pp, q.comm_range_m, false, 0, 1e6, err))  // the simulator's, no stage's
      return err;
  }

  f.survey.area = f.area;
  const YAML::Node sv = root["survey"];
  if (sv.IsDefined()) {
    if (!sv.IsMap()) return c.err(sv, "survey", "must be a map");
    check_keys(c, sv, "survey.", {"robot", "pattern", "altitude_m", "speed_mps", "line_spacing_m", "overlap", "camera_hfov_deg", "heading_deg", "area",
                                  "return_home"},
               err, bad);
    if (bad) return err;
    Survey& s = f.survey;
    const std::string sp = "survey.";
    if (sv["pattern"].IsDefined()) {
      s.pattern = sv["pattern"].IsScalar() ? sv["pattern"].Scalar() : "";
      if (s.pattern != "lawnmower") return c.err(sv["pattern"], "survey.pattern", "'" + s.pattern + "' is not one of lawnmower");
    }
    if (!get(c, sv, "robot", sp, s.robot, false, 0, 254, err) || !get(c, sv, "altitude_m", sp, s.altitude_m, false, 5, 500, err) ||
        !get(c, sv, "speed_mps", sp, s.speed_mps, false, 0.5, 30, err) ||
        !get(c, sv, "line_spacing_m", sp, s.line_spacing_m, false, 0, 1000, err) ||
        !get(c, sv, "overlap", sp, s.overlap, false, 0, 0.95, err) ||
        !get(c, sv, "camera_hfov_deg", sp, s.camera_hfov_deg, false, 5, 170, err) ||
        !get(c, sv, "heading_deg", sp, s.heading_deg, false, -360, 360, err))
      return err;
    if (sv["area"].IsDefined() && !get_area(c, sv["area"], "survey.area", s.area, err)) return err;
    if (const YAML::Node rh = sv["return_home"]; rh.IsDefined()) {
      const std::string t = rh.IsScalar() ? rh.Scalar() : "";
      if (t != "true" && t != "false") return c.err(rh, "survey.return_home", "'" + t + "' is not true or false");
      s.return_home = t == "true";
    }
    if (f.member(s.robot) != nullptr) return c.err(sv["robot"], "survey.robot", "robot " + std::to_string(s.robot) + " is a ground robot of the team");
  }
  return f;
}

Result<MissionFile> load_mission_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kConfig, "mission file " + path + ": cannot be read");
  std::ostringstream s;
  s << in.rdbuf();
  return load_mission_string(s.str(), path);
}

std::vector<XY> survey_waypoints(const Survey& s) {
  std::vector<XY> out;
  const double sp = s.spacing_m();
  const double h = s.heading_deg * kPi / 180.0;
  const double ux = std::cos(h), uy = std::sin(h);  // along the lines
  const double vx = -uy, vy = ux;                   // across
  const double cx = 0.5 * (s.area.x0 + s.area.x1), cy = 0.5 * (s.area.y0 + s.area.y1);
  // extent of the area along u and v (the rectangle's corners projected)
  double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
  for (double x : {s.area.x0, s.area.x1})
    for (double y : {s.area.y0, s.area.y1}) {
      const double u = (x - cx) * ux + (y - cy) * uy, v = (x - cx) * vx + (y - cy) * vy;
      umin = std::min(umin, u);
      umax = std::max(umax, u);
      vmin = std::min(vmin, v);
      vmax = std::max(vmax, v);
    }
  const double width = vmax - vmin;
  const int lines = std::max(1, static_cast<int>(std::ceil(width / sp)));
  const double first = vmin + 0.5 * (width - (lines - 1) * sp);
  for (int i = 0; i < lines; ++i) {
    const double v = first + i * sp;
    const double ua = (i % 2 == 0) ? umin : umax, ub = (i % 2 == 0) ? umax : umin;
    out.push_back(XY{cx + ua * ux + v * vx, cy + ua * uy + v * vy});
    out.push_back(XY{cx + ub * ux + v * vx, cy + ub * uy + v * vy});
  }
  return out;
}

}  // namespace ag::mission
