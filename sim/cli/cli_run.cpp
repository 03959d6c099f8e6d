// airground-sim run (a team in lockstep, every stream recorded) and config (the simulator models'
// parameters that run --config-dir reads back).
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>

#include "airground/sim/diff_drive.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/radio.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/wheel_odometry.hpp"
#include "cli.hpp"

namespace fs = std::filesystem;

namespace ag::sim::cli {

const char kRunHelp[] =
    "airground-sim run --world W --ugvs N --seed S --duration T --out DIR [options]\n\n"
    "Runs a team in lockstep on a simulated clock: the quadrotor flies a lawnmower survey, the ground\n"
    "robots drive scripted routes over the roads from ground truth, every robot runs its real role\n"
    "table, and every sensor stream is recorded. Writes summary.yaml, summary.json, report.md,\n"
    "trajectories.png and the recordings into DIR. Defaults: --world default --ugvs 3 --seed 1\n"
    "--duration 60 --out sim-run.\n\n"
    "Options:\n"
    "  --no-uav                 ground robots only\n"
    "  --physics-hz F           vehicle/odometry/GPS step (50)\n"
    "  --camera-hz F            quadrotor camera frames (5)      --camera-scale S   0.5 = 640x400 (0.5)\n"
    "  --lidar-hz F             LiDAR scans (10)                 --lidar-columns C  512|1024|2048 (1024)\n"
    "  --altitude M             survey altitude (40)             --uav-speed V      (5 m/s)\n"
    "  --ugv-speed V            scripted ground speed (1.2 m/s)  --overlap F        survey side overlap (0.6)\n"
    "  --ugv-map online|gt|none the aerial map the ground robots localize in: the quadrotor's, as it builds\n"
    "                           it (default with a quadrotor), the world's class map (default without), none\n"
    "  --init-error M           each ground robot's initial pose guess is M metres off (16) ...\n"
    "  --init-yaw-error D       ... and D degrees (30)\n"
    "  --wait-map-radius M      --ugv-map online: a robot starts driving once the map knows half the cells\n"
    "                           within M metres of it (30; 0 = at once)\n"
    "  --compute-time MODE      model (default): a robot stage's outputs show after its modelled\n"
    "                           compute time on the robot's CPU; measured: this machine's, scaled; off\n"
    "  --target-cpu CPU         nuc|ryzen|xavier-nx for every robot (quadrotor NUC, ground robots Ryzen)\n"
    "  --oracle labels,vo       ablation (field mode without it): labels = the camera frames and LiDAR points carry\n"
    "                           the true classes and the robots use them instead of ErfNet and the geometric\n"
    "                           labeller; vo = the simulator's VO model (visual_odometry.yaml) feeds the pose\n"
    "                           graph instead of the quadrotor's own vo stage; the report lists them\n"
    "  --config-dir DIR         model parameters: gps.yaml, visual_odometry.yaml, wheel_odometry.yaml,\n"
    "                           radio.yaml, diff_drive.yaml, quadrotor.yaml, camera.yaml, lidar_noise.yaml\n"
    "                           (airground-sim config --out DIR writes the defaults)\n"
    "  --record none|light|full what to record (light: CSV streams + every 20th camera frame)\n"
    "  --threads N              worker threads for the sensors and the robots' stages (all cores)\n"
    "  --serial-robots          step the robots one after another on one thread (same results, slower;\n"
    "                           for a debugger or a profile per robot)\n"
    "  --quiet                  no progress line\n";

int write_model_configs(const Args& a) {
  const std::string out = required(a, "out");
  fs::create_directories(out);
  struct Model {
    const char* file;
    std::span<const ParamSection> schema;
  };
  const Model models[] = {{"gps.yaml", gps_config_schema()},
                          {"visual_odometry.yaml", vo_config_schema()},
                          {"wheel_odometry.yaml", wheel_odometry_config_schema()},
                          {"diff_drive.yaml", diff_drive_config_schema()},
                          {"quadrotor.yaml", quadrotor_config_schema()},
                          {"radio.yaml", radio_config_schema()}};
  for (const auto& m : models) {
    std::ofstream f(fs::path(out) / m.file);
    f << "# airground-sim model parameters (defaults); edit and pass the folder as run --config-dir\n"
      << Config::defaults(m.schema).to_yaml();
    if (!f) return fail(Error::make(ErrorCode::kIo, "cannot write " + (fs::path(out) / m.file).string()));
  }
  std::printf("wrote gps, visual_odometry, wheel_odometry, diff_drive, quadrotor and radio parameters to %s\n"
              "(camera and LiDAR: config/sensors/camera.yaml and lidar_noise.yaml in the source tree)\n", out.c_str());
  return 0;
}

int run(const Args& a) {
  RunOptions o;
  o.oracles = oracles_from(a);
  compute_time_from(a, o);
  o.world = a.get("world", o.world);
  o.ugvs = static_cast<int>(number(a, "ugvs", o.ugvs));
  o.seed = static_cast<std::uint64_t>(number(a, "seed", static_cast<double>(o.seed)));
  o.duration_s = number(a, "duration", o.duration_s);
  o.out_dir = a.get("out", o.out_dir);
  o.uav = !a.has("no-uav");
  o.physics_hz = number(a, "physics-hz", o.physics_hz);
  o.camera_hz = number(a, "camera-hz", o.camera_hz);
  o.camera_scale = number(a, "camera-scale", o.camera_scale);
  o.lidar_hz = number(a, "lidar-hz", o.lidar_hz);
  o.lidar_columns = static_cast<int>(number(a, "lidar-columns", o.lidar_columns));
  o.uav_altitude_m = number(a, "altitude", o.uav_altitude_m);
  o.uav_speed_mps = number(a, "uav-speed", o.uav_speed_mps);
  o.ugv_speed_mps = number(a, "ugv-speed", o.ugv_speed_mps);
  o.survey_overlap = number(a, "overlap", o.survey_overlap);
  o.config_dir = a.get("config-dir");
  o.threads = static_cast<int>(number(a, "threads", 0));
  o.parallel_robots = !a.has("serial-robots");
  const std::string ugv_map = a.get("ugv-map", o.uav ? "online" : "gt");
  if (ugv_map == "online") o.ugv_map = UgvMapSource::kOnline;
  else if (ugv_map == "gt") o.ugv_map = UgvMapSource::kGroundTruth;
  else if (ugv_map == "none") o.ugv_map = UgvMapSource::kNone;
  else usage_error("--ugv-map must be online, gt or none");
  if (o.ugv_map == UgvMapSource::kOnline && !o.uav) usage_error("--ugv-map online needs the quadrotor (drop --no-uav)");
  o.init_error_m = number(a, "init-error", 16.0);
  o.init_yaw_error_deg = number(a, "init-yaw-error", 30.0);
  o.ugv_wait_map_radius_m = o.ugv_map == UgvMapSource::kOnline ? number(a, "wait-map-radius", 30.0) : 0.0;
  const std::string rec = a.get("record", "light");
  if (rec == "none") o.record = RecordLevel::kNone;
  else if (rec == "light") o.record = RecordLevel::kLight;
  else if (rec == "full") o.record = RecordLevel::kFull;
  else usage_error("--record must be none, light or full");
  for (double hz : {o.physics_hz, o.camera_hz, o.lidar_hz})
    if (!(hz > 0 && hz <= 1000)) usage_error("rates must be in (0, 1000] Hz");
  const bool tty = isatty(2) != 0;
  const bool show = !a.has("quiet");
  double last_print = -1;
  auto progress = [&](double sim, double total, double rtf) {
    if (!show) return;
    if (!tty && sim - last_print < total / 10 && sim < total) return;
    last_print = sim;
    std::fprintf(stderr, "%ssim %7.1f / %.1f s  %3.0f%%  real-time factor %.1fx%s", tty ? "\r" : "", sim, total,
                 100.0 * sim / total, rtf, tty ? "   " : "\n");
  };
  std::fprintf(stderr, "running %s%d ground robots on world '%s' for %.0f s (seed %llu) -> %s\n", o.uav ? "1 quadrotor + " : "",
               o.ugvs, o.world.c_str(), o.duration_s, static_cast<unsigned long long>(o.seed), o.out_dir.c_str());
  auto s = run_team(o, progress);
  if (show && tty) std::fprintf(stderr, "\n");
  if (!s) return fail(s.error());
  const RunSummary& r = s.value();
  std::printf("simulated %.1f s in %.1f s: real-time factor %.1fx; CPU %.1f s (%.2f core-s per simulated s): camera %.1f s, "
              "LiDAR %.1f s",
              r.sim_s, r.wall_s, r.real_time_factor, r.process_cpu_s, r.sim_s > 0 ? r.process_cpu_s / r.sim_s : 0.0,
              r.camera_cpu_s, r.lidar_cpu_s);
  for (const auto& [name, cpu] : r.robot_cpu_s) std::printf(", %s %.1f s", name.c_str(), cpu);
  std::printf("\n");
  std::printf("quadrotor: %.0f m, %llu camera frames, %llu GPS fixes, %llu VO samples (%llu segments)\n", r.uav_distance_m,
              static_cast<unsigned long long>(r.camera_frames), static_cast<unsigned long long>(r.gps_fixes),
              static_cast<unsigned long long>(r.vo_samples), static_cast<unsigned long long>(r.vo_segments));
  for (const auto& u : r.ugvs)
    std::printf("%s: %.0f m, %llu goals, %llu collisions, %llu scans, odometry error at end %.2f m; localization %s, tracking %.0f%%, "
                "error mean %.2f m, p95 %.2f m\n",
                u.name.c_str(), u.distance_m, static_cast<unsigned long long>(u.goals_reached),
                static_cast<unsigned long long>(u.collisions), static_cast<unsigned long long>(u.scans), u.odometry_final_error_m,
                u.loc_status.c_str(), 100.0 * u.loc_tracking_fraction, u.loc_error_mean_m, u.loc_error_p95_m);
  std::printf("radio: %llu sent, %llu delivered; report: %s/report.md\n", static_cast<unsigned long long>(r.radio_sent),
              static_cast<unsigned long long>(r.radio_delivered), o.out_dir.c_str());
  return 0;
}

}  // namespace ag::sim::cli
