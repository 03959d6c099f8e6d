// airground-sim mission (a whole team mission in the lockstep simulator, scored) and hil (the real role
// binaries over the devices' wire protocols).
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "airground/sim/eval_mission.hpp"
#include "airground/sim/hil.hpp"
#include "cli.hpp"

namespace ag::sim::cli {

const char kMissionHelp[] =
    "airground-sim mission — a whole team mission: the quadrotor surveys and maps, finds the regions of\n"
    "interest (vehicle clusters), the ground robots localize in its map from a rough guess, claim regions\n"
    "among themselves over the radio's gossip (no central server), plan, drive, visit and return; the base\n"
    "station only listens. Scored against the world's targets and the true poses.\n\n"
    "Usage: airground-sim mission --world W --ugvs N --seed S [--comm-range METRES] [--mission FILE.yaml] --out DIR\n\n"
    "Writes DIR/metrics.json (targets_total, targets_visited, mission_time_s, loc_error_mean_m, loc_error_p95_m,\n"
    "odom_only_error_mean_m, collisions, failed_goals, false_visits, map_class_accuracy, bytes_on_air,\n"
    "realtime_factor, per robot), DIR/report.md with mission_map.png, pose_error.png, odometry_error.png,\n"
    "claims_timeline.png, comms_traffic.png, the quadrotor's final maps in DIR/maps (PNG and GeoTIFF),\n"
    "visits.csv and the runner's recordings.\n"
    "Defaults: --world default --ugvs 3 --seed 1 --out mission (comm range: the radio model's 100 m).\n\n"
    "Options:\n"
    "  --init-error M          initial guesses up to M metres off, uniform per robot (16)\n"
    "  --init-yaw-error D      ... and D degrees (10)\n"
    "  --init-sigma S          the sigma the robots' localizers are given with their guesses (half of --init-error:\n"
    "                          a guess up to M off lies within 2 sigma)\n"
    "  --altitude A            quadrotor survey altitude (40 m)\n"
    "  --max-duration T        stop after T simulated seconds at the latest (4x the survey's flying time, >= 1800)\n"
    "  --kill-ugv I@T          power ground robot I (1-based) off at T seconds (repeatable)\n"
    "  --kill-base T           power the base station off at T seconds\n"
    "  --set SECTION.KEY=VALUE any parameter of the ground robots' role config (repeatable)\n"
    "  --set-uav SECTION.KEY=VALUE  ... of the quadrotor's\n"
    "  --compute-time MODE      model (default): a robot stage's outputs show after its modelled\n"
    "                           compute time on the robot's CPU; measured: this machine's, scaled; off\n"
    "  --target-cpu CPU         nuc|ryzen|xavier-nx for every robot (quadrotor NUC, ground robots Ryzen)\n"
    "  --oracle labels,vo       ablation (field mode without it): labels = true classes in the camera frames and\n"
    "                           LiDAR points, used instead of ErfNet and the geometric labeller; vo = the\n"
    "                           simulator's VO model instead of the quadrotor's own vo stage; metrics.json and the\n"
    "                           report list them\n"
    "  --lidar-columns C       512|1024|2048 (1024)\n"
    "  --uav-cache DIR         record the quadrotor's mapping output into DIR the first time, replay it in later\n"
    "                          missions with the same world, seed, altitude and quadrotor settings (the study's;\n"
    "                          docs/simulator.md, \"Quadrotor replay\")\n"
    "  --uav-cache-build EXE   replay the recordings in --uav-cache that the airground-sim EXE made (a build whose\n"
    "                          quadrotor code is this one's); never records; the report names EXE\n"
    "  --web-port P            the base station serves its live page on http://localhost:P/ during the run\n"
    "  --pace X                hold the run to X times real time (to watch it on the page)\n"
    "  --record none|light|full  recordings (light)\n"
    "  --threads N             worker threads for the sensors and the robots' stages (all cores)\n"
    "  --serial-robots         step the robots one after another (same results, slower)\n"
    "  --verbose [S]           every S simulated seconds (30) a status line per robot\n"
    "  --quiet                 no progress bar\n";

namespace {

void progress_bar(double sim, double total, double rtf, bool tty, double& last_print) {
  if (!tty && sim - last_print < 60 && sim < total) return;
  last_print = sim;
  const int width = 30;
  const int filled = static_cast<int>(std::lround(width * std::min(1.0, sim / std::max(total, 1e-9))));
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(static_cast<std::size_t>(width), '.');
  std::fprintf(stderr, "%s[%s] sim %6.0f s (cap %.0f s)  real-time factor %.1fx%s", tty ? "\r" : "", bar.c_str(), sim, total, rtf, tty ? "   " : "\n");
}

}  // namespace

int mission_cmd(const Args& a) {
  MissionOptions o;
  o.oracles = oracles_from(a);
  compute_time_from(a, o);
  o.world = a.get("world", o.world);
  o.out_dir = a.get("out", o.out_dir);
  o.mission_file = a.get("mission");
  o.ugvs = static_cast<int>(number(a, "ugvs", o.ugvs));
  o.seed = static_cast<std::uint64_t>(number(a, "seed", static_cast<double>(o.seed)));
  o.comm_range_m = number(a, "comm-range", o.comm_range_m);
  o.init_error_m = number(a, "init-error", o.init_error_m);
  o.init_yaw_error_deg = number(a, "init-yaw-error", o.init_yaw_error_deg);
  o.init_sigma_m = number(a, "init-sigma", 0);
  o.uav_altitude_m = number(a, "altitude", o.uav_altitude_m);
  o.max_duration_s = a.has("max-duration") ? number(a, "max-duration", 0) : 0;
  if (a.has("max-duration") && !(o.max_duration_s > 0)) usage_error("--max-duration must be > 0");
  o.lidar_columns = static_cast<int>(number(a, "lidar-columns", o.lidar_columns));
  o.threads = static_cast<int>(number(a, "threads", 0));
  o.parallel_robots = !a.has("serial-robots");
  o.web_port = static_cast<int>(number(a, "web-port", 0));
  o.uav_cache = a.get("uav-cache");
  o.uav_cache_build = a.get("uav-cache-build");
  if (!o.uav_cache_build.empty() && o.uav_cache.empty()) usage_error("--uav-cache-build needs --uav-cache DIR");
  if (!o.uav_cache_build.empty() && !std::filesystem::is_regular_file(o.uav_cache_build)) usage_error("--uav-cache-build " + o.uav_cache_build + ": no such file");
  o.web_pace = number(a, "pace", 0);
  o.status_period_s = a.has("verbose") ? number(a, "verbose", 30) : 0;
  if (o.ugvs < 1 || o.ugvs > 32) usage_error("--ugvs must be 1..32");
  if (o.comm_range_m < 0 || o.init_error_m < 0) usage_error("--comm-range, --init-error must be >= 0");
  if (a.has("init-sigma") && !(o.init_sigma_m > 0)) usage_error("--init-sigma must be > 0");
  if (o.web_port < 0 || o.web_port > 65535) usage_error("--web-port must be 1..65535");
  if (a.has("kill-ugv"))
    for (const auto& k : a.opt.at("kill-ugv")) {
      const auto at = k.find('@');
      if (at == std::string::npos) usage_error("--kill-ugv needs I@T, got '" + k + "'");
      const int i = std::atoi(k.substr(0, at).c_str());
      const double t = std::atof(k.substr(at + 1).c_str());
      if (i < 1 || i > o.ugvs || !(t >= 0)) usage_error("--kill-ugv I@T: I in 1..ugvs, T >= 0, got '" + k + "'");
      o.kills.push_back(RunOptions::Kill{i - 1, t});
    }
  if (a.has("kill-base")) o.kills.push_back(RunOptions::Kill{-1, number(a, "kill-base", 0)});
  for (const char* key : {"set", "set-uav"})
    if (a.has(key))
      for (const auto& s : a.opt.at(key)) {
        if (s.find('=') == std::string::npos || s.find('.') == std::string::npos) usage_error(std::string("--") + key + " needs SECTION.KEY=VALUE, got '" + s + "'");
        (std::string(key) == "set" ? o.ugv_config : o.uav_config).push_back(s);
      }
  const std::string rec = a.get("record", "light");
  if (rec == "none") o.record = RecordLevel::kNone;
  else if (rec == "light") o.record = RecordLevel::kLight;
  else if (rec == "full") o.record = RecordLevel::kFull;
  else usage_error("--record must be none, light or full");
  const bool tty = isatty(2) != 0;
  const bool show = !a.has("quiet");
  double last_print = -1;
  std::fprintf(stderr, "mission: 1 quadrotor + %d ground robots on world '%s' (seed %llu)%s -> %s\n", o.ugvs, o.world.c_str(),
               static_cast<unsigned long long>(o.seed), o.web_port > 0 ? (", live page on http://localhost:" + std::to_string(o.web_port) + "/").c_str() : "",
               o.out_dir.c_str());
  auto m = run_mission(o, [&](double sim, double total, double rtf) {
    if (show) progress_bar(sim, total, rtf, tty, last_print);
  });
  if (show && tty) std::fprintf(stderr, "\n");
  if (!m) return fail(m.error());
  const MissionMetrics& r = m.value();
  std::printf("targets visited %u of %u (regions found %u, visited %u); mission time %.0f s%s\n", r.targets_visited, r.targets_total,
              r.regions_found, r.regions_visited, r.mission_time_s, r.completed ? "" : " (time cap reached)");
  std::printf("localization error mean %.2f m, p95 %.2f m (odometry alone %.1f m); false visits %u, failed goals %u, collisions %llu\n",
              r.loc_error_mean_m, r.loc_error_p95_m, r.odom_only_error_mean_m, r.false_visits, r.failed_goals, static_cast<unsigned long long>(r.collisions));
  std::printf("map class accuracy %.3f; %.1f MB on air; real-time factor %.2fx; report: %s/report.md\n", r.map_class_accuracy,
              static_cast<double>(r.bytes_on_air) / 1e6, r.realtime_factor, o.out_dir.c_str());
  if (r.uav_replay.mode != "live") std::printf("quadrotor: %s (%s)\n", r.uav_replay.mode.c_str(), r.uav_replay.file.c_str());
  return 0;
}

const char kHilHelp[] =
    "airground-sim hil — hardware in the loop: the simulated world served to the real role binaries over\n"
    "the devices' wire protocols, in real time. Each ground robot's airground-ugv gets Ouster OS-1 packets on\n"
    "its lidar UDP port (the surface's albedo in the reflectivity byte) and its two ODrive controllers over\n"
    "the cannelloni CAN-over-UDP bridge; airground-uav gets UBX NAV-PVT on a pseudo-terminal (the receiver's\n"
    "serial port), a simulated PX4's HEARTBEAT and ATTITUDE on another (TELEM2) and RGB camera frames through\n"
    "the camera stage's frame-stream replay (a FIFO), which its own VO tracks;\n"
    "airground-base serves the live page. The processes are configured only by the YAML files written to\n"
    "DIR/config/ and talk gossip over UDP on the loopback interface. The run ends when every ground robot\n"
    "reports 'done' to the base station (or at --max-duration).\n\n"
    "Usage: airground-sim hil --world W --mission M.yaml --out DIR [options]\n\n"
    "Writes DIR/hil_report.md (robots, wire traffic, every stage's timing against its budget), DIR/hil.json,\n"
    "DIR/trajectories.png (truth white, the robots' own estimates red), DIR/base_state.json, DIR/mission.jsonl\n"
    "(the base's mission log), DIR/logs/<robot>.log and the robots' CAN recordings and odometry.\n"
    "Exit status: 0 mission done, 1 not done or a robot process failed, 2 usage error.\n\n"
    "Options:\n"
    "  --world W              world folder or 'default' (default)\n"
    "  --mission M.yaml       the mission: team, starts, guesses, waypoints, survey (required)\n"
    "  --out DIR              (build/hil)\n"
    "  --bin-dir DIR          where airground-uav/-ugv/-base are (next to airground-sim)\n"
    "  --max-duration T       wall-clock seconds before the run is cut off (300)\n"
    "  --lidar-columns C      512, 1024 or 2048 (1024)\n"
    "  --lidar-profile P      Ouster packet profile: LEGACY, RNG19_RFL8_SIG16_NIR16 (default),\n"
    "                         RNG19_RFL8_SIG16_NIR16_DUAL or RNG15_RFL8_NIR8\n"
    "  --seed S               sensor noise (1)\n"
    "  --oracle labels,vo     ablation (field mode without it): labels = the true class in the frames and the\n"
    "                         reflectivity byte, used by the robots; vo = the simulator's odometry in the frame\n"
    "                         stream, taken by the quadrotor's pose graph instead of its own VO\n"
    "  --quiet                no progress lines\n"
    "  --record none|mcap     DIR/recording.mcap (mcap, the default: truth, the poses the base heard, sensors) or nothing\n";

int hil_cmd(const Args& a) {
  HilOptions o;
  o.world = a.get("world", o.world);
  o.mission_file = a.get("mission");
  o.out_dir = a.get("out", o.out_dir);
  o.bin_dir = a.get("bin-dir");
  o.max_duration_s = number(a, "max-duration", o.max_duration_s);
  o.lidar_columns = static_cast<int>(number(a, "lidar-columns", o.lidar_columns));
  o.lidar_profile = a.get("lidar-profile", o.lidar_profile);
  o.seed = static_cast<std::uint64_t>(number(a, "seed", static_cast<double>(o.seed)));
  o.progress = !a.has("quiet");
  o.record = record_mcap(a);
  o.oracles = oracles_from(a);
  if (o.mission_file.empty()) usage_error("hil needs --mission FILE.yaml");
  if (!(o.max_duration_s > 0)) usage_error("--max-duration must be positive");
  auto r = run_hil(o);
  if (!r) {
    std::fprintf(stderr, "airground-sim hil: %s\n", r.error().message.c_str());
    return 1;
  }
  const HilResult& h = r.value();
  std::printf("hil: mission %s after %.1f s; report %s/hil_report.md\n", h.mission_done ? "done" : "NOT done", h.duration_s, o.out_dir.c_str());
  std::printf("%-6s %-14s %8s %10s %10s %10s %10s %8s\n", "robot", "stage", "runs", "p50_us", "p99_us", "max_us", "budget_us", "overruns");
  for (const HilStageTiming& t : h.timing)
    std::printf("%-6s %-14s %8llu %10.1f %10.1f %10.1f %10.0f %8llu%s\n", t.robot.c_str(), t.stage.c_str(), static_cast<unsigned long long>(t.runs),
                t.p50_us, t.p99_us, t.max_us, t.budget_us, static_cast<unsigned long long>(t.overruns), t.p99_us > t.budget_us ? "  over budget" : "");
  for (const HilRobot& rb : h.robots)
    if (!rb.final_state.empty())
      std::printf("%s: %s, %.1f m driven, localization error final %.2f m, mean %.2f m, max %.2f m, %llu collisions\n", rb.name.c_str(),
                  rb.final_state.c_str(), rb.distance_m, rb.final_error_m, rb.mean_error_m, rb.max_error_m, static_cast<unsigned long long>(rb.collisions));
  return h.mission_done ? 0 : 1;
}

}  // namespace ag::sim::cli
