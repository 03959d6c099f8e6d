// Planner and drive stages.
#include "airground/planning/stages.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::plan {

Status PlannerStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  cfg_ = load_params(v, kPlannerFields);
  auto loaded_area = load_mission_area(v, kPlannerAreaFields, ctx.stage_name);
  if (!loaded_area) return loaded_area.error();
  const MapRect area = loaded_area.value().rect();
  const std::string where = std::string(ctx.stage_name) + ".";
  const double margin = cfg_.geofence_margin_m;
  if (!(area.x1 - area.x0 > 2 * margin) || !(area.y1 - area.y0 > 2 * margin))
    return Error::make(ErrorCode::kConfig, "config error: " + where + "geofence_margin_m (" + std::to_string(margin) +
                                               " m) leaves nothing of the mission area area_* inside the geofence");
  RoadmapParams p = load_roadmap_params(v, kMapResolutionM, kTileCells);
  p.fence = {area.x0 + margin, area.y0 + margin, area.x1 - margin, area.y1 - margin};
  map_ = std::make_unique<Roadmap>(p, ClassTable::builtin(), tiles_covering(area, kMapResolutionM, kTileCells));
  stall_ = std::make_unique<StallMarks>(load_params(v, kStallFields));
  path_ = std::make_unique<PlannedPath>();
  msg_ = std::make_unique<PlannedPathMsg>();
  replan_period_ = from_seconds(cfg_.replan_period_s);
  auto tiles = ctx.channels.ring_reader(chan::kMapTiles);
  if (!tiles) return tiles.error();
  tiles_ = tiles.value();
  auto loc = ctx.channels.latest_reader(chan::kLocalization);
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto goal = ctx.channels.latest_reader(chan::kGoal);
  if (!goal) return goal.error();
  goal_in_ = goal.value();
  auto out = ctx.channels.latest_writer(chan::kPlannedPath);
  if (!out) return out.error();
  out_ = out.value();
  return ok_status();
}

static_assert(static_cast<std::uint8_t>(PlanStatus::kStartBlocked) == kPlanStatusStartBlocked, "the localizer reads this value");

// Lifting the marks re-plans at once only when that folds in no more than this many tiles (the marks'
// own: a mark touches at most four); with the map still loading the next steps fold them in as usual.
constexpr std::size_t kLiftReplanTiles = 16;

void PlannerStage::plan_now(TimeNs now) noexcept {
  ++c_.plans;
  last_plan_ = now;
  map_changed_ = false;
  // While the localizer converges its estimate may be metres off, even inside a building: the start
  // snaps to a free cell within twice its sigma (at most initialising_snap_m), so the robot still moves
  // (the filter converges only with motion) and the route is re-planned once it tracks.
  double snap = cfg_.snap_radius_m;
  if (pose_.status != LocalizationStatus::kTracking) {
    const double sigma = std::sqrt(std::max(0.0, std::max(pose_.covariance[0], pose_.covariance[4])));
    snap = std::min(cfg_.initialising_snap_m, std::max(cfg_.snap_radius_m, 2.0 * sigma));
  }
  map_->plan(Point2{pose_.pose.x, pose_.pose.y}, Point2{goal_.goal.x, goal_.goal.y}, *path_, snap);
  // The robot's own blocked marks may have closed the only way (a one-lane track where it stood): lift
  // them and plan again at once, before the mission counts a failure. A mark diverts, it never strands.
  if (path_->status != PlanStatus::kOk && path_->status != PlanStatus::kStartOutside && path_->status != PlanStatus::kGoalOutside &&
      stall_->lift_all(*map_)) {
    if (map_->pending_tiles() <= kLiftReplanTiles) {
      map_->update();
      map_->plan(Point2{pose_.pose.x, pose_.pose.y}, Point2{goal_.goal.x, goal_.goal.y}, *path_, snap);
    }
  }
  if (path_->status == PlanStatus::kOk && path_->start_escaped && c_.start_escapes++ % 50 == 0)
    AG_LOG_INFO("planner", "no free cell within %.1f m of the start (%.1f, %.1f): the route starts across the grass to the nearest one (%llu such routes)",
                snap, pose_.pose.x, pose_.pose.y, static_cast<unsigned long long>(c_.start_escapes));
  add_work(1.0);  // one route planned (compute-time model)
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
    // A map still being loaded (tiles queued for the roadmap) explains most early failures: say so, so
    // a start-up "no free cell near the goal" is not read as a wrong goal. It is re-planned anyway.
    if (c_.plans_failed == 1 || c_.plans_failed % 50 == 0) {
      if (const std::size_t pending = map_->pending_tiles(); pending > 0)
        AG_LOG_INFO("planner", "goal %u at (%.1f, %.1f): %s while the map loads (%zu tiles queued; %llu failures)", goal_.id, goal_.goal.x,
                    goal_.goal.y, to_string(path_->status), pending, static_cast<unsigned long long>(c_.plans_failed));
      else
        AG_LOG_WARN("planner", "goal %u at (%.1f, %.1f): %s (%llu failures)", goal_.id, goal_.goal.x, goal_.goal.y, to_string(path_->status),
                    static_cast<unsigned long long>(c_.plans_failed));
    }
  }
  out_.publish(m);
}

void PlannerStage::step(TimeNs now) noexcept {
  for (MapTileMsg* t = tiles_.front(); t != nullptr; t = tiles_.front()) {
    ++c_.tiles_in;
    const TileExtent& e = map_->extent();
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
  if (map_->pending_tiles() > 0 && map_->update(static_cast<std::size_t>(cfg_.tiles_per_step)) > 0) map_changed_ = true;
  if (loc_.fresh()) {
    pose_ = loc_.read();
    have_pose_ = (pose_.status == LocalizationStatus::kTracking || (cfg_.plan_while_initialising && pose_.status == LocalizationStatus::kInitialising)) &&
                 std::isfinite(pose_.pose.x) && std::isfinite(pose_.pose.y);
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
  // Standing on the route: the ground ahead is marked blocked (folded in by update() like a changed tile).
  const bool following = have_goal_ && have_pose_ && pose_.status == LocalizationStatus::kTracking && msg_->status == RouteStatus::kOk;
  const std::span<const Point2> route(path_->points.data(), path_->status == PlanStatus::kOk ? path_->count : 0U);
  if (stall_->observe(pose_.pose, Point2{goal_.goal.x, goal_.goal.y}, following, now, *map_, route)) {
    ++c_.stalls;
    map_changed_ = true;  // re-plan soon (a widening rebuilt the roadmap at once: no tile is pending)
  }
  stall_->expire(now, *map_);
  if (have_goal_ && have_pose_ && (now - last_plan_ >= replan_period_ || (map_changed_ && now - last_plan_ >= replan_period_ / 4)))
    plan_now(now);
}

Status DriveStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  follow_ = std::make_unique<PathFollower>(load_drive_params(v));
  path_ = std::make_unique<PlannedPathMsg>();
  pts_ = std::make_unique<std::array<Point2, kMaxPathPoints>>();
  cfg_ = load_params(v, kDriveStageFields);
  pose_timeout_ = from_seconds(cfg_.pose_timeout_s);
  local_timeout_ = from_seconds(cfg_.local_goal_timeout_s);
  reflex_hold_ = from_seconds(cfg_.reflex_turn_after_s);
  auto lg = ctx.channels.latest_reader(chan::kLocalGoal);
  if (!lg) return lg.error();
  local_in_ = lg.value();
  auto p = ctx.channels.latest_reader(chan::kPlannedPath);
  if (!p) return p.error();
  path_in_ = p.value();
  auto loc = ctx.channels.latest_reader(chan::kLocalization);
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto out = ctx.channels.latest_writer(chan::kWheelCommand);
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
      blocked_ = false;
      if (path_->status == RouteStatus::kOk && path_->count >= 2) {
        n_pts_ = std::min<std::uint32_t>(path_->count, static_cast<std::uint32_t>(kMaxPathPoints));
        for (std::uint32_t i = 0; i < n_pts_; ++i) (*pts_)[i] = Point2{path_->points[i].x, path_->points[i].y};
        follow_->set_path(pts_->data(), n_pts_);
        have_path_ = true;
      } else {
        follow_->clear();
        have_path_ = false;
        n_pts_ = 0;
      }
    }
  }
  if (loc_.fresh()) pose_ = loc_.read();
  if (local_in_.fresh()) local_ = local_in_.read();
  const bool tracking = pose_.status == LocalizationStatus::kTracking;
  const bool converging = pose_.status == LocalizationStatus::kInitialising && cfg_.initialising_speed_mps > 0;
  // Lost: the localizer dead-reckons from its last good pose; go on along the route slowly for a while.
  if (pose_.status != LocalizationStatus::kLost) {
    coasting_ = false;
    coast_m_ = 0.0;
  } else if (!coasting_) {
    coasting_ = true;
    coast_last_ = pose_.pose;
  } else {
    coast_m_ += std::hypot(pose_.pose.x - coast_last_.x, pose_.pose.y - coast_last_.y);
    coast_last_ = pose_.pose;
  }
  const bool coasting = coasting_ && cfg_.lost_speed_mps > 0 && coast_m_ < cfg_.lost_coast_m;
  const bool pose_ok = (tracking || converging || coasting) && now - pose_.stamp <= pose_timeout_;
  const double top_speed = tracking ? 1e9 : converging ? cfg_.initialising_speed_mps : cfg_.lost_speed_mps;
  const bool local_ok = local_.stamp > 0 && now - local_.stamp <= local_timeout_ && (local_.path_seq == path_seq_ || local_.reflex_stop);
  TwistCommand tw;
  if (local_ok && local_.reflex_stop) {
    if (cmd_.v_mps > 0.0) ++reflex_stops_;
    // Nothing forward; a turn on the spot toward the tracker's goal is allowed (the way it found around
    // the obstacle, or back along the route when it backs up).
    const Point2 lg{local_.goal.x, local_.goal.y};
    if (reflex_since_ < 0) reflex_since_ = now;
    const bool can_turn = have_path_ && pose_ok && !blocked_ && local_.valid && std::isfinite(lg.x) && std::isfinite(lg.y) &&
                          now - reflex_since_ >= reflex_hold_;  // first a standstill
    tw = can_turn ? follow_->turn_toward(pose_.pose, lg, dt) : follow_->halt();
  } else {
    reflex_since_ = -1;
    if (local_ok && local_.state == static_cast<std::uint8_t>(TrackState::kFailed)) blocked_ = true;  // until a new route
    const Point2 lg{local_.goal.x, local_.goal.y};
    const bool steer = cfg_.steer_to_local_goal && local_ok && local_.valid && std::isfinite(lg.x) && std::isfinite(lg.y);
    tw = (have_path_ && pose_ok && !blocked_) ? follow_->step(pose_.pose, dt, top_speed, steer ? &lg : nullptr)
                                              : follow_->stop(dt);
  }
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

Status TrackerStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  const LocalTrackerParams p = load_params(v, kTrackerFields);
  if (p.overhang_m <= p.obstacle_min_m)
    return Error::make(ErrorCode::kConfig, "config error: " + std::string(ctx.stage_name) + ".overhang_m must be above obstacle_min_m");
  tracker_ = std::make_unique<LocalTracker>(p);
  path_ = std::make_unique<PlannedPathMsg>();
  pts_ = std::make_unique<std::array<Point2, kMaxPathPoints>>();
  auto sc = ctx.channels.ring_reader(chan::kLidarScan);
  if (!sc) return sc.error();
  scans_ = sc.value();
  auto loc = ctx.channels.latest_reader(chan::kLocalization);
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto pin = ctx.channels.latest_reader(chan::kPlannedPath);
  if (!pin) return pin.error();
  path_in_ = pin.value();
  auto cin = ctx.channels.latest_reader(chan::kWheelCommand);
  if (!cin) return cin.error();
  cmd_in_ = cin.value();
  auto out = ctx.channels.latest_writer(chan::kLocalGoal);
  if (!out) return out.error();
  out_ = out.value();
  return ok_status();
}

void TrackerStage::step(TimeNs now) noexcept {
  if (path_in_.fresh()) {
    *path_ = path_in_.read();
    if (path_->seq != path_seq_) {
      path_seq_ = path_->seq;
      const std::uint32_t n = path_->status == RouteStatus::kOk ? std::min<std::uint32_t>(path_->count, static_cast<std::uint32_t>(kMaxPathPoints)) : 0U;
      for (std::uint32_t i = 0; i < n; ++i) (*pts_)[i] = Point2{path_->points[i].x, path_->points[i].y};
      tracker_->set_path(std::span<const Point2>(pts_->data(), n));
    }
  }
  if (loc_.fresh()) pose_ = loc_.read();
  if (cmd_in_.fresh()) cmd_ = cmd_in_.read();
  // The newest scan only: an older one describes where the robot was.
  // (front() before every pop(): the ring's consumer side learns the writer's position only there.)
  LidarScanMsg* newest = scans_.front();
  while (newest != nullptr && scans_.size() > 1) {
    scans_.pop();
    newest = scans_.front();
  }
  if (newest == nullptr) return;
  ++scans_in_;
  if (newest->count > newest->points.size()) {
    ++scans_malformed_;
    scans_.pop();
    return;
  }
  if (pose_.status == LocalizationStatus::kTracking || pose_.status == LocalizationStatus::kInitialising ||
      pose_.status == LocalizationStatus::kLost) {  // lost: the dead-reckoned pose, which the drive coasts on
    add_work(1.0);  // one scan tracked (compute-time model)
    (void)tracker_->update(std::span<const ScanReturn>(newest->points.data(), newest->count), newest->sensor_in_body, pose_.pose, cmd_.v_mps);
    const LocalGoal g = tracker_->local_goal(pose_.pose, now);
    msg_.valid = g.valid;
    msg_.goal = RoutePoint{g.goal.x, g.goal.y};
    msg_.clearance_m = g.clearance_m;
    msg_.reflex_stop = g.reflex_stop;
  } else {
    msg_.valid = false;
    msg_.reflex_stop = false;
  }
  msg_.stamp = newest->stamp;
  msg_.published = now;
  msg_.state = static_cast<std::uint8_t>(tracker_->state());
  msg_.path_seq = path_seq_;
  msg_.failures = tracker_->failures();
  out_.publish(msg_);
  scans_.pop();
}

}  // namespace ag::plan
