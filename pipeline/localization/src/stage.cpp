// The localization stage: channels in, SemanticLocalizer, the fused pose out.
#include "airground/localization/stage.hpp"

#include <cmath>
#include <cstdint>
#include <string>

#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::loc {

namespace {
std::uint64_t seed_from_name(std::string_view name) noexcept {
  std::uint64_t h = 1469598103934665603ULL;  // FNV-1a
  for (const char ch : name) h = (h ^ static_cast<unsigned char>(ch)) * 1099511628211ULL;
  return h;
}
bool finite(const Pose2& p) noexcept { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.yaw); }
}  // namespace

Status LocalizationStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  auto loaded_area = load_mission_area(v, kLocalizationAreaFields, ctx.stage_name);
  if (!loaded_area) return loaded_area.error();
  const MapRect area = loaded_area.value().rect();
  const std::string where = std::string(ctx.stage_name) + ".";
  LocalizerParams p = load_localizer_params(v, kMapResolutionM, kTileCells);
  p.filter.area = area;  // the robot is inside its mission area
  if (p.filter.max_particles < p.filter.min_particles)
    return Error::make(ErrorCode::kConfig, "config error: " + where + "pf_max_particles must be >= pf_min_particles");
  if (p.filter.range_bin_max_m < p.filter.range_bin_min_m)
    return Error::make(ErrorCode::kConfig, "config error: " + where + "pf_range_bin_max_m must be >= pf_range_bin_min_m");
  LocalizationStageSettings own = load_params(v, kLocalizationStageOwnParams);
  load_params(v, std::span<const ParamField<LocalizationStageSettings>>(kLocalizationLabelsParam), own);
  geometric_ = own.labels == ScanLabels::kGeometric;
  LocalizationChannels channels =
      geometric_ ? LocalizationChannels::two_class(1.0, 1.5, p.fields.obstacle_faces) : LocalizationChannels::per_class();
  if (p.filter.obstacle_penalty_per_m > 0.0 && p.filter.obstacle_traversable != Traversability::kBlocked)
    channels.add_off_route(p.filter.obstacle_traversable);  // the obstacle prior's room is the planner's free space
  if (geometric_) labeller_ = std::make_unique<GeometricLabeller>(p.label, 128, 2048);
  else labeller_ = std::make_unique<GroundTruthLabeller>();
  const TileExtent extent = tiles_covering(area, kMapResolutionM, kTileCells);
  fields_ = std::make_unique<ClassDistanceFields>(p.fields, channels, extent);
  const auto seed_param = static_cast<std::uint64_t>(own.seed);
  loc_ = std::make_unique<SemanticLocalizer>(p, channels, seed_param != 0 ? seed_param : seed_from_name(ctx.instance));
  tiles_per_step_ = static_cast<std::size_t>(own.field_tiles_per_step);

  auto scans = ctx.channels.ring_reader(chan::kLidarScan);
  if (!scans) return scans.error();
  scans_ = scans.value();
  auto odom = ctx.channels.ring_reader(chan::kWheelOdometry);
  if (!odom) return odom.error();
  odom_ = odom.value();
  auto tiles = ctx.channels.ring_reader(chan::kMapTiles);
  if (!tiles) return tiles.error();
  tiles_ = tiles.value();
  auto init = ctx.channels.latest_reader(chan::kInitialPose);
  if (!init) return init.error();
  init_ = init.value();
  ctx.channels.allow_unwritten(chan::kInitialPose);  // optional: an operator's tool or the simulator; else the config's guess
  auto path = ctx.channels.latest_reader(chan::kPlannedPath);
  if (!path) return path.error();
  path_ = path.value();
  ctx.channels.allow_unwritten(chan::kPlannedPath);  // optional: a role without a planner (eval localization)
  auto out = ctx.channels.latest_writer(chan::kLocalization);
  if (!out) return out.error();
  out_ = out.value();
  msg_ = LocalizationMsg{};
  config_init_pending_ = own.set_initial_pose;
  config_init_.pose = Pose2{own.initial_x_m, own.initial_y_m, own.initial_yaw_rad};
  config_init_.sigma_xy_m = own.initial_sigma_m;
  config_init_.sigma_yaw_rad = own.initial_sigma_yaw_rad;
  return ok_status();
}

std::size_t LocalizationStage::memory_bytes() const noexcept {
  std::size_t n = sizeof(*this) + loc_->memory_bytes() + fields_->memory_bytes();
  if (geometric_) n += static_cast<const GeometricLabeller&>(*labeller_).memory_bytes();
  return n;
}

void LocalizationStage::take_tiles() noexcept {
  for (MapTileMsg* t = tiles_.front(); t != nullptr; t = tiles_.front()) {
    ++c_.tiles_in;
    const TileExtent& e = fields_->extent();
    if (t->tx < e.tile_x0 || t->ty < e.tile_y0 || t->tx >= e.tile_x0 + e.tiles_x || t->ty >= e.tile_y0 + e.tiles_y) {
      if (c_.tiles_outside_area++ == 0)
        AG_LOG_WARN("localization", "map tile (%d, %d) is outside the mission area (localization.area_*): dropped (counted)",
                    static_cast<int>(t->tx), static_cast<int>(t->ty));
    } else if (fields_->set_tile(t->tx, t->ty, t->version, std::span<const std::uint8_t>(t->cls.data(), t->cls.size()))) {
      ++c_.tiles_applied;
      have_map_ = true;
    } else {
      ++c_.tiles_stale;
    }
    tiles_.pop();
  }
  if (fields_->pending_tiles() > 0) (void)fields_->update(tiles_per_step_);
}

void LocalizationStage::take_initial_pose() noexcept {
  if (config_init_pending_ && have_odom_) {  // once odometry gives the filter a time base
    config_init_pending_ = false;
    const InitialPoseMsg& m = config_init_;
    ++c_.initial_poses;
    have_init_ = true;
    loc_->initialise_gaussian(m.pose, m.sigma_xy_m, m.sigma_yaw_rad, last_odom_stamp_);
    AG_LOG_INFO("localization", "initial pose from the configuration (%.1f, %.1f, %.2f rad) sigma %.1f m %.2f rad", m.pose.x, m.pose.y,
                m.pose.yaw, m.sigma_xy_m, m.sigma_yaw_rad);
  }
  if (!init_.fresh()) return;
  const InitialPoseMsg& m = init_.read();
  if (m.stamp == init_stamp_) return;
  if (!finite(m.pose) || !std::isfinite(m.sigma_xy_m) || !std::isfinite(m.sigma_yaw_rad) || m.sigma_xy_m < 0 || m.sigma_yaw_rad < 0) {
    if (c_.initial_pose_invalid++ == 0) AG_LOG_WARN("localization", "initial_pose with a non-finite or negative value: ignored (counted)");
    return;
  }
  init_stamp_ = m.stamp;
  ++c_.initial_poses;
  have_init_ = true;
  loc_->initialise_gaussian(m.pose, std::max(m.sigma_xy_m, 0.5), std::max(m.sigma_yaw_rad, 0.02), last_odom_stamp_);
  AG_LOG_INFO("localization", "initial pose (%.1f, %.1f, %.2f rad) sigma %.1f m %.2f rad", m.pose.x, m.pose.y, m.pose.yaw, m.sigma_xy_m,
              m.sigma_yaw_rad);
}

void LocalizationStage::feed_odometry_until(TimeNs t) noexcept {
  for (WheelOdometryMsg* m = odom_.front(); m != nullptr && m->stamp <= t; m = odom_.front()) {
    ++c_.odometry_in;
    if (!finite(m->pose)) {
      if (c_.odometry_non_finite++ == 0) AG_LOG_WARN("localization", "wheel_odometry with a non-finite pose: dropped (counted)");
    } else if (have_odom_ && m->stamp <= last_odom_stamp_) {
      ++c_.odometry_out_of_order;
    } else {
      loc_->on_odometry(m->pose, m->stamp);
      last_odom_stamp_ = m->stamp;
      have_odom_ = true;
    }
    odom_.pop();
  }
}

void LocalizationStage::take_scan(LidarScanMsg& scan) noexcept {
  ++c_.scans_in;
  if (scan.count > scan.points.size() || scan.rings == 0 || scan.columns == 0) {
    if (c_.scans_malformed++ == 0)
      AG_LOG_WARN("localization", "lidar_scan %u has %u points for %u x %u: dropped (counted)", scan.seq, scan.count,
                  static_cast<unsigned>(scan.rings), static_cast<unsigned>(scan.columns));
    return;
  }
  if (!have_map_ || !have_init_) {
    ++c_.scans_before_map;
    return;
  }
  if (!loc_->wants_scan(*fields_)) {
    ++c_.scans_skipped_standing;
    return;
  }
  const std::span<ScanPoint> pts(scan.points.data(), scan.count);
  labeller_->label(pts, scan.rings, scan.columns);
  const UpdateReport r = loc_->on_scan(pts, *fields_, scan.stamp);
  add_work(1.0);  // one scan update (compute-time model)
  if (r.updated) ++c_.scans_matched;
  if (r.recovered) {
    ++c_.recoveries;
    AG_LOG_WARN("localization", "diverged (best cost %.2f m): re-spread around the last good pose", r.best_cost_m);
  }
}

// A route the planner could not start from a pose stamped after the status last changed: the pose the
// localizer tracks is one the robot cannot hold (ParticleFilter::set_start_blocked); any other route
// clears it.
void LocalizationStage::take_route() noexcept {
  if (!path_.fresh()) return;
  const PlannedPathMsg& m = path_.read();
  if (m.seq == path_seq_) return;
  path_seq_ = m.seq;
  const bool blocked = m.status == RouteStatus::kBadEnds && m.plan_status == kPlanStatusStartBlocked && m.stamp > status_since_ &&
                       msg_.status == LocalizationStatus::kTracking;
  if (blocked) ++c_.planner_start_blocked;
  loc_->set_start_blocked(blocked);
}

void LocalizationStage::step(TimeNs now) noexcept {
  take_tiles();
  take_initial_pose();
  take_route();
  // Odometry up to each scan's time first, so the filter moves by exactly the motion before the scan.
  for (LidarScanMsg* s = scans_.front(); s != nullptr; s = scans_.front()) {
    feed_odometry_until(s->stamp);
    take_scan(*s);
    scans_.pop();
  }
  feed_odometry_until(INT64_MAX);  // the rest: a driver on another time base must not fill the ring
  if (!have_init_) {
    msg_.status = have_map_ ? LocalizationStatus::kInitialising : LocalizationStatus::kNoMap;
    msg_.stamp = last_odom_stamp_;
  } else {
    loc_->fill(msg_);
    if (!have_map_) msg_.status = LocalizationStatus::kNoMap;
  }
  msg_.published = now;
  if (msg_.status != last_status_) {
    last_status_ = msg_.status;
    status_since_ = msg_.stamp;
  }
  out_.publish(msg_);
}

}  // namespace ag::loc
