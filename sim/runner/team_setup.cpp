// The lockstep team runner's set-up (team_setup.hpp).
#include "team_setup.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string_view>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/comms/stage.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/model_params.hpp"
#include "airground/sim/survey.hpp"
#include "airground/sim/survey_plan.hpp"
#include "roles.hpp"
#include "sensor_labels_check.hpp"
#include "stage_agreement_check.hpp"
#include "sim_probes.hpp"

namespace ag::sim::lockstep {

// Two revolutions of room: the lidar stage drains one every step it runs (20 Hz against the sensor's 10).
SimLidar::SimLidar(std::string r, const ouster::SensorInfo& info)
    : robot(std::move(r)), packets(info), link(info, 2 * static_cast<std::size_t>(packets.packets_per_revolution()), packets.packet_size()),
      registered_(ouster::register_sim_lidar(robot, &link)) {}

SimLidar::~SimLidar() {
  if (registered_) ouster::unregister_sim_lidar(robot);
}

SimUavDevices::SimUavDevices(std::string r)
    : robot(std::move(r)), camera_registered_(camera::register_sim_camera(robot, &camera)), gnss_registered_(ublox::register_sim_gps(robot, &gnss)),
      autopilot_registered_(mavlink::register_sim_autopilot(robot, &autopilot)) {}

SimUavDevices::~SimUavDevices() {
  if (camera_registered_) camera::unregister_sim_camera(robot);
  if (gnss_registered_) ublox::unregister_sim_gps(robot);
  if (autopilot_registered_) mavlink::unregister_sim_autopilot(robot);
}

SimBase::SimBase(std::string r, const Clock& clock, const base::BaseParams& p)
    : robot(std::move(r)), bp(p), link(clock), odrive(link.device(), {p.left_node, p.right_node}) {
  can::register_inprocess_link(robot, &link);
  gpio::register_fake_line(robot, "estop", &estop);
  gpio::register_fake_line(robot, "led", &led);
}

SimBase::~SimBase() {
  can::unregister_inprocess_link(robot);
  gpio::unregister_fake_lines(robot);
}

double SimBase::wheel_rad_s(int axis) const noexcept { return base::wheel_rad_s(bp, axis, odrive.vel_turns_s(axis)); }

void SimBase::turn_shafts(double left_rad, double right_rad, double dt) noexcept {
  const double rad[2] = {left_rad, right_rad};
  for (int i = 0; i < 2; ++i) {
    const double turns = (i == 0 ? bp.left_sign : bp.right_sign) * rad[i] * bp.gear_ratio / (2.0 * kPi);
    shaft_turns[static_cast<std::size_t>(i)] += turns;
    odrive.set_shaft(i, shaft_turns[static_cast<std::size_t>(i)], dt > 0 ? turns / dt : 0.0);
  }
}

namespace {

// "gps.datum_*=..." of the world's datum: the mission's map frame, as the mission file gives it a robot.
std::vector<std::string> datum_keys(const Datum& d) {
  char buf[3][96];
  std::snprintf(buf[0], sizeof buf[0], "gps.datum_lat_deg=%.9f", d.lat_deg);
  std::snprintf(buf[1], sizeof buf[1], "gps.datum_lon_deg=%.9f", d.lon_deg);
  std::snprintf(buf[2], sizeof buf[2], "gps.datum_height_m=%.3f", d.height_m);
  return {buf[0], buf[1], buf[2]};
}

// "<stage>.<key>=<value>" for every device stage of the role that has a simulator backend: what plugs the
// stage into the simulated device (StageSpec::sim_backend, "key=value[,key=value]").
std::vector<std::string> sim_backend_settings(const RoleDescription& role) {
  std::vector<std::string> out;
  for (const StageSpec& st : role.stages) {
    std::string_view rest = st.sim_backend;
    while (!rest.empty()) {
      const auto comma = rest.find(',');
      out.push_back(std::string(st.name) + "." + std::string(rest.substr(0, comma)));
      rest = comma == std::string_view::npos ? std::string_view{} : rest.substr(comma + 1);
    }
  }
  return out;
}

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
  return load(model_mapping(root, section), p.string());
}

// The world's extent; "<section>.area_x0_m=..." .. "area_y1_m" for an area (the mission area the simulator gives a robot).
MapRect world_rect(const GridGeometry& g) { return MapRect{g.origin_x, g.origin_y - g.size_y(), g.origin_x + g.size_x(), g.origin_y}; }

std::vector<std::string> area_keys(const MapRect& a, const char* section) {
  const double v[4] = {a.x0, a.y0, a.x1, a.y1};
  const char* keys[4] = {"area_x0_m", "area_y0_m", "area_x1_m", "area_y1_m"};
  std::vector<std::string> out;
  for (int k = 0; k < 4; ++k) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "%s.%s=%.3f", section, keys[k], v[k]);
    out.emplace_back(buf);
  }
  return out;
}

std::vector<std::string> world_area_keys(const GridGeometry& g, const char* section) { return area_keys(world_rect(g), section); }

// The quadrotor's survey as the run's options give it.
UavSurveyOptions survey_options(const RunOptions& opt) {
  return UavSurveyOptions{opt.uav_altitude_m, opt.survey_overlap, opt.uav_speed_mps, opt.survey_margin_m,
                          opt.survey_x0,      opt.survey_y0,      opt.survey_x1,     opt.survey_y1};
}

// The ground robots' table: their role (without the devices the simulator is and, with the runner's
// goals, without the mission manager), plus the simulator's probe, which also scores every robot's
// localization for the summary.
std::vector<StageSpec> ugv_table(const RunOptions& opt) {
  std::vector<StageSpec> out;
  for (const StageSpec& st : ugv_role().stages) {
    if (!opt.ugv_goals.empty() && std::string_view(st.name) == "mission") continue;  // the runner's goals replace the mission manager's
    // A device stage with a simulator backend runs on the simulated device; one without, the world replaces
    // (it moves the vehicle by 'wheel_command' and writes the wheel odometry).
    if (st.device && st.sim_backend.empty()) continue;
    out.push_back(st);
  }
  const double hz = opt.physics_hz;
  out.push_back(StageSpec{"sim_probe", &SimProbeStage::make, hz, static_cast<std::uint32_t>(0.9e6 / hz), 1, -1, SimProbeStage::kParams,
                          "simulator: reads the robot's channels for tests and evaluations"});
  return out;
}

// What the simulator sets on every ground robot beyond the shipped configuration, before the caller's own.
std::vector<std::string> ugv_settings(const Team& t, const std::vector<std::string>& comms_common, double survey_time_s) {
  const RunOptions& opt = t.opt;
  std::vector<std::string> ugv_extra = comms_common;
  if (opt.gossip) {
    ugv_extra.emplace_back("comms.send_pose=true");
    if (opt.ugv_map == UgvMapSource::kNone) ugv_extra.emplace_back("comms.deliver_map_tiles=true");
  }
  // The runner is then the robots' map link and writes their map_tiles itself.
  if (!opt.gossip || opt.ugv_map != UgvMapSource::kNone) ugv_extra.emplace_back("comms.deliver_map_tiles=false");
  // The mission area is the world's when the runner hands the robots the true map (the shipped +-500 m
  // would drop an imported 1.9 km map's tiles outside it and never localize there), and else the area
  // the quadrotor surveys, where its map is (the fields keep the whole tiles that cover it), for the
  // localizer and the planner's geofence alike. The localizer's: over the unsurveyed border a particle's
  // score is neutral and beats a fair match on the map, and a robot whose guess reached it settled
  // there, 40 m off. The planner's: the robot must not drive where it cannot localize (its particles
  // have no weight outside the area): on the imported world a route along the road 9 m beyond the
  // survey's south edge, which the camera had mapped in part, lost a robot (docs/localization.md).
  const bool quad_map = opt.uav && opt.ugv_map != UgvMapSource::kGroundTruth;
  const MapRect ugv_area = quad_map ? survey_area(*t.world, survey_options(opt)) : world_rect(t.world->grid());
  for (const char* section : {"localization", "planner"})
    for (const std::string& kv : area_keys(ugv_area, section)) ugv_extra.push_back(kv);
  if (opt.ugv_survey_end && opt.uav) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "mission.survey_end_s=%.1f", survey_time_s);
    ugv_extra.emplace_back(buf);  // before ugv_config: a mission file's value or --set wins
  }
  // The device stages on their simulated devices (role table: `sim_backend`).
  for (const std::string& kv : sim_backend_settings(ugv_role())) ugv_extra.push_back(kv);
  ugv_extra.insert(ugv_extra.end(), opt.ugv_config.begin(), opt.ugv_config.end());
  if (opt.ugv_tap.scan) ugv_extra.emplace_back("sim_probe.scans=true");
  if (opt.ugv_tap.odometry) ugv_extra.emplace_back("sim_probe.odometry=true");
  if (opt.ugv_tap.tile) ugv_extra.emplace_back("sim_probe.tiles=true");
  if (opt.ugv_tap.initial_pose) ugv_extra.emplace_back("sim_probe.initial_pose=true");
  return ugv_extra;
}

// One ground robot: its vehicle, odometry, LiDAR and map feed, its initial pose guess and its role.
Status set_up_ugv(Team& t, const Models& m, RoleFactory& roles, int i, const RoleDescription& ugv_desc, const std::vector<std::string>& ugv_extra) {
  const RunOptions& opt = t.opt;
  const World& w = *t.world;
  const Pose2 staging = w.header.staging;
  const bool rec = opt.record == RecordLevel::kLight || opt.record == RecordLevel::kFull;  // the CSV streams
  const std::string name = "ugv" + std::to_string(i + 1);
  // Lined up on the staging pad, 2.5 m apart across the robots' heading.
  Pose2 start = staging;
  const double off = (i - (opt.ugvs - 1) / 2.0) * 2.5;
  start.x += -std::sin(staging.yaw) * off;
  start.y += std::cos(staging.yaw) * off;
  const RunOptions::UgvStart* given = static_cast<std::size_t>(i) < opt.ugv_starts.size() ? &opt.ugv_starts[static_cast<std::size_t>(i)] : nullptr;
  if (given != nullptr && given->has_start) {
    start = given->start;
    if (!w.grid().contains(w.grid().col(start.x), w.grid().row(start.y)))
      return Error::make(ErrorCode::kInvalidArgument, "ground robot " + std::to_string(i + 1) + ": its start pose is outside the world");
  }
  const bool scripted = static_cast<std::size_t>(i) < opt.ugv_routes.size() && !opt.ugv_routes[static_cast<std::size_t>(i)].empty();
  if (scripted) {  // at the route's first point, facing the first point a few metres along it
    const auto& r = opt.ugv_routes[static_cast<std::size_t>(i)];
    start = Pose2{r.front().x(), r.front().y(), 0};
    for (std::size_t k = 1; k < r.size(); ++k) {
      const Eigen::Vector2d d = r[k] - r.front();
      start.yaw = std::atan2(d.y(), d.x());
      if (d.norm() > 2.0) break;
    }
  }
  std::vector<std::string> extra_i = ugv_extra;
  if (opt.ugv_config_for) {
    const auto more = opt.ugv_config_for(i, start);
    extra_i.insert(extra_i.end(), more.begin(), more.end());
  }
  auto cfg = roles.configure(ugv_desc, ugv_role(), i + 1, name, extra_i, "ground robot config override");
  if (!cfg) return cfg.error();
  // The simulated robot is the one its configuration describes: wheel radius and track of its base
  // (the odometry model's nominal geometry too; its calibration error and slip on top).
  const base::BaseParams bp = base::load_base_params(SectionView(*cfg.value(), "base"));
  const DiffDriveConfig dd = with_wheels(m.drive, bp.wheel_radius_m, bp.track_m);
  WheelOdometryConfig oc = m.odometry;
  oc.wheel_radius_m = bp.wheel_radius_m;
  oc.track_width_m = bp.track_m;
  auto u = std::make_unique<Ugv>(name, (opt.uav ? 1 : 0) + i, DiffDriveRobot(dd, start),
                                 WheelOdometrySimulator(oc, opt.seed * 31 + static_cast<std::uint64_t>(i)),
                                 PurePursuit(PursuitParams{1.0, opt.ugv_speed_mps, 1.2, 0.8}), start);
  u->base = std::make_unique<SimBase>(name, roles.clock(), bp);
  u->lidar_mount_z_m = cfg.value()->get_real("lidar.mount_z_m");
  // Settle the robot on the ground (height and attitude) before the first step: otherwise the scan at
  // t = 0 would be cast from 0.6 m above the datum rather than above the terrain.
  (void)u->vehicle.step(1e-9, w);
  {  // its Ouster, on the link its lidar stage reads (lidar.source: sim)
    auto info = ouster_sensor_info(opt.lidar_columns, kSimLidarProfile);
    if (!info) return info.error();
    u->lidar = std::make_unique<SimLidar>(name, info.value());
    if (!u->lidar->registered())
      return Error::make(ErrorCode::kInvalidArgument, name + ": another team in this process has a simulated LiDAR of that name");
  }
  for (auto& part : u->scan_parts) part.reserve(static_cast<std::size_t>(16 * opt.lidar_columns));
  if (rec) {
    u->truth_log = CsvLog(t.out / ("truth_" + name + ".csv"), "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad");
    u->odom_log = CsvLog(t.out / ("odom_" + name + ".csv"), "t_s,x_m,y_m,yaw_rad,wheel_left_rad_s,wheel_right_rad_s");
    u->scan_log = CsvLog(t.out / ("lidar_" + name + ".csv"), "t_s,scan,points");
    if (opt.record == RecordLevel::kFull) u->scan_bin = std::fopen((t.out / ("lidar_" + name + ".bin")).c_str(), "wb");
  }
  auto role = roles.create(ugv_desc, *cfg.value(), name);
  if (!role) return role.error();
  u->role = std::move(role).value();
  u->index = i;
  ChannelRegistry& ch = u->role->channels();
  auto init_w = ch.latest_writer(chan::kInitialPose);
  auto arm_w = ch.latest_writer(chan::kBaseArm);
  if (!init_w) return init_w.error();
  if (!arm_w) return arm_w.error();
  u->arm_out = arm_w.value();
  if (!opt.gossip || opt.ugv_map != UgvMapSource::kNone) {  // else the robot's comms stage writes its map_tiles
    auto tile_w = ch.ring_writer(chan::kMapTiles);
    if (!tile_w) return tile_w.error();
    u->tiles_out = tile_w.value();
  }
  if (static_cast<std::size_t>(i) < opt.ugv_goals.size() && opt.ugv_goals[static_cast<std::size_t>(i)].allFinite()) {
    auto goal_w = ch.latest_writer(chan::kGoal);
    if (!goal_w) return goal_w.error();
    u->goal_out = goal_w.value();
    u->goal.id = 1;
    u->goal.goal = RoutePoint{opt.ugv_goals[static_cast<std::size_t>(i)].x(), opt.ugv_goals[static_cast<std::size_t>(i)].y()};
    u->goal_pending = true;
  }
  u->init_out = init_w.value();
  {  // the initial guess: the true start moved init_error_m in a direction and turned by ±init_yaw_error_deg
    Rng rng(derive_seed(opt.seed, std::uint64_t{0x696E6974} + static_cast<std::uint64_t>(i)));
    const double dir = rng.uniform(-kPi, kPi);
    const double sign = rng.bernoulli(0.5) ? 1.0 : -1.0;
    const double dist = opt.init_error_uniform ? rng.uniform(0.0, opt.init_error_m) : opt.init_error_m;
    const double yaw_err = sign * opt.init_yaw_error_deg * kPi / 180.0;
    u->init_pose.pose = Pose2{start.x + dist * std::cos(dir), start.y + dist * std::sin(dir), wrap_angle(start.yaw + yaw_err)};
    u->init_pose.sigma_xy_m = std::max(initial_sigma_m(opt), 0.5);
    u->init_pose.sigma_yaw_rad = std::max(opt.init_yaw_error_deg, 2.0) * kPi / 180.0;
    if (given != nullptr && given->has_guess) {
      u->init_pose.pose = given->guess;
      u->init_pose.sigma_xy_m = std::max(given->guess_sigma_m, 0.5);
    }
  }
  if (opt.ugv_map == UgvMapSource::kGroundTruth) u->gt_order = gt_tile_order(w, start);
  if (scripted) {
    u->scripted = true;
    u->route = densify(opt.ugv_routes[static_cast<std::size_t>(i)], 1.0);
    u->pursuit.set_path(u->route);
  }
  if (opt.ugv_map == UgvMapSource::kOnline && opt.ugv_wait_map_radius_m > 0) u->released = false;
  for (auto& slot : u->role->stages())
    if (auto* pr = dynamic_cast<SimProbeStage*>(slot.stage.get())) u->probe = pr;
  if (u->probe != nullptr) {
    u->probe->team = &t;
    u->probe->ugv = u.get();
  }
  t.ugv_roles.push_back(u->role.get());
  t.ugvs.push_back(std::move(u));
  return ok_status();
}

}  // namespace

std::string erfnet_weights_path(const std::string& shipped) {
  std::error_code ec;
  if (fs::exists(shipped, ec)) return shipped;
  return std::string(AG_SOURCE_DIR) + "/config/erfnet/erfnet_c7.agw";
}

Status check_options(const RunOptions& opt) {
  if (opt.ugvs < 0 || opt.ugvs > 32) return Error::make(ErrorCode::kInvalidArgument, "--ugvs must be 0..32");
  if (!(opt.duration_s > 0)) return Error::make(ErrorCode::kInvalidArgument, "--duration must be positive");
  if (opt.lidar_columns != 512 && opt.lidar_columns != 1024 && opt.lidar_columns != 2048)
    return Error::make(ErrorCode::kInvalidArgument, "LiDAR columns must be 512, 1024 or 2048");
  if (!(opt.init_error_m >= 0) || !(opt.init_yaw_error_deg >= 0) || opt.init_yaw_error_deg > 180)
    return Error::make(ErrorCode::kInvalidArgument, "the initial pose error must be >= 0 m and 0..180 deg");
  if (!(opt.init_sigma_m >= 0)) return Error::make(ErrorCode::kInvalidArgument, "the initial guess's sigma must be >= 0 m");
  if (opt.map_tiles_per_tick < 1) return Error::make(ErrorCode::kInvalidArgument, "map_tiles_per_tick must be >= 1");
  if (opt.sample && !(opt.sample_hz > 0 && opt.sample_hz <= opt.physics_hz))
    return Error::make(ErrorCode::kInvalidArgument, "the sampling rate must be in (0, physics rate]");
  if (opt.ugv_map == UgvMapSource::kOnline && !opt.uav)
    return Error::make(ErrorCode::kInvalidArgument, "the online map source needs the quadrotor");
  if (opt.ugv_routes.size() > static_cast<std::size_t>(opt.ugvs))
    return Error::make(ErrorCode::kInvalidArgument, "more scripted routes than ground robots");
  for (const auto& r : opt.ugv_routes)
    if (r.size() == 1) return Error::make(ErrorCode::kInvalidArgument, "a scripted route needs at least two points");
  for (const UgvHold& h : opt.ugv_holds)
    if (h.ugv < 0 || h.ugv >= opt.ugvs || !(h.duration_s >= 0))
      return Error::make(ErrorCode::kInvalidArgument, "a hold names no ground robot or has a negative duration");
  if (opt.gossip && opt.ugv_map == UgvMapSource::kOnline)
    return Error::make(ErrorCode::kInvalidArgument, "with gossip the ground robots get the quadrotor's map over the radio: ugv_map must be none (or ground truth)");
  if (opt.ugv_goals.size() > static_cast<std::size_t>(opt.ugvs)) return Error::make(ErrorCode::kInvalidArgument, "more goals than ground robots");
  for (const RunOptions::Kill& k : opt.kills)
    if (k.ugv < -1 || k.ugv >= opt.ugvs || !(k.at_s >= 0))
      return Error::make(ErrorCode::kInvalidArgument, "a kill names no ground robot (or -1, the base station) or has a negative time");
  if (!(opt.comm_range_m >= 0)) return Error::make(ErrorCode::kInvalidArgument, "the comm range must be >= 0 m");
  return ok_status();
}

Result<Models> load_models(const RunOptions& opt) {
  Models m;
  using N = const YAML::Node&;
  using O = std::string_view;
  auto gps_cfg = model_config<GpsConfig>(opt.config_dir, "gps.yaml", "gps", [](N y, O o) { return load_gps_config(y, o); });
  auto vo_cfg = model_config<VoConfig>(opt.config_dir, "visual_odometry.yaml", "visual_odometry", [](N y, O o) { return load_vo_config(y, o); });
  auto od_cfg = model_config<WheelOdometryConfig>(opt.config_dir, "wheel_odometry.yaml", "wheel_odometry", [](N y, O o) { return load_wheel_odometry_config(y, o); });
  auto radio_cfg = model_config<RadioConfig>(opt.config_dir, "radio.yaml", "radio", [](N y, O o) { return load_radio_config(y, o); });
  auto dd_cfg = model_config<DiffDriveConfig>(opt.config_dir, "diff_drive.yaml", "diff_drive", [](N y, O o) { return load_diff_drive_config(y, o); });
  auto quad_cfg = model_config<QuadrotorConfig>(opt.config_dir, "quadrotor.yaml", "quadrotor", [](N y, O o) { return load_quadrotor_config(y, o); });
  auto att_cfg = model_config<AttitudeConfig>(opt.config_dir, "attitude.yaml", "attitude", [](N y, O o) { return load_attitude_config(y, o); });
  if (!att_cfg) return att_cfg.error();
  for (const Error* e : {gps_cfg ? nullptr : &gps_cfg.error(), vo_cfg ? nullptr : &vo_cfg.error(), od_cfg ? nullptr : &od_cfg.error(),
                         radio_cfg ? nullptr : &radio_cfg.error(), dd_cfg ? nullptr : &dd_cfg.error(), quad_cfg ? nullptr : &quad_cfg.error()})
    if (e != nullptr) return *e;
  m.gps = gps_cfg.value();
  m.vo = vo_cfg.value();
  m.odometry = od_cfg.value();
  m.radio = radio_cfg.value();
  m.drive = dd_cfg.value();
  m.quad = quad_cfg.value();
  m.attitude = att_cfg.value();
  if (!opt.config_dir.empty()) {
    const fs::path cam = fs::path(opt.config_dir) / "camera.yaml";
    if (fs::exists(cam)) {
      auto c = CameraModel::load_file(cam.string());
      if (!c) return c.error();
      m.camera = c.value();
      auto s = CameraShading::load_file(cam.string());
      if (!s) return s.error();
      m.shading = s.value();
      auto se = CameraSensor::load_file(cam.string());
      if (!se) return se.error();
      m.sensor = se.value();
    }
    const fs::path li = fs::path(opt.config_dir) / "lidar_noise.yaml";
    if (fs::exists(li)) {
      auto n = LidarNoise::load_file(li.string());
      if (!n) return n.error();
      m.lidar_noise = n.value();
    }
  }
  if (opt.camera_scale != 1.0) m.camera = m.camera.scaled(opt.camera_scale);
  auto beams = OusterBeamModel::load_default(opt.lidar_columns);
  if (!beams) return beams.error();
  m.beams = std::move(beams).value();
  return m;
}

Status set_up_world(Team& t, const Models& m) {
  const RunOptions& opt = t.opt;
  const World& w = *t.world;
  try {
    t.raycaster = std::make_shared<HeightfieldRaycaster>(w);
    if (opt.uav && !t.uav_play) t.camera = std::make_unique<CameraRenderer>(w, m.camera, m.shading, m.sensor, t.raycaster);
    t.camera_ae = CameraAutoExposure(m.sensor);
    if (opt.ugvs > 0) t.lidar = std::make_unique<LidarSimulator>(w, m.beams, m.lidar_noise, t.raycaster);
  } catch (const std::exception& e) {
    return Error::make(ErrorCode::kInvalidArgument, std::string("sensor set-up: ") + e.what());
  }
  t.router = std::make_unique<RoadRouter>(w, 1.0, m.drive.footprint_radius_m + 0.2);
  const int nodes = (opt.uav ? 1 : 0) + opt.ugvs + 1;  // node 0 = quadrotor (or unused), then ground robots, then base
  RadioConfig rcfg = m.radio;
  if (opt.comm_range_m > 0) rcfg.range_m = opt.comm_range_m;
  const int radio_nodes = std::max(nodes, 2) + (opt.uav ? 0 : 1);
  if (opt.gossip) {
    t.net = std::make_unique<RadioNet>(rcfg, opt.seed ^ std::uint64_t{0x7261646F}, radio_nodes);
    t.air = &t.net->radio();
  } else {
    t.radio = std::make_unique<RadioModel>(rcfg, opt.seed ^ std::uint64_t{0x7261646F}, radio_nodes);
    t.air = t.radio.get();
  }
  const Pose2 staging = w.header.staging;
  const int base_node = 1 + opt.ugvs;
  t.base_node = base_node;
  t.air->set_position(base_node, staging.x, staging.y);
  return ok_status();
}

LinkRegistration::~LinkRegistration() {
  for (const auto& n : names) comms::register_inproc_link(n, nullptr);
}

Result<std::vector<std::string>> set_up_gossip(Team& t, LinkRegistration& links) {
  const RunOptions& opt = t.opt;
  std::vector<std::string> comms_common;
  if (opt.gossip) {
    const fs::path key = t.out / "team.key";
    if (auto st = write_team_key(key.string(), derive_seed(opt.seed, std::uint64_t{0x6B6579})); !st) return st.error();
    comms_common = {"comms.transport=inproc", "comms.key_file=" + key.string(), "comms.epoch_from_clock=false"};
    auto reg = [&](const std::string& name, int node) {
      comms::register_inproc_link(name, &t.net->endpoint(node));
      links.names.push_back(name);
    };
    if (opt.uav) reg("uav", 0);
    for (int i = 0; i < opt.ugvs; ++i) reg("ugv" + std::to_string(i + 1), (opt.uav ? 1 : 0) + i);
    reg("base", t.base_node);
  }
  return comms_common;
}

RoleFactory::RoleFactory(const RunOptions& opt, SimClock& clock, std::vector<Config>& configs) : opt_(opt), clock_(clock), configs_(configs) {}

Result<std::unique_ptr<RoleInstance>> RoleFactory::make(const RoleDescription& role, const RoleDescription& shipped_role, int id, const std::string& name,
                                                        const std::vector<std::string>& extra, const char* what) {
  auto c = configure(role, shipped_role, id, name, extra, what);
  if (!c) return c.error();
  return create(role, *c.value(), name);
}

Result<std::unique_ptr<RoleInstance>> RoleFactory::create(const RoleDescription& role, const Config& config, const std::string& name) {
  return RoleInstance::create(role, config, clock_, name);
}

Result<const Config*> RoleFactory::configure(const RoleDescription& role, const RoleDescription& shipped_role, int id, const std::string& name,
                                             const std::vector<std::string>& extra, const char* what) {
  std::vector<StageSpec> all(shipped_role.stages.begin(), shipped_role.stages.end());
  for (const StageSpec& st : role.stages)
    if (std::none_of(all.begin(), all.end(), [&](const StageSpec& a) { return std::string_view(a.name) == st.name; })) all.push_back(st);
  RoleDescription schema_role = shipped_role;
  schema_role.stages = all;
  const std::string origin = "firmware_host/" + std::string(shipped_role.name) + "/" + std::string(shipped_role.name) + ".yaml (built into airground-sim)";
  auto loaded = Config::load_string(role_schema(schema_role), shipped_config_yaml(shipped_role.name), origin);
  if (!loaded) return loaded.error();
  Config c = std::move(loaded).value();
  std::vector<std::string> sim = {"robot.id=" + std::to_string(id), "robot.name=" + name,
                                  "status.log_counters=false"};  // the runner reports the counters
  if (c.has("comms.journal")) {
    sim.emplace_back("comms.journal=");  // a file on the robot; the simulation keeps its store in memory
    if (!opt_.gossip) sim.emplace_back("comms.transport=none");
  }
  if (c.has("segmentation.weights")) sim.push_back("segmentation.weights=" + erfnet_weights_path(c.get_text("segmentation.weights")));
  if (opt_.oracle("labels")) {  // the ablation: the drivers hand over the truth and the robots use it
    if (c.has("segmentation.labels")) sim.emplace_back("segmentation.labels=gt");
    if (c.has("localization.labels")) sim.emplace_back("localization.labels=gt");
    if (c.has("lidar.classes")) sim.emplace_back("lidar.classes=reflectivity");  // the class in the reflectivity byte, as HIL's packets
  }
  for (const auto& kv : sim)
    if (auto st = c.set(kv, "the simulator"); !st) return st.error();
  for (const auto& kv : extra)
    if (auto st = c.set(kv, what); !st) return st.error();
  if (auto st = check_sensor_labels(c, origin + " with the simulator's settings and the " + what, opt_.oracle("labels")); !st) return st.error();
  for (std::string& w : stage_agreement_warnings(c))
    if (std::find(warned_.begin(), warned_.end(), w) == warned_.end()) {
      std::fprintf(stderr, "airground-sim: warning: %.*s: %s\n", static_cast<int>(role.name.size()), role.name.data(), w.c_str());
      warned_.push_back(std::move(w));
    }
  // The simulated camera gives what a V4L2 one gives, RGB: classes only in the ablation the user names.
  if (!opt_.oracle("labels") && c.has("segmentation.labels") && c.get_text("segmentation.labels") == "gt" && c.get_text("camera.source") == "sim")
    return Error::make(ErrorCode::kConfig, "config error: " + origin + " with the simulator's settings and the " + what +
                                               ": segmentation.labels: gt relays the camera's classes, but camera.source: sim gives RGB only "
                                               "(as a V4L2 camera); the renderer's classes only with --oracle labels");
  if (configs_.size() == configs_.capacity()) return Error::make(ErrorCode::kInternal, "RoleFactory: more roles than the configurations reserved");
  configs_.push_back(std::move(c));
  return &configs_.back();
}

Result<double> set_up_uav(Team& t, const Models& m, RoleFactory& roles, const std::vector<std::string>& comms_common) {
  const RunOptions& opt = t.opt;
  const World& w = *t.world;
  const bool rec = opt.record == RecordLevel::kLight || opt.record == RecordLevel::kFull;  // the CSV streams
  const bool labels_oracle = opt.oracle("labels");
  const Pose3 start = uav_launch_pose(w);
  auto u = std::make_unique<Uav>(Uav{Quadrotor(m.quad, start), GpsSimulator(m.gps, w.header.datum, opt.seed ^ std::uint64_t{0x67707331}),
                                     VisualOdometrySimulator(m.vo, opt.seed ^ std::uint64_t{0x766f3031}), CameraFrame{}, 0, 0, 0, 0, 0, {}, {}, {}, {}, {}, nullptr});
  const double hfov = 2.0 * std::atan(0.5 * m.camera.width / m.camera.fx);
  const UavSurveyOptions so = survey_options(opt);
  auto route = uav_survey_route(w, so, hfov);
  if (!route) return route.error();
  if (const std::string off = staging_outside_survey(w, so); !off.empty()) std::fprintf(stderr, "airground-sim: warning: %s\n", off.c_str());
  std::vector<Waypoint> wps = std::move(route).value();
  // The same route as an autopilot's mission (QGroundControl .plan), as a field team would load it.
  if (auto st = write_survey_plan((t.out / "survey.plan").string(), SurveyPlan{wps, start, w.header.datum, AutopilotFirmware::kPx4,
                                                                               opt.uav_speed_mps > 0 ? opt.uav_speed_mps : m.quad.cruise_speed_mps,
                                                                               m.quad.waypoint_tolerance_m, opt.uav_return_home});
      !st)
    return st.error();
  if (opt.uav_return_home && !wps.empty()) wps.push_back(Waypoint{start.x, start.y, wps.back().z, 0});
  const double survey_time_s = estimate_route_time_s(m.quad, start, wps);
  u->vehicle.set_waypoints(std::move(wps));
  if (rec) {
    u->truth_log = CsvLog(t.out / "truth_uav.csv", "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad");
    u->gps_log = CsvLog(t.out / "gps_uav.csv", "t_s,fix_type,lat_deg,lon_deg,height_m,east_m,north_m,up_m,h_acc_m");
    u->vo_log = CsvLog(t.out / "vo_uav.csv", "t_s,segment,tracking,x,y,z,roll_rad,pitch_rad,yaw_rad");
    u->frame_log = CsvLog(t.out / "camera_frames.csv", "t_s,frame,x_m,y_m,z_m,yaw_rad");
  }
  std::vector<std::string> uav_extra = comms_common;
  if (opt.gossip) uav_extra.emplace_back("comms.send_map_tiles=true");
  for (const std::string& kv : world_area_keys(w.grid(), "regions")) uav_extra.push_back(kv);  // before uav_config: a caller's area wins
  // The device stages on their simulated devices (role table: sim_backend), the receiver's datum the world's.
  for (const std::string& kv : sim_backend_settings(uav_role())) uav_extra.push_back(kv);
  for (const std::string& kv : datum_keys(w.header.datum)) uav_extra.push_back(kv);
  uav_extra.insert(uav_extra.end(), opt.uav_config.begin(), opt.uav_config.end());
  // The device stages run on the simulated devices (the oracle VO, when named, writes the VO's channel).
  RoleDescription uav_desc = uav_role();
  u->vo_oracle = opt.oracle("vo");
  u->labels_oracle = labels_oracle;
  for (const StageSpec& st : uav_desc.stages)
    if ((!st.device || !st.sim_backend.empty()) && !(u->vo_oracle && st.name == "vo")) t.uav_stages.push_back(st);
  t.uav_devices = std::make_unique<SimUavDevices>("uav");
  if (!t.uav_devices->registered())
    return Error::make(ErrorCode::kInvalidArgument, "uav: another team in this process has a simulated camera, receiver or autopilot of that name");
  if (!u->vo_oracle && !t.uav_play)
    t.uav_stages.push_back(StageSpec{"sim_vo_tap", &SimVoTapStage::make, 10.0, 90'000, 1, -1, SimVoTapStage::kParams,
                                     "simulator: counts and logs the quadrotor's own odometry"});
  plug_uav_cache(t, t.uav_stages);
  uav_desc.stages = t.uav_stages;
  auto role = roles.make(uav_desc, uav_role(), 0, "uav", uav_extra, "quadrotor config override");
  if (!role) return role.error();
  u->role = std::move(role).value();
  if (t.uav_play) {  // the replay stands in for the sensors and the mapping: nothing more to connect
    t.uav = std::move(u);
    if (auto st = attach_uav_cache(t); !st) return st.error();
    return survey_time_s;
  }
  if (u->vo_oracle) {
    auto vo_w = u->role->channels().ring_writer(chan::kVisualOdometry);
    if (!vo_w) return vo_w.error();
    u->vo_out = vo_w.value();
  } else {
    for (auto& slot : u->role->stages())
      if (auto* tap = dynamic_cast<SimVoTapStage*>(slot.stage.get())) tap->uav = u.get();
  }
  u->attitude = AttitudeSimulator(m.attitude, opt.seed ^ std::uint64_t{0x61747431});
  if (opt.ugv_map == UgvMapSource::kOnline) {
    for (auto& slot : u->role->stages())
      if (auto* om = dynamic_cast<const mapping::OrthoMapStage*>(slot.stage.get())) t.ortho = &om->map();
    if (t.ortho == nullptr) return Error::make(ErrorCode::kInvalidArgument, "the online map source needs the quadrotor's ortho_map stage");
    const mapping::OrthoMapParams& mp = t.ortho->params();
    if (std::abs(mp.resolution_m - kMapResolutionM) > 1e-9 || mp.tile_cells != kTileCells)
      return Error::make(ErrorCode::kInvalidArgument, "the online map source needs the ortho-map at 0.5 m cells in 64-cell tiles (the map_tiles format)");
  }
  t.uav = std::move(u);
  if (auto st = attach_uav_cache(t); !st) return st.error();
  return survey_time_s;
}

Status set_up_ugvs(Team& t, const Models& m, RoleFactory& roles, const std::vector<std::string>& comms_common, double survey_time_s) {
  t.lidar_rings = m.beams.rings();
  t.sample_period = period_from_hz(t.opt.sample_hz);
  if (t.opt.ugvs == 0) return ok_status();
  RoleDescription ugv_desc = ugv_role();
  t.ugv_stages = ugv_table(t.opt);
  ugv_desc.stages = t.ugv_stages;
  const std::vector<std::string> ugv_extra = ugv_settings(t, comms_common, survey_time_s);
  t.tile_msg = std::make_unique<MapTileMsg>();
  for (int i = 0; i < t.opt.ugvs; ++i)
    if (auto st = set_up_ugv(t, m, roles, i, ugv_desc, ugv_extra); !st) return st;
  return ok_status();
}

Status set_up_base(Team& t, RoleFactory& roles, const std::vector<std::string>& comms_common) {
  const RunOptions& opt = t.opt;
  // The base station's page on any free loopback port unless the caller names one (many simulations
  // run at once; the log names the port).
  std::vector<std::string> base_extra = comms_common;
  base_extra.emplace_back("web.port=0");
  base_extra.emplace_back("web.bind=127.0.0.1");
  if (opt.gossip) base_extra.emplace_back("comms.deliver_map_tiles=true");
  base_extra.emplace_back("web.log_path=" + (t.out / "mission_log.jsonl").string());
  base_extra.insert(base_extra.end(), opt.base_config.begin(), opt.base_config.end());
  auto role = roles.make(base_role(), base_role(), 250, "base", base_extra, "base station config");
  if (!role) return role.error();
  t.base = std::move(role).value();
  return ok_status();
}

void warn_unwritten_channels(const Team& t) {
  auto check = [](RoleInstance* r) {
    if (r == nullptr) return;
    for (const std::string& ch : r->channels().read_but_unwritten())
      std::fprintf(stderr, "airground-sim: %s: channel '%s' is read but neither a stage nor the simulator writes it; its readers wait forever\n",
                   r->name().c_str(), ch.c_str());
  };
  if (t.uav) check(t.uav->role.get());
  for (const auto& u : t.ugvs) check(u->role.get());
  check(t.base.get());
}

}  // namespace ag::sim::lockstep
