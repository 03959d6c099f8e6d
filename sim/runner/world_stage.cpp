// The world side of the lockstep tick: vehicles, odometry, GPS, VO, camera, LiDAR, radio, recording.
#include "world_stage.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <functional>
#include <string>

#include "airground/platform/clock.hpp"
#include "airground/platform/log.hpp"
#include "airground/sim/world_png.hpp"
#include "sim_probes.hpp"

namespace ag::sim::lockstep {
namespace {

// A powered-off node is moved far out of everyone's range: nothing it sends arrives, nothing reaches it.
constexpr double kFarAway = 1e9;

// LidarPoints as the .bin recording keeps them: the struct's layout with its padding bytes zeroed, so
// that one seed gives the same file byte for byte.
void write_points(const std::vector<LidarPoint>& pts, std::vector<unsigned char>& scratch, std::FILE* f) {
  scratch.assign(pts.size() * sizeof(LidarPoint), 0);
  unsigned char* d = scratch.data();
  for (const LidarPoint& q : pts) {
    std::memcpy(d + offsetof(LidarPoint, x), &q.x, sizeof q.x);
    std::memcpy(d + offsetof(LidarPoint, y), &q.y, sizeof q.y);
    std::memcpy(d + offsetof(LidarPoint, z), &q.z, sizeof q.z);
    std::memcpy(d + offsetof(LidarPoint, range), &q.range, sizeof q.range);
    std::memcpy(d + offsetof(LidarPoint, cls), &q.cls, sizeof q.cls);
    std::memcpy(d + offsetof(LidarPoint, ring), &q.ring, sizeof q.ring);
    std::memcpy(d + offsetof(LidarPoint, col), &q.col, sizeof q.col);
    d += sizeof(LidarPoint);
  }
  std::fwrite(scratch.data(), 1, scratch.size(), f);
}

// The simulated camera's frame, at the mapper's 640x400, RGB only (its labels only in the ablation the
// user names), to the quadrotor's camera stage.
void publish_image(Uav& a, camera::SimCameraLink& link, TimeNs now) {
  CameraImageMsg* slot = link.begin_frame();
  if (slot == nullptr) return;  // the camera stage has not taken the last two frames: dropped (counted by the link)
  CameraImageMsg& m = *slot;
  const cv::Mat* rgb = &a.frame.rgb;
  const cv::Mat* cls = &a.frame.cls;
  if (rgb->cols != kImageWidth || rgb->rows != kImageHeight) {
    cv::resize(a.frame.rgb, a.rgb_small, cv::Size(kImageWidth, kImageHeight), 0, 0, cv::INTER_AREA);
    cv::resize(a.frame.cls, a.cls_small, cv::Size(kImageWidth, kImageHeight), 0, 0, cv::INTER_NEAREST);
    rgb = &a.rgb_small;
    cls = &a.cls_small;
  }
  m.stamp = now;
  m.published = now;
  m.seq = a.image_seq++;
  // A camera measures light, not classes: the truth only in the ablation the user names.
  m.labels = a.labels_oracle ? LabelSource::kGroundTruth : LabelSource::kNone;
  if (!a.labels_oracle) m.cls.fill(255);
  for (int r = 0; r < kImageHeight; ++r) {
    std::memcpy(m.rgb.data() + static_cast<std::size_t>(r) * kImageWidth * 3, rgb->ptr<std::uint8_t>(r), kImageWidth * 3);
    if (a.labels_oracle) std::memcpy(m.cls.data() + static_cast<std::size_t>(r) * kImageWidth, cls->ptr<std::uint8_t>(r), kImageWidth);
  }
  link.commit();
}

// A frame's exposure, motion (blur) and noise key: the same whether it is rendered ahead or when due.
CameraShot camera_shot(const Team& t, const Quadrotor& q, double yaw_rate, std::uint64_t frame) {
  return CameraShot{t.opt.seed, frame, t.camera_ae.next(), Eigen::Vector3d(q.vx(), q.vy(), q.vz()), yaw_rate};
}

void apply_kills(Team& t, TimeNs now) {
  for (const RunOptions::Kill& k : t.opt.kills) {
    if (now < from_seconds(k.at_s)) continue;
    if (k.ugv < 0) {
      if (!t.base_killed) AG_LOG_WARN("sim", "base station powered off at %.1f s", to_seconds(now));
      t.base_killed = true;
    } else if (!t.ugvs[static_cast<std::size_t>(k.ugv)]->killed) {
      Ugv& u = *t.ugvs[static_cast<std::size_t>(k.ugv)];
      u.killed = true;
      u.killed_at = now;
      AG_LOG_WARN("sim", "%s powered off at %.1f s at (%.1f, %.1f)", u.name.c_str(), to_seconds(now), u.vehicle.pose().x, u.vehicle.pose().y);
    }
  }
  if (t.air && t.base_killed) t.air->set_position(t.base_node, -kFarAway, -kFarAway);
}

// What the operator and a test give a robot's stages: its initial pose guess and a goal.
void publish_given(Ugv& u, TimeNs now) {
  if (!u.init_published) {  // the operator's (or mission file's) guess of the start pose
    u.init_pose.stamp = now;
    u.init_pose.published = now;
    u.init_out.publish(u.init_pose);
    u.init_published = true;
    // ... and the operator arms the base (base.start_armed is false: a robot waits for that).
    u.arm_out.publish(BaseArmMsg{now, now, true});
  }
  if (u.goal_pending) {  // a test's goal for a table without a mission stage
    u.goal.stamp = now;
    u.goal.published = now;
    u.goal_out.publish(u.goal);
    u.goal_pending = false;
  }
}

// A robot waiting for the map is released once the map covers its surroundings; holds stop it a while.
void update_release(const Team& t, Ugv& u, TimeNs now) {
  if (!u.released && now >= u.next_wait_check) {
    u.next_wait_check += kNsPerS;
    if (map_covers(*t.ortho, u.vehicle.pose(), t.opt.ugv_wait_map_radius_m, t.opt.ugv_wait_map_fraction, t.world->grid()) &&
        (!u.scripted || t.opt.ugv_wait_map_route_fraction <= 0 || route_covered(*t.ortho, u.route) >= t.opt.ugv_wait_map_route_fraction)) {
      u.released = true;
      u.released_at = now;
      AG_LOG_INFO("sim", "%s: the map covers its surroundings at %.1f s; driving", u.name.c_str(), to_seconds(now));
    }
  }
  u.held = false;
  for (const UgvHold& h : t.opt.ugv_holds)
    if (h.ugv == u.index && now >= from_seconds(h.at_s) && now < from_seconds(h.at_s + h.duration_s)) u.held = true;
}

// Moves the robot one physics step: its own drive stage's wheel commands, or the scripted pursuit.
void drive(Team& t, Ugv& u, TimeNs now, double dt) {
  if (u.scripted) {
    if (!u.route_done && u.pursuit.done()) {
      u.route_done = true;
      ++u.goals_reached;
      AG_LOG_INFO("sim", "%s: route driven at %.1f s (%.0f m)", u.name.c_str(), to_seconds(now), u.vehicle.distance_travelled());
    }
    // Progress along the route (for rejoining it after a collision): the nearest vertex, never back.
    const Pose2& p = u.vehicle.pose();
    auto d2 = [&](std::size_t k) { return (u.route[k] - Eigen::Vector2d(p.x, p.y)).squaredNorm(); };
    while (u.route_progress + 1 < u.route.size() && d2(u.route_progress + 1) < d2(u.route_progress)) ++u.route_progress;
  } else if (u.pursuit.done() && now >= u.retry_at) {
    if (u.on_route) ++u.goals_reached;
    new_leg(t, u, now);
  }
  // The ODrives take what the robot's base stage sent them over CAN (and keep to it: its watchdog, not
  // the vehicle's, stops the wheels when the drive stage falls silent).
  u.base->odrive.step(now);
  if (t.opt.drive_by_stages) {
    WheelCommandMsg cmd;
    if (u.probe != nullptr && u.probe->take_command(cmd)) ++u.wheel_commands;
    if (u.killed || u.held) u.vehicle.command_wheels(0, 0);
    else u.vehicle.command_wheels(u.base->wheel_rad_s(0), u.base->wheel_rad_s(1));
  } else {
    double v = 0, w = 0;
    if (u.released && !u.held && !u.killed) u.pursuit.command(u.vehicle.pose(), v, w);
    u.vehicle.command_twist(v, w);
  }
  const bool collided = dt > 0 && u.vehicle.step(dt, *t.world);
  if (!collided && dt > 0 && u.blocked_steps > 0) {
    AG_LOG_INFO("sim", "%s: free again after %llu blocked steps at (%.2f, %.2f)", u.name.c_str(),
                static_cast<unsigned long long>(u.blocked_steps), u.vehicle.pose().x, u.vehicle.pose().y);
    u.blocked_steps = 0;
  }
  if (collided) {  // a collision: the vehicle stopped; replan from here
    if (u.blocked_steps++ == 0)
      AG_LOG_WARN("sim", "%s: collision at (%.2f, %.2f) yaw %.2f; replanning", u.name.c_str(), u.vehicle.pose().x,
                  u.vehicle.pose().y, u.vehicle.pose().yaw);
    if (t.opt.drive_by_stages) {
      // nothing to do: the robot's own stages see it stop and go on
    } else if (u.scripted) {
      if (!u.route_done) rejoin_route(t, u, now);
    } else {
      new_leg(t, u, now);
    }
  }
}

// The base's odometry over CAN, the robot's truth history and the recordings of this step.
void publish_odometry(Team& t, Ugv& u, TimeNs now, bool log_now) {
  u.history[u.history_n % Ugv::kHistory] = {now, u.vehicle.pose()};
  ++u.history_n;
  const OdometrySample od = u.odometry.step(now, u.vehicle.pose(), u.vehicle.wheel_left_rad_s(), u.vehicle.wheel_right_rad_s());
  ++u.odom_samples;
  u.odom_last = od.pose;
  {  // the encoders: the wheel angles the base stage, integrating with its nominal radius and track, turns
     // into the model's increment (calibration error and slip included); it reads them over CAN
    const WheelOdometryConfig& oc = u.odometry.config();
    const double half = 0.5 * oc.track_width_m * od.dyaw;
    u.base->turn_shafts((od.distance - half) / oc.wheel_radius_m, (od.distance + half) / oc.wheel_radius_m, to_seconds(now - u.last_encoder));
    u.last_encoder = now;
    ++u.odom_published;
  }
  if (t.opt.ugv_map != UgvMapSource::kNone) publish_tiles(t, u, now);
  if (log_now) {
    const Pose3 p = u.vehicle.pose3();
    if (u.truth_log) std::fprintf(u.truth_log.get(), "%.3f,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
    if (u.odom_log) std::fprintf(u.odom_log.get(), "%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), od.pose.x, od.pose.y, od.pose.yaw, od.wheel_left_rad_s, od.wheel_right_rad_s);
    u.trail.emplace_back(p.x, p.y);
    if (t.mcap) {
      const Pose2 om = u.odometry_in_map(od.pose);
      t.mcap->ugv_pose(now, u.index, p, &om, u.loc_has_pose ? &u.loc_pose : nullptr);
    }
    if (t.mcap && !t.opt.drive_by_stages) t.mcap->ugv_route(now, u.index, u.pursuit.path());
  }
}

void step_ugv(Team& t, Ugv& u, TimeNs now, double dt, bool log_now) {
  publish_given(u, now);
  update_release(t, u, now);
  drive(t, u, now, dt);
  publish_odometry(t, u, now, log_now);
  if (t.air) t.air->set_position(u.node, u.killed ? kFarAway : u.vehicle.pose().x, u.killed ? kFarAway : u.vehicle.pose().y);
}

// The autopilot's GNSS fix and attitude, and the oracle VO when the user names it.
void publish_uav_sensors(Team& t, Uav& a, const Pose3& p, TimeNs now) {
  GpsFix fix;
  if (a.gps.sample(now, p, fix)) {
    ++a.fixes;
    NavPvtBytes msg;  // the receiver's UART: NAV-PVT to the quadrotor's gps stage
    const std::size_t len = encode_nav_pvt_message(now, fix, msg);
    (void)t.uav_devices->gnss.write(std::span<const std::uint8_t>(msg.data(), len));  // an overrun is counted by the link
    if (t.mcap) t.mcap->uav_gps(now, fix.lat_deg, fix.lon_deg, fix.height_m, fix.h_accuracy_m);
    if (a.gps_log) std::fprintf(a.gps_log.get(), "%.3f,%d,%.9f,%.9f,%.3f,%.3f,%.3f,%.3f,%.2f\n", to_seconds(now), static_cast<int>(fix.fix_type), fix.lat_deg, fix.lon_deg, fix.height_m, fix.east_m, fix.north_m, fix.up_m, fix.h_accuracy_m);
  }
  t.uav_devices->px4.step(now);
  AttitudeSample as;
  if (a.attitude.sample(now, p, as)) {
    ++a.attitudes;
    t.uav_devices->px4.send_attitude(as);  // ATTITUDE over MAVLink to the quadrotor's autopilot stage
  }
  if (a.vo_oracle) {
    VoSample vs;
    if (a.vo.sample(now, p, vs)) {
      ++a.vo_samples;
      VoMsg m;
      m.stamp = vs.stamp;
      m.published = now;
      m.segment = vs.segment;
      m.tracking = vs.tracking;
      m.pose = vs.pose;
      (void)a.vo_out.push(m);
      if (vs.segment != a.last_segment || a.vo_samples == 1) {
        a.last_segment = vs.segment;
        ++a.segments;
      }
      if (a.vo_log) std::fprintf(a.vo_log.get(), "%.3f,%u,%d,%.4f,%.4f,%.4f,%.5f,%.5f,%.5f\n", to_seconds(now), vs.segment, vs.tracking ? 1 : 0, vs.pose.x, vs.pose.y, vs.pose.z, vs.pose.roll, vs.pose.pitch, vs.pose.yaw);
    }
  }
}

// Quadrotor: survey flight, GPS, visual odometry.
void step_uav(Team& t, TimeNs now, double dt, bool log_now) {
  Uav& a = *t.uav;
  if (dt > 0) {
    const double yaw0 = a.vehicle.pose().yaw;
    a.vehicle.step(dt);
    t.uav_yaw_rate = wrap_angle(a.vehicle.pose().yaw - yaw0) / dt;
  }
  const Pose3& p = a.vehicle.pose();
  if (t.opt.keep_uav_truth) a.truth.push_back(TruthSample{now, p});
  if (!t.uav_play) publish_uav_sensors(t, a, p, now);  // a replayed quadrotor's sensors feed nothing
  if (log_now) {
    if (a.truth_log) std::fprintf(a.truth_log.get(), "%.3f,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
    a.trail.emplace_back(p.x, p.y);
    if (t.mcap) t.mcap->uav_pose(now, p);
  }
  if (t.air) t.air->set_position(0, p.x, p.y);
}

// The due camera frame is rendered: publish and record it, and start the next one ahead.
void finish_camera_frame(Team& t, const Pose3& uav_pose, TimeNs now) {
  t.next_camera += t.camera_period;
  Uav& a = *t.uav;
  ++a.frames;
  t.camera_ae.observe(a.frame);
  publish_image(a, t.uav_devices->camera, now);
  if (t.mcap) t.mcap->camera_frame(now, a.frames, a.frame.rgb);
  if (a.frame_log) std::fprintf(a.frame_log.get(), "%.3f,%llu,%.3f,%.3f,%.3f,%.4f\n", to_seconds(now), static_cast<unsigned long long>(a.frames), uav_pose.x, uav_pose.y, uav_pose.z, uav_pose.yaw);
  const bool keep = t.opt.record == RecordLevel::kFull || (t.opt.record == RecordLevel::kLight && (a.frames - 1) % 20 == 0);
  if (keep) {
    char name[64];
    std::snprintf(name, sizeof name, "frame_%06llu", static_cast<unsigned long long>(a.frames));
    cv::Mat bgr;
    cv::cvtColor(a.frame.rgb, bgr, cv::COLOR_RGB2BGR);
    cv::imwrite((t.out / "camera" / (std::string(name) + "_rgb.png")).string(), bgr);
    cv::cvtColor(class_display_image(a.frame.cls), bgr, cv::COLOR_RGB2BGR);
    cv::imwrite((t.out / "camera" / (std::string(name) + "_class.png")).string(), bgr);
    ++t.frame_pngs;
  }
  if (t.prefetch) {  // the next exposure: step a copy of the vehicle as this stage will step it
    if (!t.uav_ahead) t.uav_ahead.emplace(a.vehicle);
    else *t.uav_ahead = a.vehicle;  // reuses the route's storage
    TimeNs due = now;
    double yaw_rate = t.uav_yaw_rate;
    while (due < t.next_camera) {
      due += t.physics_period;
      const double yaw0 = t.uav_ahead->pose().yaw;
      t.uav_ahead->step(to_seconds(t.physics_period));
      yaw_rate = wrap_angle(t.uav_ahead->pose().yaw - yaw0) / to_seconds(t.physics_period);
    }
    const TimeNs c0 = thread_cpu_now();
    t.camera->prepare(t.uav_ahead->pose(), a.frame, due, camera_shot(t, *t.uav_ahead, yaw_rate, a.frames));
    t.camera_cpu += thread_cpu_now() - c0;
    t.prefetch->start(t.uav_ahead->pose(), due);
  }
}

// The due LiDAR scans are cast: each robot's revolution as the Ouster driver publishes it, and recorded.
void publish_scans(Team& t, TimeNs now) {
  t.next_lidar += t.lidar_period;
  for (auto& up : t.ugvs) {
    Ugv& u = *up;
    std::size_t total = 0;
    for (const auto& part : u.scan_parts) total += part.size();
    ++u.scans;
    {  // the Ouster's packets to the robot's lidar stage: range and reflectivity (the class in it only with --oracle labels)
      const Pose3 sp = lidar_pose(u, u.lidar_mount_z_m);
      SimLidar& l = *u.lidar;
      const std::uint64_t want = static_cast<std::uint64_t>(l.packets.packets_per_revolution());
      const std::uint64_t sent = l.packets.send_revolution(u.scan_parts, sp, now, t.lidar_period, t.opt.oracle("labels"), *t.world,
                                                           [&l, now](std::span<const std::uint8_t> p) { return l.link.send(p, now); });
      if (sent < want) u.channel_drops += want - sent;
      ++u.scans_published;
    }
    if (t.mcap) t.mcap->ugv_scan(now, u.index, u.scans, u.scan_parts.data(), u.scan_parts.size());
    if (u.scan_log) std::fprintf(u.scan_log.get(), "%.3f,%llu,%zu\n", to_seconds(now), static_cast<unsigned long long>(u.scans), total);
    if (u.scan_bin != nullptr) {  // per scan: int64 stamp, uint32 count, then packed points
      const std::uint32_t n = static_cast<std::uint32_t>(total);
      std::fwrite(&now, sizeof now, 1, u.scan_bin);
      std::fwrite(&n, sizeof n, 1, u.scan_bin);
      for (const auto& part : u.scan_parts) write_points(part, u.bin_scratch, u.scan_bin);
    }
  }
}

// Sensors due now, rendered in parallel: camera rows in bands, one job per LiDAR scan. A camera frame
// rendered ahead (CameraPrefetch) is finished by the same jobs instead.
void step_sensors(Team& t, TimeNs now) {
  const bool camera_due = t.uav && t.camera && now >= t.next_camera;
  const bool lidar_due = !t.ugvs.empty() && now >= t.next_lidar;
  if (camera_due || lidar_due) {
    const int bands = camera_due ? kCameraBands : 0;
    constexpr std::size_t kParts = kScanParts;
    const std::size_t jobs = static_cast<std::size_t>(bands) + (lidar_due ? kParts * t.ugvs.size() : 0);
    const Pose3 uav_pose = t.uav ? t.uav->vehicle.pose() : Pose3{};
    const CameraShot shot = camera_due ? camera_shot(t, t.uav->vehicle, t.uav_yaw_rate, t.uav->frames) : CameraShot{};
    bool ahead = false;  // this frame was started ahead for exactly this pose, instant and shot
    if (camera_due && t.prefetch && t.prefetch->active()) {
      ahead = t.prefetch->matches(uav_pose, now) && t.uav->frame.shot == shot;
      if (!ahead) t.prefetch->finish();  // a stale guess (never seen): let it end, then render as usual
      else ++t.frames_ahead;
    }
    const TimeNs cpu0 = thread_cpu_now();
    if (camera_due && !ahead) t.camera->prepare(uav_pose, t.uav->frame, now, shot);
    const TimeNs prepare_cpu = thread_cpu_now() - cpu0;
    std::function<void(std::size_t)> job = [&](std::size_t j) {
      if (static_cast<int>(j) < bands && ahead) {  // the prefetch counts its own CPU
        t.prefetch->help();
        t.job_cpu[j] = 0;
        return;
      }
      const TimeNs job0 = thread_cpu_now();  // each job its own slot: no sharing between the threads
      if (static_cast<int>(j) < bands) {
        const int h = t.uav->frame.rgb.rows;
        const int b = static_cast<int>(j);
        t.camera->render_rows(uav_pose, h * b / bands, h * (b + 1) / bands, t.uav->frame);
      } else {
        const std::size_t idx = j - static_cast<std::size_t>(bands);
        Ugv& u = *t.ugvs[idx / kParts];
        const auto part = static_cast<int>(idx % kParts);
        const int cols = t.opt.lidar_columns;
        const std::uint64_t seed = t.opt.seed ^ (static_cast<std::uint64_t>(now) * std::uint64_t{0x9E3779B97F4A7C15}) ^ static_cast<std::uint64_t>(u.node);
        t.lidar->scan_columns(lidar_pose(u, u.lidar_mount_z_m), seed, cols * part / static_cast<int>(kParts),
                              cols * (part + 1) / static_cast<int>(kParts), u.scan_parts[static_cast<std::size_t>(part)]);
      }
      t.job_cpu[j] = thread_cpu_now() - job0;
    };
    t.pool->run(jobs, job);
    if (ahead) t.prefetch->finish();
    t.camera_cpu += prepare_cpu;
    for (std::size_t j = 0; j < jobs; ++j) (static_cast<int>(j) < bands ? t.camera_cpu : t.lidar_cpu) += t.job_cpu[j];
    if (camera_due) finish_camera_frame(t, uav_pose, now);
    if (lidar_due) publish_scans(t, now);
  }
}

// Radio: with gossip, what the comms stages sent reaches the receivers' inboxes; without, every robot
// broadcasts a small status datagram and the runner counts what arrives where.
void step_radio(Team& t, TimeNs now) {
  if (t.net) t.net->pump(now);
  if (t.radio) {
    if (now >= t.next_heartbeat) {
      t.next_heartbeat += t.heartbeat_period;
      std::uint8_t msg[64] = {};
      for (int n = 0; n < t.radio->num_nodes(); ++n) {
        msg[0] = static_cast<std::uint8_t>(n);
        std::memcpy(msg + 8, &now, sizeof now);
        t.radio->send(now, n, RadioModel::kBroadcast, msg);
      }
    }
    t.deliveries.clear();
    t.radio->deliver(now, t.deliveries);
  }
  if (t.mcap) {
    const LinkStats radio = t.air ? t.air->total() : LinkStats{};
    t.mcap->tick(now, t.air ? &radio : nullptr);
  }
}

}  // namespace

void SimWorldStage::step(TimeNs now) noexcept {
  Team& t = t_;
  const double dt = last_ < 0 ? 0.0 : to_seconds(now - last_);
  last_ = now;
  const bool log_now = now >= t.next_log;
  if (log_now) t.next_log += t.log_period;

  // The quadrotor's map as the ground robots' source: which tiles changed (as of the last step).
  if (t.ortho != nullptr) scan_online_map(t);
  if (t.opt.observe && now >= t.next_observe) {
    t.next_observe += t.sample_period;
    t.opt.observe(now, t.uav ? t.uav->role.get() : nullptr, t.ugv_roles, t.base.get());
  }
  apply_kills(t, now);
  // Ground robots: scripted pursuit from ground truth, exact arcs, wheel odometry.
  for (auto& up : t.ugvs) step_ugv(t, *up, now, dt, log_now);
  if (t.uav) step_uav(t, now, dt, log_now);
  step_sensors(t, now);
  step_radio(t, now);
}

}  // namespace ag::sim::lockstep
