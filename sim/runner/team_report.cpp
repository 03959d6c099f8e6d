// The team run's summary files: summary.yaml, summary.json, report.md and trajectories.png.
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "airground/sim/world_png.hpp"
#include "team.hpp"

namespace ag::sim::lockstep {
namespace {

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
  // Each robot's own localization while tracking: white dots over its true trail.
  for (const auto& u : t.ugvs)
    for (const Eigen::Vector2d& p : u->est_trail) cv::circle(bgr, px(p), 1, cv::Scalar(255, 255, 255), cv::FILLED);
  return bgr;
}

}  // namespace

Status write_reports(const Team& t, const RunSummary& s) {
  cv::imwrite((t.out / "trajectories.png").string(), trajectories_image(t));
  std::ofstream y(t.out / "summary.yaml");
  y << "# airground-sim run summary\n"
    << "oracles: " << t.opt.oracles_json() << "\n"
    << "world: " << t.opt.world << "\nseed: " << t.opt.seed << "\nugvs: " << t.opt.ugvs << "\nuav: " << (t.opt.uav ? "true" : "false")
    << "\nsim_s: " << s.sim_s << "\nwall_s: " << s.wall_s << "\nreal_time_factor: " << s.real_time_factor
    << "\nsensor_cpu_s: " << s.sensor_cpu_s << "\ncamera_cpu_s: " << s.camera_cpu_s << "\nlidar_cpu_s: " << s.lidar_cpu_s
    << "\nprocess_cpu_s: " << s.process_cpu_s << "\ncpu_per_sim_s: " << (s.sim_s > 0 ? s.process_cpu_s / s.sim_s : 0.0)
    << "\nrobot_cpu_s: {" << [&] {
         std::string r;
         for (const auto& [name, cpu] : s.robot_cpu_s) r += (r.empty() ? "" : ", ") + name + ": " + std::to_string(cpu);
         return r;
       }() << "}\ncamera_frames: " << s.camera_frames << "\ncamera_frames_ahead: " << s.camera_frames_ahead << "\ngps_fixes: " << s.gps_fixes
    << "\nvo_samples: " << s.vo_samples << "\nvo_segments: " << s.vo_segments << "\nuav_distance_m: " << s.uav_distance_m
    << "\nuav_route_estimate_s: " << s.uav_route_estimate_s << "\nduration_cap_s: " << s.duration_cap_s
    << "\nuav_waypoints_reached: " << s.uav_waypoints_reached << "\nradio:\n  sent: " << s.radio_sent
    << "\n  delivered: " << s.radio_delivered << "\n  dropped_range: " << s.radio_dropped_range
    << "\n  dropped_loss: " << s.radio_dropped_loss << "\n  dropped_queue: " << s.radio_dropped_queue
    << "\ncompute_time: " << s.compute_time << "\nstage_overruns: " << s.stage_overruns << "\nstage_slips: " << s.stage_slips << "\nstages:\n";
  for (const auto& c : s.stages)
    y << "  - {name: " << c.name << ", runs: " << c.runs << ", overruns: " << c.overruns << ", slips: " << c.slips
      << ", exec_p99_ms: " << c.exec_p99_ms << ", budget_ms: " << c.budget_ms << "}\n";
  y << "ground_robots:\n";
  for (const auto& r : s.ugvs)
    y << "  - {name: " << r.name << ", distance_m: " << r.distance_m << ", collisions: " << r.collisions
      << ", goals_reached: " << r.goals_reached << ", scans: " << r.scans << ", odometry_final_error_m: " << r.odometry_final_error_m
      << ", published: {scans: " << r.scans_published << ", odometry: " << r.odometry_published << ", tiles: " << r.tiles_published
      << ", tiles_refused: " << r.tiles_refused << ", drops: " << r.channel_drops << ", initial_pose: " << (r.initial_pose_published ? "true" : "false") << "}"
      << ", localization: {status: \"" << r.loc_status << "\", tracking_fraction: " << r.loc_tracking_fraction << ", first_tracking_s: " << r.loc_first_tracking_s
      << ", error_mean_m: " << r.loc_error_mean_m << ", error_p95_m: " << r.loc_error_p95_m << ", error_max_m: " << r.loc_error_max_m << "}}\n";
  std::ofstream j(t.out / "summary.json");
  j << "{\"oracles\": " << t.opt.oracles_json() << ", \"sim_s\": " << s.sim_s << ", \"wall_s\": " << s.wall_s << ", \"real_time_factor\": " << s.real_time_factor
    << ", \"cpu_s\": {\"process\": " << s.process_cpu_s << ", \"camera\": " << s.camera_cpu_s << ", \"lidar\": " << s.lidar_cpu_s;
  for (const auto& [name, cpu] : s.robot_cpu_s) j << ", \"" << name << "\": " << cpu;
  j << "}"
    << ", \"camera_frames\": " << s.camera_frames << ", \"gps_fixes\": " << s.gps_fixes << ", \"vo_samples\": " << s.vo_samples
    << ", \"vo_segments\": " << s.vo_segments << ", \"uav_distance_m\": " << s.uav_distance_m
    << ", \"uav_route_estimate_s\": " << s.uav_route_estimate_s << ", \"duration_cap_s\": " << s.duration_cap_s
    << ", \"radio\": {\"sent\": " << s.radio_sent << ", \"delivered\": " << s.radio_delivered << "}"
    << ", \"compute_time\": \"" << s.compute_time << "\", \"stage_overruns\": " << s.stage_overruns << ", \"stage_slips\": " << s.stage_slips
    << ", \"stages\": [";
  for (std::size_t i = 0; i < s.stages.size(); ++i) {
    const auto& c = s.stages[i];
    j << (i ? ", " : "") << "{\"name\": \"" << c.name << "\", \"runs\": " << c.runs << ", \"overruns\": " << c.overruns << ", \"slips\": " << c.slips
      << ", \"exec_p99_ms\": " << c.exec_p99_ms << ", \"budget_ms\": " << c.budget_ms << "}";
  }
  j << "], \"ground_robots\": [";
  for (std::size_t i = 0; i < s.ugvs.size(); ++i) {
    const auto& r = s.ugvs[i];
    j << (i ? ", " : "") << "{\"name\": \"" << r.name << "\", \"distance_m\": " << r.distance_m << ", \"collisions\": " << r.collisions
      << ", \"goals_reached\": " << r.goals_reached << ", \"scans\": " << r.scans << ", \"odometry_final_error_m\": " << r.odometry_final_error_m
      << ", \"published\": {\"scans\": " << r.scans_published << ", \"odometry\": " << r.odometry_published << ", \"tiles\": " << r.tiles_published
      << ", \"tiles_refused\": " << r.tiles_refused << ", \"drops\": " << r.channel_drops << ", \"initial_pose\": " << (r.initial_pose_published ? "true" : "false") << "}"
      << ", \"localization\": {\"status\": \"" << r.loc_status << "\", \"tracking_fraction\": " << r.loc_tracking_fraction
      << ", \"first_tracking_s\": " << r.loc_first_tracking_s << ", \"error_mean_m\": " << r.loc_error_mean_m << ", \"error_p95_m\": " << r.loc_error_p95_m
      << ", \"error_max_m\": " << r.loc_error_max_m << "}}";
  }
  j << "]}\n";
  std::ofstream m(t.out / "report.md");
  m << "# airground-sim run\n\n" << t.opt.oracles_line() << "\n\n"
    << "World `" << t.opt.world << "`, seed " << t.opt.seed << ", " << (t.opt.uav ? "1 quadrotor + " : "") << t.opt.ugvs
    << " ground robots, " << s.sim_s << " s simulated in " << s.wall_s << " s (real-time factor " << s.real_time_factor << "x).\n\n"
    << "CPU over the run, in core-seconds per simulated second (the machine's cores divided by the total bound the "
       "real-time factor): " << [&] {
         const auto per = [&](double cpu) {
           char b[32];
           std::snprintf(b, sizeof b, "%.3f", s.sim_s > 0 ? cpu / s.sim_s : 0.0);
           return std::string(b);
         };
         std::string r = "total " + per(s.process_cpu_s) + "; camera " + per(s.camera_cpu_s) + ", LiDAR " + per(s.lidar_cpu_s);
         for (const auto& [name, cpu] : s.robot_cpu_s) r += ", " + name + " stages " + per(cpu);
         return r + " (the rest: world, vehicles, radio, recording, threads).\n\n";
       }()
    << "![trajectories](trajectories.png)\n\n"
    << "| robot | distance [m] | goals reached | collisions | LiDAR scans | odometry error at end [m] | localization at end | tracking [%] | "
       "localization error mean / p95 / max [m] |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : s.ugvs) {
    char err[96];
    if (r.loc_error_mean_m >= 0) std::snprintf(err, sizeof err, "%.2f / %.2f / %.2f", r.loc_error_mean_m, r.loc_error_p95_m, r.loc_error_max_m);
    else std::snprintf(err, sizeof err, "-");
    m << "| " << r.name << " | " << r.distance_m << " | " << r.goals_reached << " | " << r.collisions << " | " << r.scans << " | " << r.odometry_final_error_m
      << " | " << r.loc_status << " | " << static_cast<int>(std::lround(100.0 * r.loc_tracking_fraction)) << " | " << err << " |\n";
  }
  m << "\nLocalization: each robot's own pose on its `localization` channel (no GPS: LiDAR against the aerial map, "
    << (t.opt.ugv_map == UgvMapSource::kOnline ? "the map the quadrotor builds online" : t.opt.ugv_map == UgvMapSource::kGroundTruth ? "the world's class map" : "no map given")
    << ", initial guess " << (t.opt.init_error_uniform ? "up to " : "") << t.opt.init_error_m << " m / " << t.opt.init_yaw_error_deg
    << " deg off, given with sigma " << initial_sigma_m(t.opt) << " m), sampled at " << t.opt.sample_hz
    << " Hz while driving; errors over the tracking samples. White dots in the picture: the estimates.\n";
  m << "\nQuadrotor: " << s.uav_distance_m << " m flown, " << s.uav_waypoints_reached << " survey waypoints, "
    << s.camera_frames << " camera frames, " << s.gps_fixes << " GPS fixes, " << s.vo_samples << " VO samples in "
    << s.vo_segments << " tracking segments.\n\nRadio: " << s.radio_sent << " datagrams sent, " << s.radio_delivered
    << " delivered, " << s.radio_dropped_range << " out of range, " << s.radio_dropped_loss << " lost, "
    << s.radio_dropped_queue << " dropped by queues.\n\nRecordings: `truth_*.csv`, `odom_*.csv`, `gps_uav.csv`, "
    << "`vo_uav.csv`, `camera_frames.csv` and `camera/*.png`, `lidar_*.csv` (and `lidar_*.bin` with --record full).\n";
  if (!y || !j || !m) return Error::make(ErrorCode::kIo, "cannot write the summary files in " + t.out.string());
  return ok_status();
}

}  // namespace ag::sim::lockstep
