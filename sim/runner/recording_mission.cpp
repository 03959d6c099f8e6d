// recording.mcap's mission channels: planned paths, regions with their claims and visits, mission events.
#include "recording_mission.hpp"

#include <algorithm>
#include <cstdio>

#include "airground/drivers/recording/mcap/foxglove_json.hpp"
#include "airground/mission/stages.hpp"
#include "airground/planning/stages.hpp"
#include "airground/platform/role_instance.hpp"

namespace ag::sim {
namespace fg = ag::foxglove;

namespace {

std::uint64_t ns(TimeNs t) { return t < 0 ? 0u : static_cast<std::uint64_t>(t); }
std::string robot_name(std::size_t i) { return "ugv" + std::to_string(i + 1); }
fg::Color robot_color(std::size_t i) {
  static constexpr fg::Color kColors[] = {{1.0, 0.55, 0.0, 1}, {0.2, 0.5, 1.0, 1}, {0.75, 0.3, 0.9, 1}, {0.9, 0.2, 0.3, 1}, {0.1, 0.75, 0.7, 1}};
  return kColors[i % std::size(kColors)];
}
std::string xy(double x, double y) {
  char b[64];
  std::snprintf(b, sizeof b, "(%.1f, %.1f)", x, y);
  return b;
}
void add_name(std::string& list, const std::string& name) { list += (list.empty() ? "" : "+") + name; }

}  // namespace

void MissionRecorder::watch(RoleInstance* uav, std::vector<RoleInstance*> ugvs) {
  uav_ = uav;
  ugvs_ = std::move(ugvs);
  const std::size_t n = std::max(ugvs_.size(), ch_.paths.size());
  planner_seq_.assign(n, 0);
  routes_.assign(n, {});
  states_.assign(n, {-1, mission::kNoRegion});
  visits_seen_.assign(n, 0);
}

void MissionRecorder::write_path(TimeNs now, int i, const std::vector<Eigen::Vector2d>& path) {
  const auto k = static_cast<std::size_t>(i);
  fg::SceneEntity e;
  e.id = robot_name(k) + "/path";
  e.frame_id = "map";
  fg::LineStrip l;
  l.color = robot_color(k);
  l.thickness = 0.4;
  for (const Eigen::Vector2d& p : path) l.points.push_back({p.x(), p.y(), kSceneZ});
  if (!l.points.empty()) e.lines.push_back(std::move(l));  // an empty entity: no route (the old one is replaced)
  put_(ch_.paths[k], now, fg::scene_update(ns(now), {e}));
}

void MissionRecorder::route(TimeNs now, int i, const std::vector<Eigen::Vector2d>& path) {
  const auto k = static_cast<std::size_t>(i);
  if (k >= ch_.paths.size() || ch_.paths[k] == 0 || k >= routes_.size() || routes_[k] == path) return;
  routes_[k] = path;
  write_path(now, i, path);
}

void MissionRecorder::event(TimeNs now, const std::string& robot, bool warning, const std::string& text) {
  if (ch_.events != 0) put_(ch_.events, now, fg::log(ns(now), warning ? fg::LogLevel::kWarning : fg::LogLevel::kInfo, robot, robot + ": " + text));
}

void MissionRecorder::tick(TimeNs now) {
  if (now < next_) return;
  next_ = now + kNsPerS;
  std::map<std::uint32_t, RegionView> regions;
  if (const auto* rs = find_stage<const mission::RegionsStage>(uav_)) {
    const mission::RegionsMsg& m = rs->published();
    for (std::uint32_t k = 0; k < std::min<std::uint32_t>(m.count, static_cast<std::uint32_t>(m.regions.size())); ++k) {
      const mission::RegionRecord& r = m.regions[k];
      RegionView& v = regions[r.id];
      v.known = true;
      v.x = r.goal_valid ? r.goal_x : r.cx;
      v.y = r.goal_valid ? r.goal_y : r.cy;
    }
  }
  for (std::size_t i = 0; i < ugvs_.size(); ++i) {
    const std::string name = robot_name(i);
    // the planner stage's route, when the robot drives by its own stages
    if (const auto* ps = find_stage<const plan::PlannerStage>(ugvs_[i]); ps != nullptr && i < ch_.paths.size() && ch_.paths[i] != 0) {
      const PlannedPathMsg& m = ps->published();
      if (m.seq != planner_seq_[i]) {
        planner_seq_[i] = m.seq;
        std::vector<Eigen::Vector2d> path;
        if (m.status == RouteStatus::kOk)
          for (std::uint32_t k = 0; k < std::min<std::uint32_t>(m.count, static_cast<std::uint32_t>(m.points.size())); ++k) path.emplace_back(m.points[k].x, m.points[k].y);
        write_path(now, static_cast<int>(i), path);
      }
    }
    const auto* ms = find_stage<const mission::MissionStage>(ugvs_[i]);
    if (ms == nullptr) continue;
    const mission::MissionStatusMsg& st = ms->manager().status();
    const bool claiming = st.state == mission::ClaimState::kGoing || st.state == mission::ClaimState::kFailedRetrying;
    if (claiming && st.region_id != mission::kNoRegion) {
      RegionView& v = regions[st.region_id];
      add_name(v.claimed_by, name);
      if (!v.known) v.x = st.goal_x, v.y = st.goal_y;
    }
    const std::pair<int, std::uint32_t> now_state{static_cast<int>(st.state), st.region_id};
    if (now_state != states_[i]) {
      states_[i] = now_state;
      std::string text = mission::to_string(st.state);
      if (claiming && st.region_id != mission::kNoRegion) text += " region " + std::to_string(st.region_id) + " goal " + xy(st.goal_x, st.goal_y);
      event(now, name, st.state == mission::ClaimState::kFailedRetrying, text);
    }
    const mission::VisitedRecord& vis = ms->manager().own_visited();
    for (std::uint16_t k = 0; k < std::min<std::uint16_t>(vis.count, static_cast<std::uint16_t>(vis.entries.size())); ++k) {
      const mission::VisitedEntry& e = vis.entries[k];
      RegionView& v = regions[e.region_id];
      add_name(v.visited_by, name);
      v.visited = true;
      v.visit_x = e.x;
      v.visit_y = e.y;
      if (!v.known && v.claimed_by.empty()) v.x = e.x, v.y = e.y;
      if (k >= visits_seen_[i]) event(now, name, false, "visited region " + std::to_string(e.region_id) + " at " + xy(e.x, e.y));
    }
    visits_seen_[i] = std::max(visits_seen_[i], vis.count);
  }
  if (ch_.regions == 0) return;
  // One entity per region, written when what it shows changed: a sphere at its goal (grey: open, the
  // claiming robot's colour, green: visited), a label, and a small sphere where it was marked visited.
  std::vector<fg::SceneEntity> changed;
  for (const auto& [id, v] : regions) {
    std::string label = "region " + std::to_string(id);
    if (!v.claimed_by.empty()) label += ": " + v.claimed_by + " going";
    if (v.visited) label += (v.claimed_by.empty() ? ": " : ", ") + std::string("visited by ") + v.visited_by;
    const std::string shown = label + xy(v.x, v.y);
    auto [it, fresh] = written_.try_emplace(id, shown);
    if (!fresh && it->second == shown) continue;
    it->second = shown;
    fg::SceneEntity e;
    e.id = "region/" + std::to_string(id);
    e.frame_id = "map";
    fg::Color c{0.6, 0.6, 0.6, 0.8};
    if (v.visited) c = {0.1, 0.8, 0.2, 0.9};
    else if (!v.claimed_by.empty()) {
      const std::size_t robot = static_cast<std::size_t>(std::max(0, std::atoi(v.claimed_by.c_str() + 3) - 1));
      c = robot_color(robot);
    }
    e.spheres.push_back({{v.x, v.y, kSceneZ}, 2.0, c});
    if (v.visited) e.spheres.push_back({{v.visit_x, v.visit_y, kSceneZ}, 0.8, {0.1, 0.8, 0.2, 1}});
    e.texts.push_back({{v.x, v.y, kSceneZ + 2.0}, label, {1, 1, 1, 1}, 12});
    changed.push_back(std::move(e));
  }
  if (!changed.empty()) put_(ch_.regions, now, fg::scene_update(ns(now), changed));
}

}  // namespace ag::sim
