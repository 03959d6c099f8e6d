// The simulator's reader stages in the robots' tables (sim_probes.hpp).
#include "sim_probes.hpp"

#include <cmath>
#include <cstdio>

#include "team.hpp"

namespace ag::sim::lockstep {

void SimVoTapStage::step(TimeNs) noexcept {
  while (const VoMsg* m = in_.front()) {
    if (uav != nullptr) {
      Uav& a = *uav;
      ++a.vo_samples;
      if (m->segment != a.last_segment || a.vo_samples == 1) {
        a.last_segment = m->segment;
        ++a.segments;
      }
      if (a.vo_log)
        std::fprintf(a.vo_log.get(), "%.3f,%u,%d,%.4f,%.4f,%.4f,%.5f,%.5f,%.5f\n", to_seconds(m->stamp), m->segment, m->tracking ? 1 : 0, m->pose.x,
                     m->pose.y, m->pose.z, m->pose.roll, m->pose.pitch, m->pose.yaw);
    }
    in_.pop();
  }
}

Status SimProbeStage::init(StageContext& ctx) {
  const SimProbeSettings cfg = load_params(ctx.params(), kSimProbeFields);
  auto loc = ctx.channels.latest_reader(chan::kLocalization);
  if (!loc) return loc.error();
  loc_ = loc.value();
  auto cmd = ctx.channels.latest_reader(chan::kWheelCommand);
  if (!cmd) return cmd.error();
  cmd_ = cmd.value();
  if (cfg.scans) {
    auto r = ctx.channels.ring_reader(chan::kLidarScan);
    if (!r) return r.error();
    scans_ = r.value();
    read_scans_ = true;
  }
  if (cfg.odometry) {
    auto r = ctx.channels.ring_reader(chan::kWheelOdometry);
    if (!r) return r.error();
    odom_ = r.value();
    read_odom_ = true;
  }
  if (cfg.tiles) {
    auto r = ctx.channels.ring_reader(chan::kMapTiles);
    if (!r) return r.error();
    tiles_ = r.value();
    read_tiles_ = true;
  }
  if (cfg.initial_pose) {
    auto r = ctx.channels.latest_reader(chan::kInitialPose);
    if (!r) return r.error();
    init_ = r.value();
    read_init_ = true;
  }
  return ok_status();
}

void SimProbeStage::step(TimeNs now) noexcept {
  const UgvChannelTap& tap = team->opt.ugv_tap;
  const int i = ugv->index;
  if (read_scans_)
    for (LidarScanMsg* m = scans_.front(); m != nullptr; m = scans_.front()) {
      if (tap.scan) tap.scan(i, *m);
      scans_.pop();
    }
  if (read_odom_)
    for (WheelOdometryMsg* m = odom_.front(); m != nullptr; m = odom_.front()) {
      if (tap.odometry) tap.odometry(i, *m);
      odom_.pop();
    }
  if (read_tiles_)
    for (MapTileMsg* m = tiles_.front(); m != nullptr; m = tiles_.front()) {
      if (tap.tile) tap.tile(i, *m);
      tiles_.pop();
    }
  if (read_init_ && init_.fresh()) {
    const InitialPoseMsg& m = init_.read();
    if (tap.initial_pose) tap.initial_pose(i, m);
  }
  if (cmd_.fresh()) {
    command_ = cmd_.read();
    new_command_ = true;
  }
  if (loc_.fresh()) received_ = true;
  const LocalizationMsg& loc = loc_.read();
  if (now >= next_sample_) {
    next_sample_ += team->sample_period;
    if (received_) ugv->loc_last = loc.status;
    if (received_ && ugv->released && !ugv->held) {
      ++ugv->loc_samples;
      if (loc.status == LocalizationStatus::kTracking) {
        const Pose2 tr = ugv->truth_at(loc.stamp);
        ++ugv->loc_tracking;
        ugv->loc_errors.push_back(static_cast<float>(std::hypot(loc.pose.x - tr.x, loc.pose.y - tr.y)));
        if (ugv->loc_first_tracking < 0) ugv->loc_first_tracking = now;
        ugv->loc_pose = loc.pose;
        ugv->loc_has_pose = true;
        if (ugv->est_trail.empty() || (ugv->est_trail.back() - Eigen::Vector2d(loc.pose.x, loc.pose.y)).norm() > 1.0)
          ugv->est_trail.emplace_back(loc.pose.x, loc.pose.y);
      }
    }
  }
  if (team->opt.sample && now >= next_user_sample_) {
    next_user_sample_ += team->sample_period;
    UgvSample s;
    s.now = now;
    s.ugv = i;
    s.truth = ugv->vehicle.pose();
    s.odometry = ugv->odom_last;
    s.odometry_in_map = ugv->odometry_in_map(ugv->odom_last);
    s.initial_guess = ugv->init_pose.pose;
    s.localization_received = received_;
    s.localization = &loc;
    s.truth_at_localization = received_ ? ugv->truth_at(loc.stamp) : s.truth;
    s.distance_m = ugv->vehicle.distance_travelled();
    s.released = ugv->released;
    s.held = ugv->held;
    s.route_done = ugv->route_done;
    s.killed = ugv->killed;
    s.role = ugv->role.get();
    if (team->parallel_robots) {  // called from this robot's worker: hand it over at the end of the release time
      ugv->pending_sample = s;
      ugv->has_pending_sample = true;
    } else {
      team->opt.sample(s);
    }
  }
}

}  // namespace ag::sim::lockstep
