// eval vo: fly the survey, render every frame, run the quadrotor's VO on it with the autopilot's attitude
// (the simulator's error model), score it against the true trajectory and write metrics and plots.
#include "airground/sim/eval_vo.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>

#include "airground/messages/camera.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/attitude.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/plot.hpp"
#include "airground/sim/quadrotor.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/survey.hpp"
#include "airground/visual_odometry/visual_odometry.hpp"
#include "../runner/team_recording.hpp"

namespace ag::sim {

namespace fs = std::filesystem;

namespace {

struct Sample {
  double t{0};
  bool tracking{false};
  std::uint32_t segment{0};
  Eigen::Isometry3d vo{Eigen::Isometry3d::Identity()};
  Eigen::Isometry3d truth{Eigen::Isometry3d::Identity()};
  double dist{0};  // true distance flown so far [m]
};

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

double angle_deg(const Eigen::Matrix3d& R) {
  return Eigen::AngleAxisd(R).angle() * 180.0 / M_PI;
}

Result<vo::VoParams> vo_params(const EvalVoOptions& o, const PinholeCamera& cam) {
  vo::VoParams p;
  p.camera = cam;
  for (const std::string& kv : o.set) {
    const auto eq = kv.find('=');
    if (eq == std::string::npos) return Error::make(ErrorCode::kInvalidArgument, "--set " + kv + ": expected key=value");
    const std::string k = kv.substr(0, eq);
    double v = 0;
    try {
      v = std::stod(kv.substr(eq + 1));
    } catch (...) {
      return Error::make(ErrorCode::kInvalidArgument, "--set " + kv + ": the value is not a number");
    }
    if (k == "max_features") p.max_features = static_cast<int>(v);
    else if (k == "keyframe_parallax_px") p.keyframe_parallax_px = v;
    else if (k == "window_keyframes") p.window_keyframes = static_cast<int>(v);
    else if (k == "min_pose_inliers") p.min_pose_inliers = static_cast<int>(v);
    else if (k == "max_reprojection_px") p.max_reprojection_px = v;
    else if (k == "gravity_sigma_rad") p.gravity_sigma_rad = v;
    else return Error::make(ErrorCode::kInvalidArgument, "--set " + kv + ": unknown vo parameter '" + k + "'");
  }
  return p;
}

// The survey camera: the field camera at 640 px unless a file says otherwise.
struct SurveyCamera {
  CameraModel model{CameraModel{}.scaled(0.5)};
  CameraShading shading;
  // The goals hold with a real camera's noise, exposure, blur and vignetting: on unless a file says otherwise.
  CameraSensor sensor{CameraSensor::field()};
};

Result<SurveyCamera> load_camera(const EvalVoOptions& o) {
  SurveyCamera c;
  if (o.camera_config.empty()) return c;
  auto cs = CameraSensor::load_file(o.camera_config);
  if (!cs) return cs.error();
  c.sensor = cs.value();
  auto m = CameraModel::load_file(o.camera_config);
  if (!m) return m.error();
  c.model = m.value().width == 640 ? m.value() : m.value().scaled(640.0 / m.value().width);
  auto s = CameraShading::load_file(o.camera_config);
  if (!s) return s.error();
  c.shading = s.value();
  return c;
}

Result<AttitudeConfig> load_attitude(const EvalVoOptions& o) {
  AttitudeConfig att_cfg;
  if (o.attitude_config.empty()) return att_cfg;
  std::ifstream f(o.attitude_config);
  if (!f) return Error::make(ErrorCode::kConfig, "cannot read the attitude model file " + o.attitude_config);
  std::string text;
  std::getline(f, text, '\0');
  auto a = load_attitude_config(std::string_view(text), o.attitude_config);
  if (!a) return a.error();
  return a.value();
}

// recording.mcap: the true flight (10 Hz) and every 5th camera frame, as a team run records the quadrotor;
// none without o.record.
Result<std::unique_ptr<TeamRecording>> open_recording(const EvalVoOptions& o, const World& w) {
  if (!o.record) return std::unique_ptr<TeamRecording>{};
  std::error_code mk;
  fs::create_directories(o.out_dir, mk);
  TeamRecordingOptions ro;
  ro.scheduler_period_s = 0;
  ro.mission = false;
  auto r = TeamRecording::open((fs::path(o.out_dir) / "recording.mcap").string(), w, true, 0, o.seed, ro);
  if (!r) return r.error();
  return std::move(r).value();
}

// What the flight gave: a sample per camera frame, the VO's counters and what the frames cost.
struct Flight {
  std::vector<Sample> samples;
  std::vector<double> vo_ms;  // thread CPU of the VO per frame
  double render_s{0};         // thread CPU of the renderer, all frames
  double distance_m{0}, duration_s{0};
  vo::VoStats stats;
};

// Flies the survey, renders every camera frame and runs the VO on it (with the autopilot's attitude
// when o.attitude).
Result<Flight> fly_survey(const World& w, const SurveyCamera& camera, const AttitudeConfig& att_cfg, const vo::VoParams& params,
                          const std::vector<Waypoint>& wps, const EvalVoOptions& o, const EvalVoProgress& progress) {
  QuadrotorConfig qc;
  const Pose3 start{wps.front().x, wps.front().y, wps.front().z, 0, 0, 0};
  Quadrotor quad(qc, start);
  const double est = estimate_route_time_s(qc, start, wps);
  quad.set_waypoints(wps);

  CameraRenderer renderer(w, camera.model, camera.shading, camera.sensor);
  CameraAutoExposure ae(camera.sensor);
  std::uint64_t frame_no = 0;
  double last_yaw = quad.pose().yaw;
  AttitudeSimulator attitude(att_cfg, o.seed ^ 0x617474ULL);
  vo::VisualOdometry odo(params);
  CameraFrame frame;
  Flight fl;
  const double dt = 0.02, frame_dt = 1.0 / o.camera_hz;
  double t = 0, next_frame = 0;
  Pose3 last = quad.pose();
  const double t_end = std::min(o.max_duration_s, est * 1.05 + 10.0);
  std::optional<Eigen::Matrix3d> att_R;
  int last_pct = -1;
  double yaw_rate = 0;
  auto opened = open_recording(o, w);
  if (!opened) return opened.error();
  std::unique_ptr<TeamRecording> rec = std::move(opened).value();
  std::uint64_t steps = 0;
  while (t < t_end && !quad.finished()) {
    last_yaw = quad.pose().yaw;
    quad.step(dt);
    yaw_rate = std::remainder(quad.pose().yaw - last_yaw, 2 * M_PI) / dt;
    t += dt;
    const Pose3& p = quad.pose();
    fl.distance_m += std::hypot(std::hypot(p.x - last.x, p.y - last.y), p.z - last.z);
    last = p;
    const TimeNs stamp = static_cast<TimeNs>(std::llround(t * 1e9));
    AttitudeSample as;
    if (attitude.sample(stamp, p, as)) att_R = rotation_matrix(as.roll, as.pitch, as.yaw);
    if (rec && steps++ % 5 == 0) {
      rec->uav_pose(stamp, p);
      rec->tick(stamp, nullptr);
    }
    if (t + 1e-9 < next_frame) continue;
    next_frame += frame_dt;
    const TimeNs r0 = thread_cpu_now();
    CameraShot shot;
    shot.seed = o.seed;
    shot.frame = frame_no++;
    shot.exposure = ae.next();
    shot.velocity = Eigen::Vector3d(quad.vx(), quad.vy(), quad.vz());
    shot.yaw_rate = yaw_rate;
    renderer.render(p, frame, stamp, shot);
    ae.observe(frame);
    fl.render_s += to_seconds(thread_cpu_now() - r0);
    if (rec) rec->camera_frame(stamp, frame_no, frame.rgb);
    const TimeNs v0 = thread_cpu_now();
    const vo::VoFrame f = odo.process(stamp, frame.rgb.ptr<std::uint8_t>(0), o.attitude ? att_R : std::nullopt);
    fl.vo_ms.push_back(to_seconds(thread_cpu_now() - v0) * 1e3);
    Sample s;
    s.t = t;
    s.tracking = f.tracking;
    s.segment = f.segment;
    s.vo = f.body_in_segment;
    s.truth = to_isometry(p);
    s.dist = fl.distance_m;
    fl.samples.push_back(s);
    const int pct = static_cast<int>(100.0 * t / t_end);
    if (progress && pct != last_pct) {
      last_pct = pct;
      progress(t / t_end);
    }
  }
  if (rec)
    if (Status st = rec->close(t); !st) return st.error();
  fl.duration_s = t;
  fl.stats = odo.stats();
  return fl;
}

struct ScalePoint {
  double d, log_s;
};

// Scale drift: slope of log(scale) against distance per segment, as % per 100 m, length-weighted.
double scale_drift_percent_per_100m(const std::vector<std::vector<ScalePoint>>& scale_by_segment) {
  double wsum = 0, dsum = 0;
  for (const auto& pts : scale_by_segment) {
    if (pts.size() < 10) continue;
    double sd = 0, sl = 0;
    for (const auto& q : pts) sd += q.d, sl += q.log_s;
    const double md = sd / static_cast<double>(pts.size()), ml = sl / static_cast<double>(pts.size());
    double num = 0, den = 0;
    for (const auto& q : pts) num += (q.d - md) * (q.log_s - ml), den += (q.d - md) * (q.d - md);
    if (den <= 0) continue;
    const double len = pts.back().d - pts.front().d;
    dsum += len * std::fabs(std::expm1(100.0 * num / den)) * 100.0;
    wsum += len;
  }
  return wsum > 0 ? dsum / wsum : 0.0;
}

// The pairs' errors over time, for the plots.
struct PairSeries {
  std::vector<double> t, rot, dir;
};

// Relative errors over consecutive pairs about pair_distance_m apart (true distance), same segment; the
// tilt of every tracked frame.
PairSeries score_pairs(const std::vector<Sample>& samples, double pair_distance_m, VoMetrics& m) {
  std::vector<double> rot, dir, tilt;
  PairSeries pairs;
  Eigen::Vector3d signed_err_sum = Eigen::Vector3d::Zero();
  std::size_t signed_n = 0;
  std::vector<std::vector<ScalePoint>> scale_by_segment(m.segments + 1);
  for (std::size_t i = 0; i < samples.size();) {
    if (!samples[i].tracking) {
      ++i;
      continue;
    }
    std::size_t j = i + 1;
    while (j < samples.size() && samples[j].tracking && samples[j].segment == samples[i].segment &&
           samples[j].dist - samples[i].dist < pair_distance_m)
      ++j;
    if (j >= samples.size() || !samples[j].tracking || samples[j].segment != samples[i].segment) {
      i = j;
      continue;
    }
    const Sample& a = samples[i];
    const Sample& b = samples[j];
    const Eigen::Matrix3d dv = a.vo.linear().transpose() * b.vo.linear();
    const Eigen::Matrix3d dt_ = a.truth.linear().transpose() * b.truth.linear();
    rot.push_back(angle_deg(dv.transpose() * dt_));
    {
      const Eigen::AngleAxisd e(dt_.transpose() * dv);  // error rotation in body frame a
      const Eigen::Vector3d ev = e.angle() * e.axis() * 180.0 / M_PI;
      signed_err_sum += ev;
      ++signed_n;
    }
    const Eigen::Vector3d tv = a.vo.linear().transpose() * (b.vo.translation() - a.vo.translation());
    const Eigen::Vector3d tt = a.truth.linear().transpose() * (b.truth.translation() - a.truth.translation());
    if (tv.norm() > 1e-9 && tt.norm() > 1e-9) {
      dir.push_back(std::acos(std::clamp(tv.normalized().dot(tt.normalized()), -1.0, 1.0)) * 180.0 / M_PI);
      const std::size_t seg = std::min<std::size_t>(a.segment, scale_by_segment.size() - 1);
      scale_by_segment[seg].push_back(ScalePoint{a.dist, std::log(tv.norm() / tt.norm())});
    }
    pairs.t.push_back(a.t);
    pairs.rot.push_back(rot.back());
    pairs.dir.push_back(dir.empty() ? 0.0 : dir.back());
    i = j;
  }
  for (const Sample& s : samples)
    if (s.tracking)
      tilt.push_back(std::acos(std::clamp(s.vo.linear().col(2).dot(s.truth.linear().col(2)), -1.0, 1.0)) * 180.0 / M_PI);
  m.rpe_pairs = rot.size();
  if (signed_n > 0) m.rpe_rotation_mean_deg = signed_err_sum / static_cast<double>(signed_n);
  m.rpe_rotation_deg_p50 = quantile(rot, 0.5);
  m.rpe_rotation_deg_p95 = quantile(rot, 0.95);
  m.rpe_translation_direction_deg_p50 = quantile(dir, 0.5);
  m.rpe_translation_direction_deg_p95 = quantile(dir, 0.95);
  m.tilt_error_deg_p95 = quantile(tilt, 0.95);
  m.scale_drift_percent_per_100m = scale_drift_percent_per_100m(scale_by_segment);
  return pairs;
}

// metrics.json, trajectory.csv, the pair plots and report.md.
Status write_vo_files(const EvalVoOptions& o, const VoMetrics& m, const std::vector<Sample>& samples, const PairSeries& pairs) {
  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + o.out_dir + ": " + ec.message());
  {
    std::ofstream j(fs::path(o.out_dir) / "metrics.json");
    j << "{\n  \"world\": \"" << o.world << "\",\n  \"seed\": " << o.seed << ",\n  \"oracles\": [],\n  \"attitude\": "
      << (o.attitude ? "true" : "false") << ",\n  \"frames\": " << m.frames << ",\n  \"tracked_frames\": " << m.tracked_frames
      << ",\n  \"tracked_fraction\": " << m.tracked_fraction << ",\n  \"segments\": " << m.segments << ",\n  \"keyframes\": " << m.keyframes
      << ",\n  \"rpe_pairs\": " << m.rpe_pairs << ",\n  \"rpe_rotation_deg_p50\": " << m.rpe_rotation_deg_p50
      << ",\n  \"rpe_rotation_deg_p95\": " << m.rpe_rotation_deg_p95 << ",\n  \"rpe_rotation_mean_body_xyz_deg\": ["
      << m.rpe_rotation_mean_deg.x() << ", " << m.rpe_rotation_mean_deg.y() << ", " << m.rpe_rotation_mean_deg.z() << "]" << ",\n  \"rpe_translation_direction_deg_p50\": "
      << m.rpe_translation_direction_deg_p50 << ",\n  \"rpe_translation_direction_deg_p95\": " << m.rpe_translation_direction_deg_p95
      << ",\n  \"scale_drift_percent_per_100m\": " << m.scale_drift_percent_per_100m << ",\n  \"tilt_error_deg_p95\": " << m.tilt_error_deg_p95
      << ",\n  \"ms_per_frame_p50\": " << m.ms_per_frame_p50 << ",\n  \"ms_per_frame_p99\": " << m.ms_per_frame_p99
      << ",\n  \"render_ms_per_frame\": " << m.render_ms_per_frame << ",\n  \"distance_m\": " << m.distance_m
      << ",\n  \"duration_s\": " << m.duration_s << "\n}\n";
    if (!j) return Error::make(ErrorCode::kIo, "cannot write " + (fs::path(o.out_dir) / "metrics.json").string());
  }
  {
    std::ofstream c(fs::path(o.out_dir) / "trajectory.csv");
    c << "t_s,tracking,segment,vo_x,vo_y,vo_z,true_x,true_y,true_z\n";
    for (const Sample& s : samples)
      c << s.t << ',' << (s.tracking ? 1 : 0) << ',' << s.segment << ',' << s.vo.translation().x() << ',' << s.vo.translation().y() << ','
        << s.vo.translation().z() << ',' << s.truth.translation().x() << ',' << s.truth.translation().y() << ',' << s.truth.translation().z() << '\n';
  }
  PlotOptions po;
  po.title = "relative rotation error per " + std::to_string(o.pair_distance_m).substr(0, 3) + " m pair";
  po.x_label = "time [s]";
  po.y_label = "deg";
  po.h_lines = {0.2};
  cv::imwrite((fs::path(o.out_dir) / "rpe_rotation.png").string(), line_plot({PlotSeries{"rotation", pairs.t, pairs.rot, series_colour(0), true}}, po));
  po.title = "translation direction error per pair";
  po.h_lines = {2.0};
  cv::imwrite((fs::path(o.out_dir) / "rpe_direction.png").string(), line_plot({PlotSeries{"direction", pairs.t, pairs.dir, series_colour(1), true}}, po));
  std::ofstream md(fs::path(o.out_dir) / "report.md");
  md << "# Visual odometry on the survey (world " << o.world << ", seed " << o.seed << ")\n\nOracles: none. "
     << (o.attitude ? "Gravity from the autopilot's attitude (simulated PX4 EKF2 errors)." : "Vision only (no attitude).") << "\n\n"
     << "| metric | value | goal |\n|---|---|---|\n| frames | " << m.frames << " | |\n| tracked fraction | " << m.tracked_fraction
     << " | >= 0.98 |\n| segments | " << m.segments << " | |\n| RPE rotation p95 [deg] | " << m.rpe_rotation_deg_p95
     << " | <= 0.2 |\n| RPE translation direction p95 [deg] | " << m.rpe_translation_direction_deg_p95 << " | <= 2 |\n| scale drift [%/100 m] | "
     << m.scale_drift_percent_per_100m << " | |\n| tilt error p95 [deg] | " << m.tilt_error_deg_p95 << " | |\n| VO ms/frame p50 / p99 (thread CPU) | "
     << m.ms_per_frame_p50 << " / " << m.ms_per_frame_p99 << " | <= 40 (p50) |\n\n![rotation](rpe_rotation.png)\n\n![direction](rpe_direction.png)\n";
  return ok_status();
}

}  // namespace

Result<VoMetrics> eval_vo(const EvalVoOptions& o, const EvalVoProgress& progress) {
  auto world = resolve_world(o.world);
  if (!world) return world.error();
  const World& w = *world.value();
  auto camera = load_camera(o);
  if (!camera) return camera.error();
  auto att_cfg = load_attitude(o);
  if (!att_cfg) return att_cfg.error();
  const CameraModel& model = camera.value().model;
  auto params = vo_params(o, model.pinhole());
  if (!params) return params.error();

  const GridGeometry& g = w.grid();
  const double margin = 20.0;
  const double hfov = 2.0 * std::atan(0.5 * model.width / model.fx);
  SurveyOptions so;
  so.speed_mps = o.speed_mps;
  auto route = survey_lawnmower(g.origin_x + margin, g.origin_y - g.size_y() + margin, g.origin_x + g.size_x() - margin,
                                g.origin_y - margin, o.altitude_m, o.overlap, hfov, so);
  if (!route) return route.error();
  auto flight = fly_survey(w, camera.value(), att_cfg.value(), params.value(), route.value(), o, progress);
  if (!flight) return flight.error();
  const Flight& fl = flight.value();

  VoMetrics m;
  m.frames = fl.samples.size();
  m.distance_m = fl.distance_m;
  m.duration_s = fl.duration_s;
  m.segments = fl.stats.segments;
  m.keyframes = fl.stats.keyframes;
  for (const Sample& s : fl.samples) m.tracked_frames += s.tracking ? 1U : 0U;
  m.tracked_fraction = m.frames ? static_cast<double>(m.tracked_frames) / static_cast<double>(m.frames) : 0.0;
  m.ms_per_frame_p50 = quantile(fl.vo_ms, 0.5);
  m.ms_per_frame_p99 = quantile(fl.vo_ms, 0.99);
  m.render_ms_per_frame = m.frames ? fl.render_s * 1e3 / static_cast<double>(m.frames) : 0.0;
  const PairSeries pairs = score_pairs(fl.samples, o.pair_distance_m, m);
  if (auto st = write_vo_files(o, m, fl.samples, pairs); !st) return st.error();
  return m;
}

}  // namespace ag::sim
