// The lockstep team runner: robots' role tables and the simulated world on one SimClock.
#include "airground/sim/runner.hpp"

#include <yaml-cpp/yaml.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "airground/core/messages.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/log.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/radio.hpp"
#include "airground/sim/raycast.hpp"
#include "airground/sim/rng.hpp"
#include "airground/sim/scripted_driver.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/wheel_odometry.hpp"
#include "airground/sim/world_png.hpp"
#include "roles.hpp"
#include "worker_pool.hpp"

namespace ag::sim {

Result<std::shared_ptr<const World>> resolve_world(const std::string& world_arg) {
  if (world_arg == "default") return std::shared_ptr<const World>(&default_world(), [](const World*) {});
  auto w = load_world(world_arg);
  if (!w) return w.error();
  return std::shared_ptr<const World>(std::make_shared<World>(std::move(w).value()));
}

namespace {

namespace fs = std::filesystem;

// Optional model overrides from --config-dir: <dir>/<name> when it exists. The file holds the model's
// mapping either at the top level or under its section name (as `airground-sim config` writes it).
template <typename T, typename Loader>
Result<T> model_config(const std::string& dir, const char* name, std::string_view section, Loader load) {
  if (dir.empty()) return T{};
  const fs::path p = fs::path(dir) / name;
  if (!fs::exists(p)) return T{};
  YAML::Node root;
  try {
    root = YAML::LoadFile(p.string());
  } catch (const YAML::Exception& e) {
    return Error::make(ErrorCode::kConfig, "config error: " + p.string() + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
  const std::string sec(section);
  if (root.IsMap() && root.size() == 1 && root[sec]) return load(root[sec], p.string());
  return load(root, p.string());
}

class CsvLog {
 public:
  CsvLog() = default;
  CsvLog(const fs::path& path, const char* header) : f_(std::fopen(path.c_str(), "w")) {
    if (f_ != nullptr) std::fprintf(f_, "%s\n", header);
  }
  CsvLog(CsvLog&& o) noexcept : f_(o.f_) { o.f_ = nullptr; }
  CsvLog& operator=(CsvLog&& o) noexcept {
    std::swap(f_, o.f_);
    return *this;
  }
  ~CsvLog() {
    if (f_ != nullptr) std::fclose(f_);
  }
  [[nodiscard]] std::FILE* get() const noexcept { return f_; }
  explicit operator bool() const noexcept { return f_ != nullptr; }

 private:
  std::FILE* f_{nullptr};
};

struct Ugv {
  Ugv(std::string n, int nd, DiffDriveRobot v, WheelOdometrySimulator o, PurePursuit p, const Pose2& s)
      : name(std::move(n)), node(nd), vehicle(std::move(v)), odometry(std::move(o)), pursuit(std::move(p)), start(s) {}
  std::string name;
  int node{0};
  DiffDriveRobot vehicle;
  WheelOdometrySimulator odometry;
  PurePursuit pursuit;
  std::uint64_t leg{0};
  std::uint64_t goals_reached{0};
  bool on_route{false};     // following a planned route (not waiting for one)
  TimeNs retry_at{0};       // when to try planning again after no route was found
  std::uint64_t scans{0};
  std::uint64_t odom_samples{0};
  Pose2 start;
  Pose2 odom_last;
  std::vector<LidarPoint> scan;
  std::array<std::vector<LidarPoint>, 4> scan_parts;  // column quarters, simulated in parallel
  std::vector<Eigen::Vector2d> trail;
  CsvLog truth_log, odom_log, scan_log;
  std::FILE* scan_bin{nullptr};
  std::unique_ptr<RoleInstance> role;
};

struct Uav {
  Quadrotor vehicle;
  GpsSimulator gps;
  VisualOdometrySimulator vo;
  CameraFrame frame;
  std::uint64_t frames{0}, fixes{0}, vo_samples{0};
  std::uint32_t last_segment{0};
  std::uint64_t segments{0};
  std::vector<Eigen::Vector2d> trail;
  CsvLog truth_log, gps_log, vo_log, frame_log;
  std::unique_ptr<RoleInstance> role;
  // The quadrotor's drivers in simulation: what the camera, the VO and the GPS publish to its stages.
  RingWriter<CameraImageMsg, kCameraRing> camera_out{};
  RingWriter<VoMsg, kVoRing> vo_out{};
  RingWriter<GpsMsg, kGpsRing> gps_out{};
  std::unique_ptr<CameraImageMsg> image{};
  cv::Mat rgb_small{}, cls_small{};
  std::uint32_t image_seq{0};
  std::vector<TruthSample> truth{};
};

struct Team {
  RunOptions opt;
  std::shared_ptr<const World> world;
  std::shared_ptr<const HeightfieldRaycaster> raycaster;
  std::unique_ptr<CameraRenderer> camera;
  std::unique_ptr<LidarSimulator> lidar;
  std::unique_ptr<RoadRouter> router;
  std::unique_ptr<RadioModel> radio;
  std::unique_ptr<Uav> uav;
  std::vector<std::unique_ptr<Ugv>> ugvs;
  std::unique_ptr<RoleInstance> base;
  WorkerPool* pool{nullptr};
  fs::path out;
  TimeNs camera_period{0}, lidar_period{0}, heartbeat_period{0}, log_period{0};
  TimeNs next_camera{0}, next_lidar{0}, next_heartbeat{0}, next_log{0};
  TimeNs sensor_cpu{0};
  std::vector<Delivery> deliveries;
  std::uint64_t frame_pngs{0};
};

Pose3 lidar_pose(const Ugv& u, double mount) {
  Pose3 p = u.vehicle.pose3();
  p.z += mount;
  return p;
}

void new_leg(Team& t, Ugv& u, TimeNs now) {
  std::vector<Eigen::Vector2d> path;
  u.on_route = false;
  for (int attempt = 0; attempt < 20; ++attempt) {
    const std::uint64_t key = t.opt.seed * std::uint64_t{1000003} + static_cast<std::uint64_t>(u.node) * std::uint64_t{10007} + u.leg++;
    const Eigen::Vector2d goal = t.router->pick_drivable(key);
    const Pose2& p = u.vehicle.pose();
    const double d = (goal - Eigen::Vector2d(p.x, p.y)).norm();
    if (d < 20.0 || (d > 150.0 && attempt < 15)) continue;  // legs of 20-150 m, like an errand across the block
    if (t.router->route(p.x, p.y, goal.x(), goal.y(), path) && path.size() >= 2) {
      u.pursuit.set_path(std::move(path));
      u.on_route = true;
      return;
    }
  }
  u.pursuit.set_path({});
  u.retry_at = now + 2 * kNsPerS;  // stay put and try again later rather than search every tick
  AG_LOG_WARN("sim", "%s: no road route from (%.1f, %.1f); retrying in 2 s", u.name.c_str(), u.vehicle.pose().x, u.vehicle.pose().y);
}

// The camera driver's job in simulation: the rendered frame at the mapper's 640x400, with its labels.
void publish_image(Uav& a, TimeNs now) {
  CameraImageMsg& m = *a.image;
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
  m.labels = LabelSource::kGroundTruth;
  for (int r = 0; r < kImageHeight; ++r) {
    std::memcpy(m.rgb.data() + static_cast<std::size_t>(r) * kImageWidth * 3, rgb->ptr<std::uint8_t>(r), kImageWidth * 3);
    std::memcpy(m.cls.data() + static_cast<std::size_t>(r) * kImageWidth, cls->ptr<std::uint8_t>(r), kImageWidth);
  }
  (void)a.camera_out.push(m);
}

// The world side of the lockstep tick: vehicles, odometry, GPS, VO, camera, LiDAR, radio, recording.
class SimWorldStage final : public Stage {
 public:
  explicit SimWorldStage(Team& t) : t_(t) {}
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs now) noexcept override;

 private:
  Team& t_;
  TimeNs last_{-1};
};

void SimWorldStage::step(TimeNs now) noexcept {
  Team& t = t_;
  const double dt = last_ < 0 ? 0.0 : to_seconds(now - last_);
  last_ = now;
  const bool log_now = now >= t.next_log;
  if (log_now) t.next_log += t.log_period;

  // Ground robots: scripted pursuit from ground truth, exact arcs, wheel odometry.
  for (auto& up : t.ugvs) {
    Ugv& u = *up;
    if (u.pursuit.done() && now >= u.retry_at) {
      if (u.on_route) ++u.goals_reached;
      new_leg(t, u, now);
    }
    double v = 0, w = 0;
    u.pursuit.command(u.vehicle.pose(), v, w);
    u.vehicle.command_twist(v, w);
    if (dt > 0 && u.vehicle.step(dt, *t.world)) {  // a collision: the vehicle stopped; replan from here
      AG_LOG_WARN("sim", "%s: collision at (%.2f, %.2f) yaw %.2f; replanning", u.name.c_str(), u.vehicle.pose().x,
                  u.vehicle.pose().y, u.vehicle.pose().yaw);
      new_leg(t, u, now);
    }
    const OdometrySample od = u.odometry.step(now, u.vehicle.pose(), u.vehicle.wheel_left_rad_s(), u.vehicle.wheel_right_rad_s());
    ++u.odom_samples;
    u.odom_last = od.pose;
    if (log_now) {
      const Pose3 p = u.vehicle.pose3();
      if (u.truth_log) std::fprintf(u.truth_log.get(), "%.3f,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
      if (u.odom_log) std::fprintf(u.odom_log.get(), "%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), od.pose.x, od.pose.y, od.pose.yaw, od.wheel_left_rad_s, od.wheel_right_rad_s);
      u.trail.emplace_back(p.x, p.y);
    }
    if (t.radio) t.radio->set_position(u.node, u.vehicle.pose().x, u.vehicle.pose().y);
  }

  // Quadrotor: survey flight, GPS, visual odometry.
  if (t.uav) {
    Uav& a = *t.uav;
    if (dt > 0) a.vehicle.step(dt);
    const Pose3& p = a.vehicle.pose();
    if (t.opt.keep_uav_truth) a.truth.push_back(TruthSample{now, p});
    GpsFix fix;
    if (a.gps.sample(now, p, fix)) {
      ++a.fixes;
      GpsMsg m;
      m.stamp = fix.stamp;
      m.published = now;
      m.fix_type = static_cast<std::uint8_t>(fix.fix_type);
      m.east_m = fix.east_m;
      m.north_m = fix.north_m;
      m.up_m = fix.up_m;
      m.h_accuracy_m = fix.h_accuracy_m;
      m.v_accuracy_m = fix.v_accuracy_m;
      (void)a.gps_out.push(m);  // a full ring is counted by the channel
      if (a.gps_log) std::fprintf(a.gps_log.get(), "%.3f,%d,%.9f,%.9f,%.3f,%.3f,%.3f,%.3f,%.2f\n", to_seconds(now), static_cast<int>(fix.fix_type), fix.lat_deg, fix.lon_deg, fix.height_m, fix.east_m, fix.north_m, fix.up_m, fix.h_accuracy_m);
    }
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
    if (log_now) {
      if (a.truth_log) std::fprintf(a.truth_log.get(), "%.3f,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f\n", to_seconds(now), p.x, p.y, p.z, p.roll, p.pitch, p.yaw);
      a.trail.emplace_back(p.x, p.y);
    }
    if (t.radio) t.radio->set_position(0, p.x, p.y);
  }

  // Sensors due now, rendered in parallel: camera rows in bands, one job per LiDAR scan.
  const bool camera_due = t.uav && t.camera && now >= t.next_camera;
  const bool lidar_due = !t.ugvs.empty() && now >= t.next_lidar;
  if (camera_due || lidar_due) {
    constexpr int kBands = 16;
    const int bands = camera_due ? kBands : 0;
    constexpr std::size_t kParts = 4;  // per scan: keeps both cores busy when only LiDAR is due
    const std::size_t jobs = static_cast<std::size_t>(bands) + (lidar_due ? kParts * t.ugvs.size() : 0);
    const TimeNs cpu0 = thread_cpu_now();
    if (camera_due) t.camera->prepare(t.uav->vehicle.pose(), t.uav->frame, now);
    const Pose3 uav_pose = t.uav ? t.uav->vehicle.pose() : Pose3{};
    std::function<void(std::size_t)> job = [&](std::size_t j) {
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
        t.lidar->scan_columns(lidar_pose(u, t.opt.lidar_mount_height_m), seed, cols * part / static_cast<int>(kParts),
                              cols * (part + 1) / static_cast<int>(kParts), u.scan_parts[static_cast<std::size_t>(part)]);
      }
    };
    t.pool->run(jobs, job);
    t.sensor_cpu += thread_cpu_now() - cpu0;
    if (camera_due) {
      t.next_camera += t.camera_period;
      Uav& a = *t.uav;
      ++a.frames;
      publish_image(a, now);
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
    }
    if (lidar_due) {
      t.next_lidar += t.lidar_period;
      for (auto& up : t.ugvs) {
        Ugv& u = *up;
        u.scan.clear();
        for (const auto& part : u.scan_parts) u.scan.insert(u.scan.end(), part.begin(), part.end());
        ++u.scans;
        if (u.scan_log) std::fprintf(u.scan_log.get(), "%.3f,%llu,%zu\n", to_seconds(now), static_cast<unsigned long long>(u.scans), u.scan.size());
        if (u.scan_bin != nullptr) {  // per scan: int64 stamp, uint32 count, then packed points
          const std::uint32_t n = static_cast<std::uint32_t>(u.scan.size());
          std::fwrite(&now, sizeof now, 1, u.scan_bin);
          std::fwrite(&n, sizeof n, 1, u.scan_bin);
          std::fwrite(u.scan.data(), sizeof(LidarPoint), u.scan.size(), u.scan_bin);
        }
      }
    }
  }

  // Radio: every robot broadcasts a small status datagram; count what arrives where.
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
}

cv::Mat trajectories_image(const Team& t) {
  const World& w = *t.world;
  cv::Mat img = class_display_image(w.class_id);
  cv::Mat bgr;
  cv::cvtColor(img, bgr, cv::COLOR_RGB2BGR);
  const double scale = std::min(1.0, 1600.0 / std::max(bgr.cols, bgr.rows));
  if (scale < 1.0) cv::resize(bgr, bgr, cv::Size(), scale, scale, cv::INTER_AREA);
  const GridGeometry& g = w.grid();
  auto px = [&](const Eigen::Vector2d& p) {
    return cv::Point(static_cast<int>(g.col_f(p.x()) * scale), static_cast<int>(g.row_f(p.y()) * scale));
  };
  const cv::Scalar colours[] = {{0, 200, 255}, {255, 0, 255}, {255, 255, 0}, {0, 128, 255}, {255, 128, 0}, {128, 255, 128}};
  auto draw = [&](const std::vector<Eigen::Vector2d>& trail, const cv::Scalar& c, int thick) {
    for (std::size_t i = 1; i < trail.size(); ++i) cv::line(bgr, px(trail[i - 1]), px(trail[i]), c, thick, cv::LINE_AA);
    if (!trail.empty()) cv::circle(bgr, px(trail.back()), 4, c, cv::FILLED, cv::LINE_AA);
  };
  if (t.uav) draw(t.uav->trail, cv::Scalar(255, 255, 255), 1);
  for (std::size_t i = 0; i < t.ugvs.size(); ++i) draw(t.ugvs[i]->trail, colours[i % 6], 2);
  return bgr;
}

Status write_reports(const Team& t, const RunSummary& s) {
  cv::imwrite((t.out / "trajectories.png").string(), trajectories_image(t));
  std::ofstream y(t.out / "summary.yaml");
  y << "# airground-sim run summary\n"
    << "world: " << t.opt.world << "\nseed: " << t.opt.seed << "\nugvs: " << t.opt.ugvs << "\nuav: " << (t.opt.uav ? "true" : "false")
    << "\nsim_s: " << s.sim_s << "\nwall_s: " << s.wall_s << "\nreal_time_factor: " << s.real_time_factor
    << "\nsensor_cpu_s: " << s.sensor_cpu_s << "\ncamera_frames: " << s.camera_frames << "\ngps_fixes: " << s.gps_fixes
    << "\nvo_samples: " << s.vo_samples << "\nvo_segments: " << s.vo_segments << "\nuav_distance_m: " << s.uav_distance_m
    << "\nuav_waypoints_reached: " << s.uav_waypoints_reached << "\nradio:\n  sent: " << s.radio_sent
    << "\n  delivered: " << s.radio_delivered << "\n  dropped_range: " << s.radio_dropped_range
    << "\n  dropped_loss: " << s.radio_dropped_loss << "\n  dropped_queue: " << s.radio_dropped_queue
    << "\nstage_overruns: " << s.stage_overruns << "\nground_robots:\n";
  for (const auto& r : s.ugvs)
    y << "  - {name: " << r.name << ", distance_m: " << r.distance_m << ", collisions: " << r.collisions
      << ", goals_reached: " << r.goals_reached << ", scans: " << r.scans << ", odometry_final_error_m: " << r.odometry_final_error_m << "}\n";
  std::ofstream j(t.out / "summary.json");
  j << "{\"sim_s\": " << s.sim_s << ", \"wall_s\": " << s.wall_s << ", \"real_time_factor\": " << s.real_time_factor
    << ", \"camera_frames\": " << s.camera_frames << ", \"gps_fixes\": " << s.gps_fixes << ", \"vo_samples\": " << s.vo_samples
    << ", \"vo_segments\": " << s.vo_segments << ", \"uav_distance_m\": " << s.uav_distance_m
    << ", \"radio\": {\"sent\": " << s.radio_sent << ", \"delivered\": " << s.radio_delivered << "}"
    << ", \"stage_overruns\": " << s.stage_overruns << ", \"ground_robots\": [";
  for (std::size_t i = 0; i < s.ugvs.size(); ++i) {
    const auto& r = s.ugvs[i];
    j << (i ? ", " : "") << "{\"name\": \"" << r.name << "\", \"distance_m\": " << r.distance_m << ", \"collisions\": " << r.collisions
      << ", \"goals_reached\": " << r.goals_reached << ", \"scans\": " << r.scans << ", \"odometry_final_error_m\": " << r.odometry_final_error_m << "}";
  }
  j << "]}\n";
  std::ofstream m(t.out / "report.md");
  m << "# airground-sim run\n\n"
    << "World `" << t.opt.world << "`, seed " << t.opt.seed << ", " << (t.opt.uav ? "1 quadrotor + " : "") << t.opt.ugvs
    << " ground robots, " << s.sim_s << " s simulated in " << s.wall_s << " s (real-time factor " << s.real_time_factor << "x).\n\n"
    << "![trajectories](trajectories.png)\n\n"
    << "| robot | distance [m] | goals reached | collisions | LiDAR scans | odometry error at end [m] |\n|---|---|---|---|---|---|\n";
  for (const auto& r : s.ugvs)
    m << "| " << r.name << " | " << r.distance_m << " | " << r.goals_reached << " | " << r.collisions << " | " << r.scans << " | " << r.odometry_final_error_m << " |\n";
  m << "\nQuadrotor: " << s.uav_distance_m << " m flown, " << s.uav_waypoints_reached << " survey waypoints, "
    << s.camera_frames << " camera frames, " << s.gps_fixes << " GPS fixes, " << s.vo_samples << " VO samples in "
    << s.vo_segments << " tracking segments.\n\nRadio: " << s.radio_sent << " datagrams sent, " << s.radio_delivered
    << " delivered, " << s.radio_dropped_range << " out of range, " << s.radio_dropped_loss << " lost, "
    << s.radio_dropped_queue << " dropped by queues.\n\nRecordings: `truth_*.csv`, `odom_*.csv`, `gps_uav.csv`, "
    << "`vo_uav.csv`, `camera_frames.csv` and `camera/*.png`, `lidar_*.csv` (and `lidar_*.bin` with --record full).\n";
  if (!y || !j || !m) return Error::make(ErrorCode::kIo, "cannot write the summary files in " + t.out.string());
  return ok_status();
}

}  // namespace

Result<RunSummary> run_team(const RunOptions& opt, const ProgressFn& progress) {
  if (opt.ugvs < 0 || opt.ugvs > 32) return Error::make(ErrorCode::kInvalidArgument, "--ugvs must be 0..32");
  if (!(opt.duration_s > 0)) return Error::make(ErrorCode::kInvalidArgument, "--duration must be positive");
  if (opt.lidar_columns != 512 && opt.lidar_columns != 1024 && opt.lidar_columns != 2048)
    return Error::make(ErrorCode::kInvalidArgument, "LiDAR columns must be 512, 1024 or 2048");
  auto world = resolve_world(opt.world);
  if (!world) return world.error();

  Team t;
  t.opt = opt;
  t.world = world.value();
  t.out = opt.out_dir;
  std::error_code ec;
  fs::create_directories(t.out / "camera", ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + t.out.string() + ": " + ec.message());

  using N = const YAML::Node&;
  using O = std::string_view;
  auto gps_cfg = model_config<GpsConfig>(opt.config_dir, "gps.yaml", "gps", [](N y, O o) { return load_gps_config(y, o); });
  auto vo_cfg = model_config<VoConfig>(opt.config_dir, "visual_odometry.yaml", "visual_odometry", [](N y, O o) { return load_vo_config(y, o); });
  auto od_cfg = model_config<WheelOdometryConfig>(opt.config_dir, "wheel_odometry.yaml", "wheel_odometry", [](N y, O o) { return load_wheel_odometry_config(y, o); });
  auto radio_cfg = model_config<RadioConfig>(opt.config_dir, "radio.yaml", "radio", [](N y, O o) { return load_radio_config(y, o); });
  auto dd_cfg = model_config<DiffDriveConfig>(opt.config_dir, "diff_drive.yaml", "diff_drive", [](N y, O o) { return load_diff_drive_config(y, o); });
  auto quad_cfg = model_config<QuadrotorConfig>(opt.config_dir, "quadrotor.yaml", "quadrotor", [](N y, O o) { return load_quadrotor_config(y, o); });
  for (const Error* e : {gps_cfg ? nullptr : &gps_cfg.error(), vo_cfg ? nullptr : &vo_cfg.error(), od_cfg ? nullptr : &od_cfg.error(),
                         radio_cfg ? nullptr : &radio_cfg.error(), dd_cfg ? nullptr : &dd_cfg.error(), quad_cfg ? nullptr : &quad_cfg.error()})
    if (e != nullptr) return *e;

  CameraModel cam_model;
  CameraShading shading;
  LidarNoise lidar_noise;
  if (!opt.config_dir.empty()) {
    const fs::path cam = fs::path(opt.config_dir) / "camera.yaml";
    if (fs::exists(cam)) {
      auto c = CameraModel::load_file(cam.string());
      if (!c) return c.error();
      cam_model = c.value();
      auto s = CameraShading::load_file(cam.string());
      if (!s) return s.error();
      shading = s.value();
    }
    const fs::path li = fs::path(opt.config_dir) / "lidar_noise.yaml";
    if (fs::exists(li)) {
      auto n = LidarNoise::load_file(li.string());
      if (!n) return n.error();
      lidar_noise = n.value();
    }
  }
  if (opt.camera_scale != 1.0) cam_model = cam_model.scaled(opt.camera_scale);
  auto beams = OusterBeamModel::load_default(opt.lidar_columns);
  if (!beams) return beams.error();

  const World& w = *t.world;
  try {
    t.raycaster = std::make_shared<HeightfieldRaycaster>(w);
    if (opt.uav) t.camera = std::make_unique<CameraRenderer>(w, cam_model, shading, t.raycaster);
    if (opt.ugvs > 0) t.lidar = std::make_unique<LidarSimulator>(w, beams.value(), lidar_noise, t.raycaster);
  } catch (const std::exception& e) {
    return Error::make(ErrorCode::kInvalidArgument, std::string("sensor set-up: ") + e.what());
  }
  t.router = std::make_unique<RoadRouter>(w, 1.0, dd_cfg.value().footprint_radius_m + 0.2);
  const int nodes = (opt.uav ? 1 : 0) + opt.ugvs + 1;  // node 0 = quadrotor (or unused), then ground robots, then base
  t.radio = std::make_unique<RadioModel>(radio_cfg.value(), opt.seed ^ std::uint64_t{0x7261646F}, std::max(nodes, 2) + (opt.uav ? 0 : 1));
  const Pose2 staging = w.header.staging;
  const int base_node = 1 + opt.ugvs;
  t.radio->set_position(base_node, staging.x, staging.y);

  const bool rec = opt.record != RecordLevel::kNone;
  SimClock clock(0);
  // Robot role instances: the real stage tables, quiet status stages (the runner reports instead).
  auto make_role = [&](const RoleDescription& role, int id, const std::string& name,
                       std::vector<Config>& cfgs) -> Result<std::unique_ptr<RoleInstance>> {
    Config c = Config::defaults(role_schema(role));
    if (auto st = c.set("robot.id=" + std::to_string(id)); !st) return st.error();
    if (auto st = c.set("robot.name=" + name); !st) return st.error();
    if (auto st = c.set("status.log_counters=false"); !st) return st.error();
    cfgs.push_back(std::move(c));
    return RoleInstance::create(role, cfgs.back(), clock, name);
  };
  std::vector<Config> cfgs;
  cfgs.reserve(static_cast<std::size_t>(opt.ugvs) + 2);

  if (opt.uav) {
    const Pose3 start{staging.x, staging.y, w.terrain.at<float>(w.grid().row(staging.y), w.grid().col(staging.x)), 0, 0, staging.yaw};
    auto u = std::make_unique<Uav>(Uav{Quadrotor(quad_cfg.value(), start), GpsSimulator(gps_cfg.value(), w.header.datum, opt.seed ^ std::uint64_t{0x67707331}),
                                       VisualOdometrySimulator(vo_cfg.value(), opt.seed ^ std::uint64_t{0x766f3031}), CameraFrame{}, 0, 0, 0, 0, 0, {}, {}, {}, {}, {}, nullptr});
    const GridGeometry& g = w.grid();
    const double margin = opt.survey_margin_m;
    SurveyOptions so;
    so.speed_mps = opt.uav_speed_mps;
    const double hfov = 2.0 * std::atan(0.5 * cam_model.width / cam_model.fx);
    auto route = survey_lawnmower(g.origin_x + margin, g.origin_y - g.size_y() + margin, g.origin_x + g.size_x() - margin,
                                  g.origin_y - margin, opt.uav_altitude_m, opt.survey_overlap, hfov, so);
    if (!route) return route.error();
    u->vehicle.set_waypoints(std::move(route).value());
    if (rec) {
      u->truth_log = CsvLog(t.out / "truth_uav.csv", "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad");
      u->gps_log = CsvLog(t.out / "gps_uav.csv", "t_s,fix_type,lat_deg,lon_deg,height_m,east_m,north_m,up_m,h_acc_m");
      u->vo_log = CsvLog(t.out / "vo_uav.csv", "t_s,segment,tracking,x,y,z,roll_rad,pitch_rad,yaw_rad");
      u->frame_log = CsvLog(t.out / "camera_frames.csv", "t_s,frame,x_m,y_m,z_m,yaw_rad");
    }
    auto role = make_role(uav_role(), 0, "uav", cfgs);
    if (!role) return role.error();
    u->role = std::move(role).value();
    auto cam_w = u->role->channels().ring_writer<CameraImageMsg, kCameraRing>("camera");
    auto vo_w = u->role->channels().ring_writer<VoMsg, kVoRing>("visual_odometry");
    auto gps_w = u->role->channels().ring_writer<GpsMsg, kGpsRing>("gps");
    if (!cam_w) return cam_w.error();
    if (!vo_w) return vo_w.error();
    if (!gps_w) return gps_w.error();
    u->camera_out = cam_w.value();
    u->vo_out = vo_w.value();
    u->gps_out = gps_w.value();
    u->image = std::make_unique<CameraImageMsg>();
    t.uav = std::move(u);
  }
  for (int i = 0; i < opt.ugvs; ++i) {
    const std::string name = "ugv" + std::to_string(i + 1);
    // Lined up on the staging pad, 2.5 m apart across the robots' heading.
    Pose2 start = staging;
    const double off = (i - (opt.ugvs - 1) / 2.0) * 2.5;
    start.x += -std::sin(staging.yaw) * off;
    start.y += std::cos(staging.yaw) * off;
    auto u = std::make_unique<Ugv>(name, (opt.uav ? 1 : 0) + i, DiffDriveRobot(dd_cfg.value(), start),
                                   WheelOdometrySimulator(od_cfg.value(), opt.seed * 31 + static_cast<std::uint64_t>(i)),
                                   PurePursuit(PursuitParams{1.0, opt.ugv_speed_mps, 1.2, 0.8}), start);
    u->scan.reserve(static_cast<std::size_t>(64 * opt.lidar_columns));
    for (auto& part : u->scan_parts) part.reserve(static_cast<std::size_t>(16 * opt.lidar_columns));
    if (rec) {
      u->truth_log = CsvLog(t.out / ("truth_" + name + ".csv"), "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad");
      u->odom_log = CsvLog(t.out / ("odom_" + name + ".csv"), "t_s,x_m,y_m,yaw_rad,wheel_left_rad_s,wheel_right_rad_s");
      u->scan_log = CsvLog(t.out / ("lidar_" + name + ".csv"), "t_s,scan,points");
      if (opt.record == RecordLevel::kFull) u->scan_bin = std::fopen((t.out / ("lidar_" + name + ".bin")).c_str(), "wb");
    }
    auto role = make_role(ugv_role(), i + 1, name, cfgs);
    if (!role) return role.error();
    u->role = std::move(role).value();
    t.ugvs.push_back(std::move(u));
  }
  {
    auto role = make_role(base_role(), 250, "base", cfgs);
    if (!role) return role.error();
    t.base = std::move(role).value();
  }

  const int threads = opt.threads > 0 ? opt.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  WorkerPool pool(threads);
  t.pool = &pool;
  t.camera_period = period_from_hz(opt.camera_hz);
  t.lidar_period = period_from_hz(opt.lidar_hz);
  t.heartbeat_period = period_from_hz(opt.heartbeat_hz);
  t.log_period = period_from_hz(10.0);

  // The world runs first at each release time, then the robots in table order.
  LockstepExecutor exec(clock, ExecTimer::kThreadCpu);
  PerfRegistry sim_perf;
  StagePerf& world_perf = sim_perf.add("sim/world", 0, 0);
  SimWorldStage world_stage(t);
  exec.add_stage(world_stage, world_perf, opt.physics_hz);
  if (t.uav) exec.add(*t.uav->role);
  for (auto& u : t.ugvs) exec.add(*u->role);
  exec.add(*t.base);
  exec.start(0);

  const TimeNs end = from_seconds(opt.duration_s);
  TimeNs chunk = std::max<TimeNs>(kNsPerS / 10, end / 100);
  if (opt.stop_when_survey_done) chunk = std::min<TimeNs>(chunk, 2 * kNsPerS);
  const auto wall0 = std::chrono::steady_clock::now();
  TimeNs ended = end;
  for (TimeNs tt = 0; tt < end;) {
    tt = std::min(end, tt + chunk);
    exec.run_until(tt);
    if (opt.stop_when_survey_done && t.uav && t.uav->vehicle.finished()) {
      ended = tt;
      break;
    }
    if (progress) {
      const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
      progress(to_seconds(tt), opt.duration_s, wall > 0 ? to_seconds(tt) / wall : 0);
    }
  }
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();

  RunSummary s;
  s.sim_s = to_seconds(ended);
  s.wall_s = wall_s;
  s.real_time_factor = wall_s > 0 ? s.sim_s / wall_s : 0;
  s.sensor_cpu_s = to_seconds(t.sensor_cpu);
  if (t.uav) {
    s.camera_frames = t.uav->frames;
    s.gps_fixes = t.uav->fixes;
    s.vo_samples = t.uav->vo_samples;
    s.vo_segments = t.uav->segments;
    s.uav_distance_m = t.uav->vehicle.distance_flown();
    s.uav_waypoints_reached = t.uav->vehicle.waypoints_reached();
  }
  const LinkStats tot = t.radio->total();
  s.radio_sent = tot.sent;
  s.radio_delivered = tot.delivered;
  s.radio_dropped_range = tot.dropped_range;
  s.radio_dropped_loss = tot.dropped_loss;
  s.radio_dropped_queue = tot.dropped_queue;
  for (const auto& r : exec.runnables()) s.stage_overruns += r.perf == &world_perf ? 0 : r.perf->overruns.load();
  for (auto& up : t.ugvs) {
    Ugv& u = *up;
    RobotSummary r;
    r.name = u.name;
    r.distance_m = u.vehicle.distance_travelled();
    r.collisions = u.vehicle.collisions();
    r.goals_reached = u.goals_reached;
    r.scans = u.scans;
    r.odometry_samples = u.odom_samples;
    // Odometry starts at the robot's start pose in its own frame: put it into the map frame to compare.
    const double c = std::cos(u.start.yaw), sn = std::sin(u.start.yaw);
    const double ox = u.start.x + c * u.odom_last.x - sn * u.odom_last.y;
    const double oy = u.start.y + sn * u.odom_last.x + c * u.odom_last.y;
    r.odometry_final_error_m = std::hypot(ox - u.vehicle.pose().x, oy - u.vehicle.pose().y);
    s.ugvs.push_back(r);
    if (u.scan_bin != nullptr) std::fclose(u.scan_bin);
    u.scan_bin = nullptr;
  }
  if (opt.inspect) {
    const GridGeometry& g = w.grid();
    RunInspection in{w};
    in.uav = t.uav ? t.uav->role.get() : nullptr;
    in.uav_truth = t.uav ? &t.uav->truth : nullptr;
    in.vo_scale = t.uav ? t.uav->vo.scale() : 0.0;
    in.vo_segments = s.vo_segments;
    in.vo_tracking_losses = t.uav ? t.uav->vo.tracking_losses() : 0;
    in.survey_x0 = g.origin_x + opt.survey_margin_m;
    in.survey_y0 = g.origin_y - g.size_y() + opt.survey_margin_m;
    in.survey_x1 = g.origin_x + g.size_x() - opt.survey_margin_m;
    in.survey_y1 = g.origin_y - opt.survey_margin_m;
    if (auto st = opt.inspect(in); !st) return st.error();
  }
  if (auto st = write_reports(t, s); !st) return st.error();
  return s;
}

}  // namespace ag::sim
