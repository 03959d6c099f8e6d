// Planner and drive stages.
#include "airground/planning/stages.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "airground/platform/log.hpp"

namespace ag::plan {

Status PlannerStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  const double x0 = v.real("area_x0_m"), y0 = v.real("area_y0_m"), x1 = v.real("area_x1_m"), y1 = v.real("area_y1_m");
  const std::string where = std::string(ctx.stage_name) + ".";
  if (!(x1 > x0) || !(y1 > y0))
    return Error::make(ErrorCode::kConfig, "config error: " + where + "area_x1_m/area_y1_m must be east/north of area_x0_m/area_y0_m");
  const RoadmapParams p = load_roadmap_params(v, kMapResolutionM, kTileCells);
  map_ = std::make_unique<Roadmap>(p, ClassTable::builtin(), extent_covering_area(x0, y0, x1, y1, kMapResolutionM, kTileCells));
  path_ = std::make_unique<PlannedPath>();
  msg_ = std::make_unique<PlannedPathMsg>();
  tiles_per_step_ = static_cast<std::size_t>(v.integer("tiles_per_step"));
  replan_period_ = from_seconds(v.real("replan_period_s"));
  snap_ = v.real("snap_radius_m");
  auto tiles = ctx.channels.ring_reader<MapTileMsg, kMapTileRing>("map_tiles");
  if (!tiles) return tiles.error();
  tiles_ = tiles.value();
  auto loc = ctx.channels.latest_reader<LocalizationMsg>("localization");
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto goal = ctx.channels.latest_reader<GoalMsg>("goal");
  if (!goal) return goal.error();
  goal_in_ = goal.value();
  auto out = ctx.channels.latest_writer<PlannedPathMsg>("planned_path");
  if (!out) return out.error();
  out_ = out.value();
  return ok_status();
}

void PlannerStage::plan_now(TimeNs now) noexcept {
  ++c_.plans;
  last_plan_ = now;
  map_changed_ = false;
  map_->plan(Point2{pose_.pose.x, pose_.pose.y}, Point2{goal_.goal.x, goal_.goal.y}, *path_, snap_);
  PlannedPathMsg& m = *msg_;
  m.stamp = pose_.stamp;
  m.published = now;
  m.seq = ++seq_;
  m.goal_id = goal_.id;
  m.plan_status = static_cast<std::uint8_t>(path_->status);
  if (path_->status == PlanStatus::kOk) {
    m.status = RouteStatus::kOk;
    m.count = std::min<std::uint32_t>(path_->count, static_cast<std::uint32_t>(kMaxRoutePoints));
    for (std::uint32_t i = 0; i < m.count; ++i) m.points[i] = RoutePoint{path_->points[i].x, path_->points[i].y};
    m.length_m = path_->length_m;
    m.min_clearance_m = path_->min_clearance_m;
  } else {
    ++c_.plans_failed;
    m.status = path_->status == PlanStatus::kNoRoute ? RouteStatus::kNoRoute : RouteStatus::kBadEnds;
    m.count = 0;
    m.length_m = 0;
    if (c_.plans_failed == 1 || c_.plans_failed % 50 == 0)
      AG_LOG_WARN("planner", "goal %u at (%.1f, %.1f): %s (%llu failures)", goal_.id, goal_.goal.x, goal_.goal.y, to_string(path_->status),
                  static_cast<unsigned long long>(c_.plans_failed));
  }
  out_.publish(m);
}

void PlannerStage::step(TimeNs now) noexcept {
  for (MapTileMsg* t = tiles_.front(); t != nullptr; t = tiles_.front()) {
    ++c_.tiles_in;
    const MapExtent& e = map_->extent();
    if (t->tx < e.tile_x0 || t->ty < e.tile_y0 || t->tx >= e.tile_x0 + e.tiles_x || t->ty >= e.tile_y0 + e.tiles_y) {
      if (c_.tiles_outside++ == 0)
        AG_LOG_WARN("planner", "map tile (%d, %d) is outside the mission area (planner.area_*): dropped (counted)", static_cast<int>(t->tx),
                    static_cast<int>(t->ty));
    } else if (map_->set_tile(t->tx, t->ty, t->version, std::span<const std::uint8_t>(t->cls.data(), t->cls.size()))) {
      ++c_.tiles_applied;
    } else {
      ++c_.tiles_stale;
    }
    tiles_.pop();
  }
  if (map_->pending_tiles() > 0 && map_->update(tiles_per_step_) > 0) map_changed_ = true;
  if (loc_.fresh()) {
    pose_ = loc_.read();
    have_pose_ = pose_.status == LocalizationStatus::kTracking && std::isfinite(pose_.pose.x) && std::isfinite(pose_.pose.y);
  }
  if (goal_in_.fresh()) {
    const GoalMsg& g = goal_in_.read();
    if (g.stamp != goal_stamp_) {
      goal_stamp_ = g.stamp;
      ++c_.goals;
      if (g.cancel) {
        have_goal_ = false;
        msg_->seq = ++seq_;
        msg_->status = RouteStatus::kCancelled;
        msg_->count = 0;
        msg_->published = now;
        out_.publish(*msg_);
      } else if (!std::isfinite(g.goal.x) || !std::isfinite(g.goal.y)) {
        ++c_.goals_non_finite;
      } else {
        goal_ = g;
        have_goal_ = true;
        if (have_pose_) plan_now(now);
        else last_plan_ = 0;
      }
    }
  }
  if (have_goal_ && have_pose_ && (now - last_plan_ >= replan_period_ || (map_changed_ && now - last_plan_ >= replan_period_ / 4)))
    plan_now(now);
}

Status DriveStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  follow_ = std::make_unique<PathFollower>(load_drive_params(v));
  path_ = std::make_unique<PlannedPathMsg>();
  pts_ = std::make_unique<std::array<Point2, kMaxPathPoints>>();
  pose_timeout_ = from_seconds(v.real("pose_timeout_s"));
  auto p = ctx.channels.latest_reader<PlannedPathMsg>("planned_path");
  if (!p) return p.error();
  path_in_ = p.value();
  auto loc = ctx.channels.latest_reader<LocalizationMsg>("localization");
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto out = ctx.channels.latest_writer<WheelCommandMsg>("wheel_command");
  if (!out) return out.error();
  out_ = out.value();
  return ok_status();
}

void DriveStage::step(TimeNs now) noexcept {
  const double dt = last_ < 0 ? 0.0 : to_seconds(now - last_);
  last_ = now;
  if (path_in_.fresh()) {
    *path_ = path_in_.read();
    if (path_->seq != path_seq_) {
      path_seq_ = path_->seq;
      if (path_->status == RouteStatus::kOk && path_->count >= 2) {
        const std::uint32_t n = std::min<std::uint32_t>(path_->count, static_cast<std::uint32_t>(kMaxPathPoints));
        for (std::uint32_t i = 0; i < n; ++i) (*pts_)[i] = Point2{path_->points[i].x, path_->points[i].y};
        follow_->set_path(pts_->data(), n);
        have_path_ = true;
      } else {
        follow_->clear();
        have_path_ = false;
      }
    }
  }
  if (loc_.fresh()) pose_ = loc_.read();
  const bool pose_ok = pose_.status == LocalizationStatus::kTracking && now - pose_.stamp <= pose_timeout_;
  const TwistCommand tw = (have_path_ && pose_ok) ? follow_->step(pose_.pose, dt) : follow_->stop(dt);
  const DriveParams& dp = follow_->params();
  const WheelSpeeds ws = wheels_from_twist(tw.v_mps, tw.w_radps, dp.track_m, dp.max_wheel_speed_mps);
  cmd_.stamp = now;
  cmd_.published = now;
  cmd_.left_mps = ws.left_mps;
  cmd_.right_mps = ws.right_mps;
  cmd_.v_mps = tw.v_mps;
  cmd_.w_radps = tw.w_radps;
  cmd_.follow_state = static_cast<std::uint8_t>(follow_->state());
  out_.publish(cmd_);
}

}  // namespace ag::plan
