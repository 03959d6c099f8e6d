// airground-sim: worlds (generate, import, show), one camera frame or LiDAR scan, and team runs.
#include <sys/wait.h>
#include <unistd.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string_view>
#include <cctype>
#include <string>
#include <thread>
#include <vector>

#include "airground/platform/log.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/sim/gps.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/radio.hpp"
#include "airground/sim/visual_odometry.hpp"
#include "airground/sim/wheel_odometry.hpp"
#include "airground/sim/eval_localization.hpp"
#include "airground/sim/eval_mapping.hpp"
#include "airground/sim/eval_planning.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/importer.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/raycast.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/eval_mission.hpp"
#include "airground/sim/hil.hpp"
#include "airground/sim/world_png.hpp"

namespace fs = std::filesystem;
int segment_cmd(int argc, char** argv);  // segment.cpp
int vo_cmd(int argc, char** argv);       // vo.cpp
int eval_vo_cmd(int argc, char** argv);  // vo.cpp
int lidar_info_cmd(int argc, char** argv);  // lidar_info.cpp
int study_cmd(int argc, char** argv);       // study.cpp
int survey_plan_cmd(int argc, char** argv);  // survey_plan.cpp
using namespace ag;
using namespace ag::sim;

namespace {

constexpr const char* kUsage =
    "airground-sim — the world our robots live in when there is no field\n\n"
    "Usage:\n"
    "  airground-sim world generate --seed S [--size METRES] [--targets N] [--resolution M] --out DIR\n"
    "  airground-sim world import --classes RASTER.png --legend LEGEND.yaml --resolution METRES_PER_PIXEL\n"
    "                             --out DIR [--elevation RASTER.tif] [--color IMAGE.png] [--name NAME]\n"
    "                             [--datum LAT,LON,HEIGHT]   (--px-per-m P instead of --resolution)\n"
    "  airground-sim world show DIR --out DIR\n"
    "  airground-sim render --world W --pose X Y Z ROLL PITCH YAW --out DIR [--scale 0.5] [--config camera.yaml]\n"
    "  airground-sim scan --world W --pose X Y YAW --out DIR [--columns 512|1024|2048] [--height 0.6]\n"
    "  airground-sim run --world W --ugvs N --seed S --duration T --out DIR [options]\n"
    "  airground-sim eval mapping --world W --seed S --out DIR [options]   (see eval mapping --help)\n"
    "  airground-sim eval vo --world W --seed S --out DIR [options]   (the quadrotor's visual odometry; eval vo --help)\n"
    "  airground-sim vo --images DIR --camera CAMERA.yaml --out DIR   (visual odometry over your own images)\n"
    "  airground-sim eval localization --world W --seed S --init-error 16 --map gt|online --out DIR [options]\n"
    "                                  (see eval localization --help)\n"
    "  airground-sim eval planning --world W --seed S --pairs 20 --out DIR   (see eval planning --help)\n"
    "  airground-sim mission --world W --ugvs N --seed S [--comm-range METRES] [--mission FILE.yaml] --out DIR\n"
    "  airground-sim hil --world W --mission FILE.yaml --out DIR   (the real role binaries over the wire protocols)\n"
    "                        (a whole team mission and its report; see mission --help)\n"
    "  airground-sim study --ugvs 1,2,3,5,10 --comm-range 50,150,1000 --seeds K --out DIR   (a grid of missions;\n"
    "                        --slurm SDIR writes it as a Slurm job array)\n"
    "  airground-sim survey-plan --world W --out FILE.plan   (the quadrotor's survey as a QGroundControl plan)\n"
    "  airground-sim segment --weights FILE --image IMAGE.png --out DIR [--threads N]   (ErfNet: logits.npy,\n"
    "                        classes.png; see segment --help)\n"
    "  airground-sim lidar-info --pcap FILE --metadata FILE [--out DIR]   (an Ouster capture: sensor, profile,\n"
    "                        frames, errors; the first frame as PNGs and PLY; see lidar-info --help)\n"
    "  airground-sim config --out DIR   (every simulator model's parameters with units and ranges, as\n"
    "                                    YAML files that 'run --config-dir DIR' reads back)\n\n"
    "--world W is a world directory or 'default' (the built-in 400 m world, seed 42).\n"
    "Angles in radians, positions in metres in the world's map frame (x east, y north, origin at the centre).\n"
    "'airground-sim COMMAND --help' shows a command's options. Exit status: 0 ok, 1 failed, 2 bad usage.\n";

constexpr const char* kRunHelp =
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

constexpr const char* kEvalMappingHelp =
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

constexpr const char* kEvalPlanningHelp =
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

constexpr const char* kEvalLocalizationHelp =
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
    "  --wait-map-radius M      --map online: wait for the map within M metres of the start (30; 0 = start at once)\n"
    "  --wait-map-fraction F    ... until it knows this fraction of those cells (0.5)\n"
    "  --wait-map-route F       ... and this fraction of the cells within 3 m of its route (0.8; 0 = drive\n"
    "                           into ground the quadrotor has not seen yet, where it can only dead-reckon)\n"
    "  --lidar-columns C        512|1024|2048 (1024)\n"
    "  --max-duration T         stop after T simulated seconds (default from the route length)\n"
    "  --config-dir DIR         simulator model overrides (as for run)\n"
    "  --threads N              sensor worker threads (all cores)\n"
    "  --quiet                  no progress line\n"
    "  --record none|mcap       DIR/recording.mcap (mcap, the default) or nothing\n";

struct Args {
  std::vector<std::string> pos;
  std::map<std::string, std::vector<std::string>> opt;
  bool has(const std::string& k) const { return opt.count(k) != 0; }
  std::string get(const std::string& k, const std::string& def = "") const {
    auto it = opt.find(k);
    return it == opt.end() || it->second.empty() ? def : it->second.front();
  }
};

[[noreturn]] void usage_error(const std::string& msg) {
  std::fprintf(stderr, "airground-sim: %s (see --help)\n", msg.c_str());
  std::exit(2);
}

// --record none|mcap of the evaluations and hil: whether they write DIR/recording.mcap.
bool record_mcap(const Args& a) {
  const std::string r = a.get("record", "mcap");
  if (r != "none" && r != "mcap") usage_error("--record must be none or mcap, got '" + r + "'");
  return r == "mcap";
}

// Options take the following words up to the next "--" option; --pose takes several numbers.
Args parse(int argc, char** argv, int first) {
  Args a;
  std::string cur;
  for (int i = first; i < argc; ++i) {
    std::string s = argv[i];
    const bool is_opt = s.rfind("--", 0) == 0 && !(s.size() > 2 && (std::isdigit(static_cast<unsigned char>(s[2])) != 0 || s[2] == '.'));
    if (is_opt) {
      cur = s.substr(2);
      a.opt[cur];
    } else if (!cur.empty()) {
      a.opt[cur].push_back(s);
    } else {
      a.pos.push_back(s);
    }
  }
  return a;
}

// --oracle labels,vo: ground truth handed to the robots by name, an ablation; unknown names are an error.
std::vector<std::string> oracles_from(const Args& a) {
  std::vector<std::string> out;
  if (!a.has("oracle")) return out;
  for (const std::string& v : a.opt.at("oracle")) {
    std::size_t b = 0;
    while (b <= v.size()) {
      const std::size_t e = std::min(v.find(',', b), v.size());
      const std::string name = v.substr(b, e - b);
      if (name != "vo" && name != "labels") {
        std::fprintf(stderr, "airground-sim: --oracle: unknown oracle '%s' (known: labels, vo) (see --help)\n", name.c_str());
        std::exit(2);
      }
      if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
      b = e + 1;
    }
  }
  return out;
}

// --compute-time model|measured|off and --target-cpu nuc|ryzen|xavier-nx (docs/simulator.md, "Compute time").
template <class O>
void compute_time_from(const Args& a, O& o) {
  if (a.has("compute-time")) {
    auto m = ag::sim::parse_compute_time(a.get("compute-time"));
    if (!m) usage_error("--compute-time: " + m.error().message);
    o.compute_time = m.value();
  }
  if (a.has("target-cpu")) {
    auto c = ag::sim::parse_target_cpu(a.get("target-cpu"));
    if (!c) usage_error("--target-cpu: " + c.error().message);
    o.target_cpu = c.value();
  }
}

double number(const Args& a, const std::string& k, double def) {
  if (!a.has(k)) return def;
  const std::string v = a.get(k);
  char* end = nullptr;
  const double d = std::strtod(v.c_str(), &end);
  if (v.empty() || *end != '\0' || !std::isfinite(d)) usage_error("--" + k + " needs a number, got '" + v + "'");
  return d;
}

std::vector<double> numbers(const Args& a, const std::string& k, std::size_t n) {
  auto it = a.opt.find(k);
  if (it == a.opt.end() || it->second.size() != n) usage_error("--" + k + " needs " + std::to_string(n) + " numbers");
  std::vector<double> out;
  for (const auto& v : it->second) {
    char* end = nullptr;
    out.push_back(std::strtod(v.c_str(), &end));
    if (*end != '\0') usage_error("--" + k + ": '" + v + "' is not a number");
  }
  return out;
}

std::string required(const Args& a, const std::string& k) {
  if (!a.has(k) || a.get(k).empty()) usage_error("--" + k + " is required");
  return a.get(k);
}

int fail(const Error& e) {
  std::fprintf(stderr, "airground-sim: %s\n", e.message.c_str());
  return 1;
}

Datum parse_datum(const Args& a) {
  Datum d;
  if (!a.has("datum")) return d;
  const std::string v = a.get("datum");
  if (std::sscanf(v.c_str(), "%lf,%lf,%lf", &d.lat_deg, &d.lon_deg, &d.height_m) != 3 || std::abs(d.lat_deg) > 90 || std::abs(d.lon_deg) > 180)
    usage_error("--datum needs LAT,LON,HEIGHT in degrees and metres, got '" + v + "'");
  return d;
}

int world_generate(const Args& a) {
  GeneratorOptions o;
  o.seed = static_cast<std::uint64_t>(number(a, "seed", 1));
  o.size_m = number(a, "size", o.size_m);
  o.targets = static_cast<int>(number(a, "targets", o.targets));
  o.resolution = number(a, "resolution", o.resolution);
  o.datum = parse_datum(a);
  const std::string out = required(a, "out");
  std::fprintf(stderr, "generating a %.0f m world (seed %llu, %d targets, %.2f m cells)...\n", o.size_m,
               static_cast<unsigned long long>(o.seed), o.targets, o.resolution);
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<TargetCluster> targets;
  auto w = generate_world(o, &targets);
  if (!w) return fail(w.error());
  if (auto st = save_world(w.value(), out); !st) return fail(st.error());
  if (auto st = save_targets(targets, w.value().header.staging, out); !st) return fail(st.error());
  if (auto st = write_world_pngs(w.value(), (fs::path(out) / "png").string()); !st) return fail(st.error());
  std::printf("world %s: %dx%d cells, %zu target clusters, %.1f s; layer pictures in %s/png\n", out.c_str(),
              w.value().grid().width, w.value().grid().height, targets.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), out.c_str());
  return 0;
}

int world_import(const Args& a) {
  ImportOptions o;
  o.classes_path = required(a, "classes");
  o.legend_path = required(a, "legend");
  if (a.has("px-per-m")) {
    const double ppm = number(a, "px-per-m", 0);
    if (ppm <= 0) usage_error("--px-per-m must be positive");
    o.resolution_m_per_px = 1.0 / ppm;
  } else {
    o.resolution_m_per_px = number(a, "resolution", 0);
  }
  if (!(o.resolution_m_per_px > 0)) usage_error("--resolution METRES_PER_PIXEL (or --px-per-m) is required and positive");
  o.elevation_path = a.get("elevation");
  o.color_path = a.get("color");
  o.name = a.get("name", fs::path(o.classes_path).stem().string());
  o.datum = parse_datum(a);
  const std::string out = required(a, "out");
  auto w = import_world(o);
  if (!w) return fail(w.error());
  if (auto st = save_world(w.value(), out); !st) return fail(st.error());
  if (auto st = write_world_pngs(w.value(), (fs::path(out) / "png").string()); !st) return fail(st.error());
  std::printf("world %s: %dx%d cells at %.3f m; layer pictures in %s/png\n", out.c_str(), w.value().grid().width,
              w.value().grid().height, w.value().grid().resolution, out.c_str());
  return 0;
}

int world_show(const Args& a) {
  if (a.pos.empty()) usage_error("world show needs the world directory");
  const std::string out = required(a, "out");
  auto w = resolve_world(a.pos.front());
  if (!w) return fail(w.error());
  if (auto st = write_world_pngs(*w.value(), out); !st) return fail(st.error());
  std::printf("wrote the layers of %s to %s\n", a.pos.front().c_str(), out.c_str());
  return 0;
}

int render(const Args& a) {
  auto w = resolve_world(a.get("world", "default"));
  if (!w) return fail(w.error());
  const auto p = numbers(a, "pose", 6);
  const std::string out = required(a, "out");
  CameraModel model;
  CameraShading shading;
  if (a.has("config")) {
    auto m = CameraModel::load_file(a.get("config"));
    if (!m) return fail(m.error());
    model = m.value();
    auto s = CameraShading::load_file(a.get("config"));
    if (!s) return fail(s.error());
    shading = s.value();
  }
  if (a.has("scale")) model = model.scaled(number(a, "scale", 1.0));
  CameraRenderer renderer(*w.value(), model, shading);
  CameraFrame f;
  const auto t0 = std::chrono::steady_clock::now();
  renderer.render(Pose3{p[0], p[1], p[2], p[3], p[4], p[5]}, f);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  fs::create_directories(out);
  cv::Mat bgr, depth_mm;
  cv::cvtColor(f.rgb, bgr, cv::COLOR_RGB2BGR);
  f.depth.convertTo(depth_mm, CV_16U, 1000.0);
  cv::Mat depth_vis;
  double dmax = 0;
  cv::minMaxLoc(f.depth, nullptr, &dmax);
  f.depth.convertTo(depth_vis, CV_8U, dmax > 0 ? 255.0 / dmax : 1.0);
  cv::applyColorMap(depth_vis, depth_vis, cv::COLORMAP_VIRIDIS);
  const bool ok = cv::imwrite((fs::path(out) / "rgb.png").string(), bgr) &&
                  cv::imwrite((fs::path(out) / "class.png").string(), f.cls) &&
                  cv::imwrite((fs::path(out) / "class_colour.png").string(), [&] { cv::Mat c; cv::cvtColor(class_display_image(f.cls), c, cv::COLOR_RGB2BGR); return c; }()) &&
                  cv::imwrite((fs::path(out) / "depth_mm.png").string(), depth_mm) &&
                  cv::imwrite((fs::path(out) / "depth.png").string(), depth_vis);
  if (!ok) return fail(Error::make(ErrorCode::kIo, "cannot write images into " + out));
  std::printf("rendered %dx%d in %.1f ms: %s/{rgb,class,class_colour,depth_mm,depth}.png (class.png holds ids, depth_mm.png 16-bit mm)\n",
              f.rgb.cols, f.rgb.rows, ms, out.c_str());
  return 0;
}

int scan(const Args& a) {
  auto w = resolve_world(a.get("world", "default"));
  if (!w) return fail(w.error());
  const auto p = numbers(a, "pose", 3);
  const std::string out = required(a, "out");
  const int columns = static_cast<int>(number(a, "columns", 1024));
  const double height = number(a, "height", 0.6);
  auto beams = OusterBeamModel::load_default(columns);
  if (!beams) return fail(beams.error());
  const World& world = *w.value();
  const GridGeometry& g = world.grid();
  const int c = g.col(p[0]), r = g.row(p[1]);
  if (!g.contains(c, r)) usage_error("--pose is outside the world");
  LidarSimulator lidar(world, beams.value(), LidarNoise{});
  std::vector<LidarPoint> pts;
  const Pose3 pose{p[0], p[1], static_cast<double>(world.surface_at(c, r)) + height, 0, 0, p[2]};
  const auto t0 = std::chrono::steady_clock::now();
  lidar.scan(pose, 1, pts);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  fs::create_directories(out);
  std::ofstream ply(fs::path(out) / "scan.ply");
  ply << "ply\nformat ascii 1.0\ncomment airground-sim scan, sensor frame (x forward, y left, z up) [m]\nelement vertex "
      << pts.size() << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar class\nproperty ushort ring\n";
  ply << "end_header\n";
  for (const auto& q : pts) {
    const Rgb col = ClassTable::builtin().info(static_cast<ClassId>(q.cls)).color;
    ply << q.x << ' ' << q.y << ' ' << q.z << ' ' << int(col.r) << ' ' << int(col.g) << ' ' << int(col.b) << ' ' << int(q.cls) << ' ' << q.ring << '\n';
  }
  // Top-down picture, 60 m across, 10 px/m, forward up.
  constexpr int kPx = 600;
  cv::Mat top(kPx, kPx, CV_8UC3, cv::Scalar(20, 20, 20));
  for (const auto& q : pts) {
    const int u = static_cast<int>(kPx / 2 - q.y * 10), v = static_cast<int>(kPx / 2 - q.x * 10);
    if (u < 0 || v < 0 || u >= kPx || v >= kPx) continue;
    const Rgb col = ClassTable::builtin().info(static_cast<ClassId>(q.cls)).color;
    top.at<cv::Vec3b>(v, u) = cv::Vec3b(col.b, col.g, col.r);
  }
  cv::drawMarker(top, cv::Point(kPx / 2, kPx / 2), cv::Scalar(255, 255, 255), cv::MARKER_TRIANGLE_UP, 12, 2);
  cv::imwrite((fs::path(out) / "scan_top.png").string(), top);
  std::printf("scan of %zu points (%d x %d rays) in %.1f ms: %s/scan.ply, %s/scan_top.png\n", pts.size(),
              beams.value().rings(), columns, ms, out.c_str(), out.c_str());
  return 0;
}

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

constexpr const char* kMissionHelp =
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
    "  --web-port P            the base station serves its live page on http://localhost:P/ during the run\n"
    "  --pace X                hold the run to X times real time (to watch it on the page)\n"
    "  --record none|light|full  recordings (light)\n"
    "  --threads N             worker threads for the sensors and the robots' stages (all cores)\n"
    "  --serial-robots         step the robots one after another (same results, slower)\n"
    "  --verbose [S]           every S simulated seconds (30) a status line per robot\n"
    "  --quiet                 no progress bar\n";

void progress_bar(double sim, double total, double rtf, bool tty, double& last_print) {
  if (!tty && sim - last_print < 60 && sim < total) return;
  last_print = sim;
  const int width = 30;
  const int filled = static_cast<int>(std::lround(width * std::min(1.0, sim / std::max(total, 1e-9))));
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(static_cast<std::size_t>(width), '.');
  std::fprintf(stderr, "%s[%s] sim %6.0f s (cap %.0f s)  real-time factor %.1fx%s", tty ? "\r" : "", bar.c_str(), sim, total, rtf, tty ? "   " : "\n");
}

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
  o.uav_altitude_m = number(a, "altitude", o.uav_altitude_m);
  o.max_duration_s = a.has("max-duration") ? number(a, "max-duration", 0) : 0;
  if (a.has("max-duration") && !(o.max_duration_s > 0)) usage_error("--max-duration must be > 0");
  o.lidar_columns = static_cast<int>(number(a, "lidar-columns", o.lidar_columns));
  o.threads = static_cast<int>(number(a, "threads", 0));
  o.parallel_robots = !a.has("serial-robots");
  o.web_port = static_cast<int>(number(a, "web-port", 0));
  o.web_pace = number(a, "pace", 0);
  o.status_period_s = a.has("verbose") ? number(a, "verbose", 30) : 0;
  if (o.ugvs < 1 || o.ugvs > 32) usage_error("--ugvs must be 1..32");
  if (o.comm_range_m < 0 || o.init_error_m < 0) usage_error("--comm-range, --init-error must be >= 0");
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
  return 0;
}

constexpr const char* kHilHelp =
    "airground-sim hil — hardware in the loop: the simulated world served to the real role binaries over\n"
    "the devices' wire protocols, in real time. Each ground robot's airground-ugv gets Ouster OS-1 packets on\n"
    "its lidar UDP port (the surface's albedo in the reflectivity byte) and its two ODrive controllers over\n"
    "the cannelloni CAN-over-UDP bridge; airground-uav gets UBX NAV-PVT on a pseudo-terminal (its serial\n"
    "port) and camera frames with visual odometry through the camera stage's frame-stream replay (a FIFO);\n"
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
    "  --oracle labels        ablation: the true class in the frames and the reflectivity byte, used by the robots\n"
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

// ------------------------------------------------------------------------------------ the command table

// A command parsed here: its help is its contract, every option the help names (--x) is allowed and any
// other is an error naming it (exit 2), as the role binaries do.
struct Command {
  std::string_view name;  // "mission", "eval mapping", "world generate"
  const char* help;
  int (*handler)(const Args&);
};
// A command with its own parser (it checks its options itself, exit 2 on an unknown one).
struct OwnCommand {
  std::string_view name;
  int (*handler)(int argc, char** argv);
};

constexpr Command kCommands[] = {
    {"run", kRunHelp, &run},
    {"mission", kMissionHelp, &mission_cmd},
    {"hil", kHilHelp, &hil_cmd},
    {"eval mapping", kEvalMappingHelp, &eval_mapping_cmd},
    {"eval localization", kEvalLocalizationHelp, &eval_localization_cmd},
    {"eval planning", kEvalPlanningHelp, &eval_planning_cmd},
    {"world generate", kUsage, &world_generate},
    {"world import", kUsage, &world_import},
    {"world show", kUsage, &world_show},
    {"render", kUsage, &render},
    {"scan", kUsage, &scan},
    {"config", kUsage, &write_model_configs},
};
constexpr OwnCommand kOwnCommands[] = {
    {"eval vo", &eval_vo_cmd},  {"vo", &vo_cmd},        {"segment", &segment_cmd}, {"lidar-info", &lidar_info_cmd},
    {"study", &study_cmd},      {"survey-plan", &survey_plan_cmd},
};

// The options a help text names: every "--word" in it.
std::set<std::string> named_options(std::string_view help) {
  std::set<std::string> out;
  for (std::size_t i = help.find("--"); i != std::string_view::npos; i = help.find("--", i + 2)) {
    std::size_t e = i + 2;
    while (e < help.size() && (std::islower(static_cast<unsigned char>(help[e])) != 0 || std::isdigit(static_cast<unsigned char>(help[e])) != 0 ||
                               (help[e] == '-' && e > i + 2)))
      ++e;
    if (e > i + 2) out.emplace(help.substr(i + 2, e - i - 2));
  }
  return out;
}

void check_options(const Args& a, const Command& c) {
  const std::set<std::string> allowed = named_options(c.help);
  for (const auto& [k, v] : a.opt)
    if (allowed.count(k) == 0) usage_error("unknown option '--" + k + "' for " + std::string(c.name) + " (see airground-sim " + std::string(c.name) + " --help)");
}

// argv[1] [argv[2]] against the command names: the two-word name first ("eval mapping" before "eval").
template <class C, std::size_t N>
const C* find_command(const C (&table)[N], int argc, char** argv, int& words) {
  const std::string one = argc > 1 ? argv[1] : "";
  const std::string two = argc > 2 ? one + " " + argv[2] : "";
  for (const C& c : table)
    if (!two.empty() && c.name == two) {
      words = 2;
      return &c;
    }
  for (const C& c : table)
    if (c.name == one) {
      words = 1;
      return &c;
    }
  return nullptr;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  if (std::string(argv[1]) == "--version") {
    std::printf("airground-sim 0.1.0\n");
    return 0;
  }
  const bool help = [&] {
    for (int i = 1; i < argc; ++i)
      if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") return true;
    return false;
  }();
  try {
    int words = 0;
    if (const OwnCommand* c = find_command(kOwnCommands, argc, argv, words)) return c->handler(argc, argv);
    if (const Command* c = find_command(kCommands, argc, argv, words)) {
      if (help) {
        std::fputs(c->help, stdout);
        return 0;
      }
      const Args a = parse(argc, argv, 1 + words);
      check_options(a, *c);
      return c->handler(a);
    }
    if (help) {
      std::fputs(kUsage, stdout);
      return 0;
    }
    const std::string cmd = argv[1];
    if (cmd == "world") usage_error(argc < 3 ? "world needs generate, import or show" : "unknown world command '" + std::string(argv[2]) + "'");
    if (cmd == "eval") usage_error("eval needs 'mapping', 'vo', 'localization' or 'planning'");
    usage_error("unknown command '" + cmd + "'");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "airground-sim: %s\n", e.what());
    return 1;
  }
}
