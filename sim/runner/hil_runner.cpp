// airground-sim hil: the world served over the devices' wire protocols to the real role processes.
// Two threads: the physics thread (200 Hz: the ODrive controllers on the CAN bridge, the bases, the
// quadrotor) must never stall, or a robot sees its controllers fall silent; the sensor thread (this
// one) sends what is due (GPS, attitude, LiDAR; the camera renders on a third) and watches the mission through the base.
// The steps are in hil_roles.cpp, hil_devices.cpp, hil_loop.cpp and hil_report.cpp (hil_run.hpp).
#include <sys/socket.h>

#include <algorithm>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <thread>

#include "airground/platform/config.hpp"
#include "airground/platform/rng.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/survey.hpp"
#include "hil_run.hpp"
#include "roles.hpp"

namespace ag::sim {
namespace hil {

Run::Run(const HilOptions& o, const World& w, const mission::MissionFile& m)
    : opt(o), world(w), mf(m), out(o.out_dir),
      labels_oracle(std::find(o.oracles.begin(), o.oracles.end(), "labels") != o.oracles.end()),
      vo_oracle(std::find(o.oracles.begin(), o.oracles.end(), "vo") != o.oracles.end()) {}

namespace {

// Ports: gossip per process and the base station's page.
void pick_ports(Run& run) {
  run.gossip.resize(run.mf.team.size() + 2);
  for (auto& p : run.gossip) p = any_port(SOCK_DGRAM);
  run.web_port = any_port(SOCK_STREAM);
}

// Per ground robot: lidar + IMU ports and the CAN bridge's two ends, its devices and its YAML.
Status set_up_ugvs(Run& run, const json& meta) {
  // The simulated robot is the one the shipped file describes: its base's wheel radius and track.
  auto shipped = Config::load_string(role_schema(ugv_role()), shipped_config_yaml("ugv"), "firmware_host/ugv/ugv.yaml (built into airground-sim)");
  if (!shipped) return shipped.error();
  const base::BaseParams bp = base::load_base_params(SectionView(shipped.value(), "base"));
  run.lidar_mount_z_m = shipped.value().get_real("lidar.mount_z_m");  // and its LiDAR where the file mounts it
  const DiffDriveConfig dd = with_wheels(DiffDriveConfig{}, bp.wheel_radius_m, bp.track_m);
  const Settings shared = ugv_shared_settings(run);
  for (int i = 0; i < static_cast<int>(run.mf.team.size()); ++i) {
    const mission::TeamMember& tm = run.mf.team[static_cast<std::size_t>(i)];
    auto u = std::make_unique<Ugv>("ugv" + std::to_string(tm.id), tm.id, DiffDriveRobot(dd, Pose2{tm.start_x, tm.start_y, tm.start_yaw}));
    const std::uint16_t lidar_port = any_port(SOCK_DGRAM), imu_port = any_port(SOCK_DGRAM), can_robot = any_port(SOCK_DGRAM),
                        can_sim = any_port(SOCK_DGRAM);
    const fs::path meta_path = run.out / "config" / ("ouster-" + u->name + ".json");
    if (auto st = open_ugv_devices(*u, meta, meta_path, lidar_port, imu_port, can_robot, can_sim); !st) return st.error();
    if (auto st = write_ugv_yaml(run, i, tm, *u, shared, meta_path, can_robot, can_sim); !st) return st.error();
    run.ugvs.push_back(std::move(u));
  }
  return ok_status();
}

// The simulators (the simulator's defaults, as the lockstep runner uses them); the quadrotor flies the
// survey of the mission file from the first ground robot's start.
Status build_simulators(Run& run) {
  const World& w = run.world;
  const mission::MissionFile& mf = run.mf;
  const CameraModel cam_model = CameraModel{}.scaled(0.5);
  const mission::TeamMember& lead = mf.team.front();
  const float z0 = w.terrain.at<float>(w.grid().row(lead.start_y), w.grid().col(lead.start_x));
  run.quad.emplace(QuadrotorConfig{}, Pose3{lead.start_x, lead.start_y, z0, 0, 0, 0});
  {
    SurveyOptions so;
    so.speed_mps = mf.survey.speed_mps;
    const double hfov = 2.0 * std::atan(0.5 * cam_model.width / cam_model.fx);
    const mission::Area area = mf.area.x1 > mf.area.x0 ? mf.area : world_area(w);
    const mission::Area& sa = mf.survey.area.x1 > mf.survey.area.x0 ? mf.survey.area : area;
    auto route = survey_lawnmower(sa.x0, sa.y0, sa.x1, sa.y1, mf.survey.altitude_m, mf.survey.overlap, hfov, so);
    if (!route) return route.error();
    run.quad->set_waypoints(std::move(route).value());
  }
  run.gps.emplace(GpsConfig{}, w.header.datum, run.opt.seed ^ std::uint64_t{0x67707331});
  if (run.vo_oracle) run.vo.emplace(VoConfig{}, run.opt.seed ^ std::uint64_t{0x766f3031});
  run.attitude.emplace(AttitudeConfig{}, run.opt.seed ^ std::uint64_t{0x61747431});
  auto raycaster = std::make_shared<HeightfieldRaycaster>(w);
  run.camera.emplace(w, cam_model, CameraShading{}, raycaster);
  auto beams = OusterBeamModel::from_metadata_json((run.out / "config" / ("ouster-" + run.ugvs.front()->name + ".json")).string(),
                                                   run.opt.lidar_columns);
  if (!beams) return beams.error();
  run.lidar.emplace(w, beams.value(), LidarNoise{}, raycaster);
  return ok_status();
}

// recording.mcap: the truth, the poses the base heard, GPS, LiDAR and camera frames; log times from
// here on (wall clock: HIL runs in real time).
Status open_recording(Run& run) {
  run.rec0 = monotonic_now();
  if (!run.opt.record) return ok_status();
  TeamRecordingOptions ro;
  ro.scheduler_period_s = 0;  // the robots' stages run in their own processes (their hil_report.md timing)
  ro.mission = false;
  ro.lidar_mount_height_m = run.lidar_mount_z_m;
  auto r = TeamRecording::open((run.out / "recording.mcap").string(), run.world, true, static_cast<int>(run.ugvs.size()), run.opt.seed, ro);
  if (!r) {
    signal_roles(run.children, SIGTERM);
    return r.error();
  }
  run.rec = std::move(r).value();
  return ok_status();
}

// Writes the configs and opens the devices, builds the simulators and starts the role processes.
Status set_up(Run& run) {
  std::error_code ec;
  for (const char* d : {"config", "logs"}) fs::create_directories(run.out / d, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + run.out.string() + ": " + ec.message());
  auto bin = find_role_binaries(run.opt.bin_dir);
  if (!bin) return bin.error();
  run.bin = bin.value();
  // The team key, as an operator would make it.
  run.key = run.out / "config" / "team.key";
  if (auto st = write_team_key(run.key.string(), derive_seed(run.opt.seed, std::uint64_t{0x68696C})); !st) return st.error();
  pick_ports(run);
  auto meta = ouster_metadata(run.opt.lidar_columns, run.opt.lidar_profile);
  if (!meta) return meta.error();
  if (auto st = set_up_ugvs(run, meta.value()); !st) return st.error();
  if (auto st = open_pty(run, "gps", run.gps_pty); !st) return st.error();
  if (auto st = open_pty(run, "autopilot", run.autopilot_pty); !st) return st.error();
  if (auto st = make_camera_fifo(run); !st) return st.error();
  if (auto st = write_uav_yaml(run); !st) return st.error();
  if (auto st = write_base_yaml(run); !st) return st.error();
  fs::remove(run.out / "mission.jsonl", ec);
  if (auto st = build_simulators(run); !st) return st.error();
  return start_roles(run);
}

}  // namespace
}  // namespace hil

Result<HilResult> run_hil(const HilOptions& opt) {
  if (opt.mission_file.empty()) return Error::make(ErrorCode::kInvalidArgument, "hil needs --mission FILE.yaml");
  auto mf_r = mission::load_mission_file(opt.mission_file);
  if (!mf_r) return mf_r.error();
  const mission::MissionFile mf = std::move(mf_r).value();
  if (mf.team.empty()) return Error::make(ErrorCode::kConfig, opt.mission_file + ": the team has no ground robot");
  auto world_r = resolve_world(opt.world);
  if (!world_r) return world_r.error();
  const std::shared_ptr<const World> world = world_r.value();
  hil::Run run(opt, *world, mf);
  if (auto st = hil::set_up(run); !st) return st.error();
  if (opt.progress)
    std::fprintf(stderr, "hil: %zu processes started (base page http://127.0.0.1:%u/); configs and logs in %s\n", run.children.size(),
                 static_cast<unsigned>(run.web_port), run.out.c_str());
  if (auto st = hil::open_recording(run); !st) return st.error();

  std::thread physics([&run] { hil::physics_thread(run); });
  std::thread camera_thread([&run] { hil::camera_thread(run); });
  hil::sensor_loop(run);
  HilResult& res = run.res;
  res.duration_s = to_seconds(monotonic_now() - run.t0);

  hil::stop_roles(run.children);
  run.stop_camera.store(true);
  camera_thread.join();
  res.camera_frames = run.cam_written.load();
  res.camera_frames_dropped = run.cam_dropped.load();
  res.camera_frames_skipped = run.cam_skipped.load();
  res.vo_records = run.vo_written.load();
  res.mavlink_frames = run.px4.frames_sent();
  res.mavlink_bytes_in = run.px4.bytes_received();
  run.stop.store(true);
  physics.join();
  hil::close_devices(run);
  if (!run.last_state.empty()) std::ofstream(run.out / "base_state.json") << run.last_state << "\n";
  if (run.rec)
    if (Status st = run.rec->close(to_seconds(monotonic_now() - run.rec0)); !st) return st.error();

  hil::collect_results(run);
  hil::write_report(run);
  if (!run.failure.empty()) return Error::make(ErrorCode::kIo, "hil: " + run.failure);
  return std::move(run.res);
}

}  // namespace ag::sim
