// airground-sim eval mapping, eval localization and eval planning: one part of the robots' software in the
// simulator, scored against the world.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <string>

#include "airground/sim/eval_localization.hpp"
#include "airground/sim/eval_mapping.hpp"
#include "airground/sim/eval_planning.hpp"
#include "cli.hpp"

namespace ag::sim::cli {

const char kEvalMappingHelp[] =
    "airground-sim eval mapping --world W --seed S --out DIR [options]\n\n"
    "Flies a lawnmower survey over the world with the simulator's camera, GPS and visual-odometry noise,\n"
    "runs the quadrotor's real mapping stages (pose graph, keyframes, dense stereo, ortho-map) in lockstep,\n"
    "and scores the map against the world. Writes DIR/metrics.json (map_class_accuracy, map_coverage,\n"
    "elevation_rmse_ground_m, elevation_rmse_m, georeg_error_m, scale_error, keyframes, ...), report.md,\n"
    "map_class/map_rgb/map_elevation .png and .tif (GeoTIFF in the datum's UTM zone).\n"
    "Defaults: --world default --seed 1 --out eval-mapping.\n\n"
    "Options:\n"
    "  --altitude M            survey altitude above the start (40)   --speed V   survey speed (5 m/s)\n"
    "  --overlap F             side overlap of the survey lines (0.3)\n"
    "  --compute-time MODE     model (default): a robot stage's outputs show after its modelled\n"
    "                          compute time on the robot's CPU; measured: this machine's, scaled; off\n"
    "  --target-cpu CPU        nuc|ryzen|xavier-nx for every robot (quadrotor NUC, ground robots Ryzen)\n"
    "  --oracle labels,vo      ablation: labels = the camera's true classes instead of ErfNet's (segmentation.labels\n"
    "                          gt); vo = the simulator's VO model (true motion, scaled, noisy) instead of the\n"
    "                          quadrotor's own vo stage on the rendered frames; the report says so\n"
    "  --vo-scale S            with --oracle vo: the odometry starts with exactly this scale (VO units per metre)\n"
    "  --tracking-loss-at T    with --oracle vo: force one odometry tracking loss T s into the flight\n"
    "  --gps-outlier-at T      one GPS fix T s into the flight is off by --gps-outlier-m (50) metres\n"
    "  --no-random-faults      no random tracking losses or GPS dropouts\n"
    "  --max-duration T        stop after T simulated seconds even if the survey is not done (3600)\n"
    "  --config-dir DIR        simulator model overrides (as for run)\n"
    "  --erfnet WEIGHTS.agw    ErfNet with these weights instead of the shipped ones (config/erfnet/erfnet_c7.agw)\n"
    "  --set SECTION.KEY=VALUE quadrotor role parameter (repeatable), e.g. segmentation.threads=2\n"
    "  --quiet                 no progress line\n"
    "  --record none|mcap      DIR/recording.mcap (mcap, the default) or nothing\n";

const char kEvalPlanningHelp[] =
    "airground-sim eval planning --world W --seed S --pairs 20 --out DIR [options]\n\n"
    "The ground robot's global planner (its 'planner' parameters) on the world's true class map at the\n"
    "aerial map's 0.5 m cells, between --pairs random points (by seed) that keep the minimum clearance,\n"
    "are connected and at least --min-distance apart. Each route is compared with the shortest\n"
    "8-connected grid path through traversable cells that keep the clearance (planner.min_clearance_m),\n"
    "checked for cells it crosses that are not traversable or too close to an obstacle, and driven by the\n"
    "drive controller (its 'drive' parameters) on the simulated differential-drive robot with the\n"
    "ground-truth pose (the vehicle model counts collisions on the 0.25 m world). Reached: the follower\n"
    "arrived within 1 m of the goal in 60 s + 3x the route's driving time.\n\n"
    "Writes DIR/metrics.json: path_length_ratio_mean, path_length_ratio_max (route length / grid optimum),\n"
    "min_clearance_ratio_mean (route's smallest clearance / min_clearance_m, >= 1 keeps it), reached,\n"
    "collisions, failures (not planned, through a blocked cell, too close, or not reached), build and\n"
    "query times (thread CPU time), and every pair's figures.\n"
    "Defaults: --world default --seed 1 --pairs 20 --out eval-planning.\n\n"
    "Options:\n"
    "  --min-distance M         pairs at least M metres apart (40)\n"
    "  --speed V                top driving speed (1.2 m/s)\n"
    "  --no-drive               plan and check only\n"
    "  --pose truth|localizer   drive with the true pose (truth), or with the robot's own stages in the\n"
    "                           lockstep runner: its localizer's pose, planner, tracker, drive (localizer)\n"
    "  --set SECTION.KEY=VALUE  a planner.* or drive.* parameter (repeatable)\n"
    "  --compute-time MODE      model (default): a robot stage's outputs show after its modelled\n"
    "                           compute time on the robot's CPU; measured: this machine's, scaled; off\n"
    "  --target-cpu CPU         nuc|ryzen|xavier-nx for every robot (quadrotor NUC, ground robots Ryzen)\n"
    "  --oracle labels          with --pose localizer: ablation, the LiDAR points carry the true classes and the\n"
    "                           localizer uses them (metrics.json lists it)\n"
    "  --quiet                  no progress line\n"
    "  --record none|mcap       with --pose localizer: each drive's DIR/drive_N/recording.mcap (mcap) or nothing\n";

const char kEvalLocalizationHelp[] =
    "airground-sim eval localization --world W --seed S --init-error 16 --map gt|online --out DIR [options]\n\n"
    "One ground robot drives a loop of about --route-km over the roads (planned from ground truth through\n"
    "far-apart drivable points, from the staging pad; deterministic by seed) with its initial pose guess off\n"
    "by exactly --init-error metres (direction by seed) and --init-yaw-error degrees (sign by seed). Its real\n"
    "role table (its shipped configuration) gets the simulated LiDAR (no classes), wheel odometry, that guess and the aerial map\n"
    "tiles: --map gt the world's class map at 0.5 m, --map online the quadrotor's ortho-map as its mapping\n"
    "stages build it (it flies its survey; the robot waits at its start until the map knows\n"
    "--wait-map-fraction of the cells within --wait-map-radius and --wait-map-route of those along its\n"
    "route, then drives while the map grows and is corrected; tiles\n"
    "reach the robot as soon as they change: perfect comms until gossip over the radio), --map none no map.\n"
    "The pose the robot publishes on its 'localization' channel is sampled at 10 Hz against the truth.\n\n"
    "Writes DIR/metrics.json (converged, convergence_time_s, loc_error_mean_m, loc_error_p95_m,\n"
    "yaw_error_mean_deg, odom_only_error_mean_m, ...), report.md (with the metric definitions),\n"
    "samples.csv, trajectory.png (truth, estimate, odometry only over the class map) and error.png.\n"
    "A sample is good when the robot's status is tracking, its pose at most 0.5 s old and within --radius\n"
    "of the truth at its stamp; converged = from some sample on every sample is good; the errors are over\n"
    "those samples; convergence_time_s is the driving time to the first of them. Without a localization\n"
    "stage on the robot, converged is false.\n"
    "Defaults: --world default --seed 1 --init-error 16 --map gt --out eval-localization.\n\n"
    "Options:\n"
    "  --init-yaw-error D       initial yaw error [deg] (30)\n"
    "  --route-km K             route length (2)                  --speed V   driving speed (1.2 m/s)\n"
    "  --labels gt|geometric    the robot's scan labelling (localization.labels; shipped: geometric); gt needs\n"
    "                           --oracle labels\n"
    "  --compute-time MODE      model (default): a robot stage's outputs show after its modelled\n"
    "                           compute time on the robot's CPU; measured: this machine's, scaled; off\n"
    "  --target-cpu CPU         nuc|ryzen|xavier-nx for every robot (quadrotor NUC, ground robots Ryzen)\n"
    "  --oracle labels          ablation: the LiDAR points carry the world's classes and the robot labels its scans\n"
    "                           with them (gt); metrics.json and the report list it\n"
    "  --set SECTION.KEY=VALUE  any parameter of the ground robot's role config (repeatable)\n"
    "  --stand-still-s S        the robot stands still S seconds ...\n"
    "  --stand-still-at T       ... from simulated time T (120; with --map online the wait counts)\n"
    "  --yaw-drift-at-rest R    the wheel odometry's yaw drift while standing [rad/s] (model default 0)\n"
    "  --radius M               convergence radius (3 m)\n"
    "  --wait-map-radius M      --map online: wait for the map within M metres of the start, inside the\n"
    "                           world (ground beyond its edge is never mapped; 30; 0 = start at once)\n"
    "  --wait-map-fraction F    ... until it knows this fraction of those cells (0.5)\n"
    "  --wait-map-route F       ... and this fraction of the cells within 3 m of its route (0.8; 0 = drive\n"
    "                           into ground the quadrotor has not seen yet, where it can only dead-reckon)\n"
    "  --lidar-columns C        512|1024|2048 (1024)\n"
    "  --max-duration T         stop after T simulated seconds (default from the route length)\n"
    "  --config-dir DIR         simulator model overrides (as for run)\n"
    "  --threads N              sensor worker threads (all cores)\n"
    "  --quiet                  no progress line\n"
    "  --record none|mcap       DIR/recording.mcap (mcap, the default) or nothing\n";

int eval_mapping_cmd(const Args& a) {
  EvalMappingOptions o;
  o.oracles = oracles_from(a);
  compute_time_from(a, o);
  o.world = a.get("world", o.world);
  o.seed = static_cast<std::uint64_t>(number(a, "seed", static_cast<double>(o.seed)));
  o.out_dir = a.get("out", o.out_dir);
  o.altitude_m = number(a, "altitude", o.altitude_m);
  o.speed_mps = number(a, "speed", o.speed_mps);
  o.overlap = number(a, "overlap", o.overlap);
  o.vo_scale = number(a, "vo-scale", 0);
  if ((a.has("vo-scale") || a.has("tracking-loss-at")) && std::find(o.oracles.begin(), o.oracles.end(), "vo") == o.oracles.end())
    usage_error("--vo-scale and --tracking-loss-at shape the simulator's VO model: they need --oracle vo");
  o.tracking_loss_at_s = number(a, "tracking-loss-at", -1);
  o.gps_outlier_at_s = number(a, "gps-outlier-at", -1);
  o.gps_outlier_m = number(a, "gps-outlier-m", o.gps_outlier_m);
  o.random_faults = !a.has("no-random-faults");
  o.max_duration_s = number(a, "max-duration", o.max_duration_s);
  o.config_dir = a.get("config-dir");
  o.quiet = a.has("quiet");
  o.record = record_mcap(a);
  if (a.has("set")) {
    for (const auto& s : a.opt.at("set")) {
      if (s.find('=') == std::string::npos || s.find('.') == std::string::npos) usage_error("--set needs SECTION.KEY=VALUE, got '" + s + "'");
      o.set.push_back(s);
    }
  }
  if (a.has("erfnet")) {  // ErfNet labels instead of the camera's ground truth: the segmentation stage on, the mapper on its output
    o.set.push_back("segmentation.labels=erfnet");
    o.set.push_back("segmentation.weights=" + a.get("erfnet"));
    o.set.push_back("ortho_map.keyframes_channel=keyframes_labelled");
  }
  if (!(o.speed_mps > 0) || !(o.altitude_m > 0)) usage_error("--speed and --altitude must be positive");
  const bool tty = isatty(2) != 0;
  double last_print = -1;
  auto progress = [&](double sim, double, double rtf) {
    if (o.quiet) return;
    if (!tty && sim - last_print < 60) return;
    last_print = sim;
    std::fprintf(stderr, "%ssurvey flight: %7.1f s simulated, real-time factor %.1fx%s", tty ? "\r" : "", sim, rtf, tty ? "   " : "\n");
  };
  std::fprintf(stderr, "mapping evaluation on world '%s' (seed %llu) -> %s\n", o.world.c_str(), static_cast<unsigned long long>(o.seed), o.out_dir.c_str());
  auto m = eval_mapping(o, progress);
  if (!o.quiet && tty) std::fprintf(stderr, "\n");
  if (!m) return fail(m.error());
  const MappingMetrics& r = m.value();
  std::printf("map_class_accuracy %.4f  map_coverage %.4f  elevation_rmse_ground_m %.3f  elevation_rmse_m %.3f\n",
              r.map_class_accuracy, r.map_coverage, r.elevation_rmse_ground_m, r.elevation_rmse_m);
  std::printf("elevation_coverage %.4f  ", r.elevation_coverage);
  std::printf("elevation on flat ground: bias %+.3f m, |error| p50 %.3f m p95 %.3f m; all cells |error| p95 %.3f m, %.2f%% off by > 2 m\n",
              r.elevation_bias_ground_m, r.elevation_p50_ground_m, r.elevation_p95_ground_m, r.elevation_p95_m, 100.0 * r.elevation_outliers);
  std::printf("keyframe poses: height RMS %.3f m, tilt RMS %.3f deg, heading RMS %.3f deg\n", r.pose_z_rmse_m, r.pose_tilt_rmse_deg, r.pose_yaw_rmse_deg);
  std::printf("georeg_error_m %.3f  scale_error %.4f  keyframes %llu  tiles %llu (rebuilt %llu)  GPS rejected %llu  VO segments %llu\n",
              r.georeg_error_m, r.scale_error, static_cast<unsigned long long>(r.keyframes), static_cast<unsigned long long>(r.tiles),
              static_cast<unsigned long long>(r.tiles_rebuilt), static_cast<unsigned long long>(r.gps_rejected),
              static_cast<unsigned long long>(r.vo_segments));
  std::printf("stages: pose_graph p99 %.1f ms, ortho_map p99 %.1f ms, overruns %llu; resident %.0f MB (grew %.0f MB while mapping; map %.0f MB); %.0f s simulated in %.0f s\n",
              r.pose_graph_p99_ms, r.ortho_map_p99_ms, static_cast<unsigned long long>(r.stage_overruns), r.resident_mb,
              r.resident_growth_mb, r.map_memory_mb, r.sim_s, r.wall_s);
  std::printf("metrics: %s/metrics.json\n", o.out_dir.c_str());
  return 0;
}

int eval_localization_cmd(const Args& a) {
  EvalLocalizationOptions o;
  o.oracles = oracles_from(a);
  compute_time_from(a, o);
  o.world = a.get("world", o.world);
  o.seed = static_cast<std::uint64_t>(number(a, "seed", static_cast<double>(o.seed)));
  o.out_dir = a.get("out", o.out_dir);
  o.init_error_m = number(a, "init-error", o.init_error_m);
  o.init_yaw_error_deg = number(a, "init-yaw-error", o.init_yaw_error_deg);
  const std::string map = a.get("map", "gt");
  if (map == "gt") o.map = UgvMapSource::kGroundTruth;
  else if (map == "online") o.map = UgvMapSource::kOnline;
  else if (map == "none") o.map = UgvMapSource::kNone;
  else usage_error("--map must be gt, online or none");
  o.route_km = number(a, "route-km", o.route_km);
  o.speed_mps = number(a, "speed", o.speed_mps);
  o.labels = a.get("labels");
  if (a.has("labels") && o.labels != "gt" && o.labels != "geometric") usage_error("--labels must be gt or geometric");
  if (o.labels == "gt" && std::find(o.oracles.begin(), o.oracles.end(), "labels") == o.oracles.end())
    usage_error("--labels gt needs the scans' true classes, which a LiDAR does not give: name the ablation --oracle labels");
  if (a.has("set")) {
    const auto& kv = a.opt.at("set");
    if (kv.empty()) usage_error("--set needs SECTION.KEY=VALUE");
    for (const auto& s : kv)
      if (s.find('=') == std::string::npos || s.find('.') == std::string::npos) usage_error("--set needs SECTION.KEY=VALUE, got '" + s + "'");
    o.set = kv;
  }
  o.stand_still_s = number(a, "stand-still-s", 0);
  o.stand_still_at_s = number(a, "stand-still-at", o.stand_still_at_s);
  if (a.has("yaw-drift-at-rest")) {
    o.yaw_drift_at_rest = number(a, "yaw-drift-at-rest", 0);
    o.yaw_drift_at_rest_set = true;
  }
  o.convergence_radius_m = number(a, "radius", o.convergence_radius_m);
  o.wait_map_radius_m = number(a, "wait-map-radius", o.wait_map_radius_m);
  o.wait_map_fraction = number(a, "wait-map-fraction", o.wait_map_fraction);
  o.wait_map_route = number(a, "wait-map-route", o.wait_map_route);
  if (o.wait_map_route < 0 || o.wait_map_route > 1) usage_error("--wait-map-route must be in 0..1");
  o.lidar_columns = static_cast<int>(number(a, "lidar-columns", o.lidar_columns));
  o.max_duration_s = number(a, "max-duration", 0);
  o.config_dir = a.get("config-dir");
  o.threads = static_cast<int>(number(a, "threads", 0));
  o.quiet = a.has("quiet");
  o.record = record_mcap(a);
  if (!(o.init_error_m >= 0) || !(o.init_yaw_error_deg >= 0) || o.init_yaw_error_deg > 180)
    usage_error("--init-error must be >= 0 and --init-yaw-error in 0..180");
  if (!(o.route_km > 0) || !(o.speed_mps > 0) || !(o.convergence_radius_m > 0)) usage_error("--route-km, --speed and --radius must be positive");
  if (o.stand_still_s < 0 || o.stand_still_at_s < 0) usage_error("--stand-still-s and --stand-still-at must be >= 0");
  if (o.wait_map_radius_m < 0 || o.wait_map_fraction < 0 || o.wait_map_fraction > 1) usage_error("--wait-map-radius >= 0, --wait-map-fraction in 0..1");
  const bool tty = isatty(2) != 0;
  double last_print = -1;
  auto progress = [&](const LocalizationProgress& p) {
    if (o.quiet) return;
    if (!tty && p.sim_s - last_print < 60) return;
    last_print = p.sim_s;
    char err[32] = "-";
    if (p.error_m >= 0) std::snprintf(err, sizeof err, "%.2f m", p.error_m);
    std::fprintf(stderr, "%ssim %7.1f s  driven %6.0f / %.0f m%s  localization: %-12s error %-9s  real-time factor %.1fx%s",
                 tty ? "\r" : "", p.sim_s, p.distance_m, p.route_m, p.released ? "" : " (waiting for the map)", p.status, err,
                 p.rtf, tty ? "   " : "\n");
  };
  std::fprintf(stderr, "localization evaluation on world '%s' (seed %llu, map %s, initial error %.1f m / %.0f deg) -> %s\n",
               o.world.c_str(), static_cast<unsigned long long>(o.seed), map.c_str(), o.init_error_m, o.init_yaw_error_deg, o.out_dir.c_str());
  auto m = eval_localization(o, progress);
  if (!o.quiet && tty) std::fprintf(stderr, "\n");
  if (!m) return fail(m.error());
  const LocalizationMetrics& r = m.value();
  if (!r.localization_published)
    std::printf("the ground robot never published a localization (no localization stage in its role table): not converged\n");
  if (r.converged)
    std::printf("converged after %.1f s of driving (%.0f m): loc_error_mean_m %.2f  loc_error_p95_m %.2f  yaw_error_mean_deg %.2f  "
                "odom_only_error_mean_m %.2f  divergences %llu\n",
                r.convergence_time_s, r.convergence_distance_m, r.loc_error_mean_m, r.loc_error_p95_m, r.yaw_error_mean_deg,
                r.odom_only_error_mean_m, static_cast<unsigned long long>(r.divergences));
  else
    std::printf("not converged (tracking %.0f %% of the samples)  odom_only_error_mean_m %.2f\n", 100.0 * r.tracking_fraction,
                r.odom_only_error_mean_m);
  std::printf("route %.0f m, driven %.0f m, %llu map tiles and %llu scans published; %.0f s simulated in %.0f s; metrics: %s/metrics.json\n",
              r.route_length_m, r.distance_m, static_cast<unsigned long long>(r.tiles_published),
              static_cast<unsigned long long>(r.scans_published), r.sim_s, r.wall_s, o.out_dir.c_str());
  return 0;
}

int eval_planning_cmd(const Args& a) {
  EvalPlanningOptions o;
  o.oracles = oracles_from(a);
  compute_time_from(a, o);
  o.world = a.get("world", o.world);
  o.seed = static_cast<std::uint64_t>(number(a, "seed", static_cast<double>(o.seed)));
  o.pairs = static_cast<int>(number(a, "pairs", o.pairs));
  o.out_dir = a.get("out", o.out_dir);
  o.min_pair_distance_m = number(a, "min-distance", o.min_pair_distance_m);
  o.speed_mps = number(a, "speed", o.speed_mps);
  o.drive = !a.has("no-drive");
  const std::string pose = a.get("pose", "truth");
  if (pose != "truth" && pose != "localizer") usage_error("--pose must be truth or localizer");
  o.localizer_pose = pose == "localizer";
  o.quiet = a.has("quiet");
  o.record = record_mcap(a);
  if (a.has("set")) o.set = a.opt.at("set");
  for (const auto& s : o.set)
    if (s.rfind("planner.", 0) != 0 && s.rfind("drive.", 0) != 0) usage_error("--set takes planner.KEY=VALUE or drive.KEY=VALUE, got '" + s + "'");
  if (o.pairs < 1 || o.pairs > 10000) usage_error("--pairs must be in 1..10000");
  if (!(o.min_pair_distance_m >= 0) || !(o.speed_mps > 0)) usage_error("--min-distance must be >= 0 and --speed > 0");
  const bool tty = isatty(2) != 0;
  auto progress = [&](const PlanningProgress& p) {
    if (o.quiet) return;
    std::fprintf(stderr, "%s%s: pair %d / %d%s", tty ? "\r" : "", p.phase, p.pair, p.pairs, tty ? "      " : "\n");
  };
  std::fprintf(stderr, "planning evaluation on world '%s' (seed %llu, %d pairs) -> %s\n", o.world.c_str(),
               static_cast<unsigned long long>(o.seed), o.pairs, o.out_dir.c_str());
  auto m = eval_planning(o, progress);
  if (!o.quiet && tty) std::fprintf(stderr, "\n");
  if (!m) return fail(m.error());
  const PlanningMetrics& r = m.value();
  std::printf("roadmap: %u nodes, %u edges, built in %.0f ms; queries %.2f ms mean, %.2f ms max\n", r.nodes, r.edges, r.build_ms, r.query_ms_mean,
              r.query_ms_max);
  std::printf("path_length_ratio_mean %.3f  path_length_ratio_max %.3f  min_clearance_ratio_mean %.2f (min %.2f)  through blocked %d  too close %d\n",
              r.path_length_ratio_mean, r.path_length_ratio_max, r.min_clearance_ratio_mean, r.min_clearance_ratio_min, r.through_blocked, r.too_close);
  if (o.drive) std::printf("reached %d / %d  collisions %llu  failures %d  (%s pose)\n", r.reached, r.pairs, static_cast<unsigned long long>(r.collisions), r.failures,
                           o.localizer_pose ? "localizer" : "true");
  else std::printf("failures %d (not driven)\n", r.failures);
  std::printf("metrics: %s/metrics.json\n", o.out_dir.c_str());
  return 0;
}

}  // namespace ag::sim::cli
