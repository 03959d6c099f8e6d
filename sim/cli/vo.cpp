// airground-sim vo (the quadrotor's visual odometry over a folder of images) and eval vo (over a
// simulated survey, scored against the truth).
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <unistd.h>
#include <vector>

#include "airground/messages/camera.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/eval_vo.hpp"
#include "airground/sim/plot.hpp"
#include "airground/visual_odometry/visual_odometry.hpp"

namespace fs = std::filesystem;

namespace {

constexpr const char* kVoHelp =
    "airground-sim vo --images DIR --camera CAMERA.yaml --out DIR [--set KEY=VALUE ...] [--quiet]\n\n"
    "Runs the quadrotor's visual odometry (the uav's vo stage, vision only: no autopilot attitude) over the\n"
    "image files of DIR (png, jpg, jpeg, bmp, tif, tiff; sorted by name; any size, resampled to 640x400 as\n"
    "the camera stage does). CAMERA.yaml is in the project's camera format (section `camera:` with width,\n"
    "height, fx, fy, cx, cy, k1, k2, p1, p2, k3 of the original images; config/sensors/camera.yaml).\n"
    "Writes into DIR:\n"
    "  trajectory.csv   image,tracking,segment,x,y,z,qw,qx,qy,qz: the camera pose in the first camera frame of\n"
    "                   its segment (OpenCV axes; up to scale; a new segment after each tracking loss)\n"
    "  trajectory.png   the camera positions seen from above (x right, y forward of the first frame)\n"
    "Parameters (--set): max_features, keyframe_parallax_px, window_keyframes, min_pose_inliers,\n"
    "max_reprojection_px. Exit 2: no images, an unreadable image, a bad camera file or option.\n";

constexpr const char* kEvalVoHelp =
    "airground-sim eval vo --world W --seed S --out DIR [options]\n\n"
    "Flies the survey (lawnmower over the world) with the simulator's quadrotor, renders every camera frame\n"
    "(with the camera's noise, blur, exposure and vignetting), runs the uav's visual odometry on them with the\n"
    "autopilot's attitude as gravity, and scores it against the true trajectory. Writes DIR/metrics.json\n"
    "(frames, tracked_fraction, segments, rpe_rotation_deg_p95, rpe_translation_direction_deg_p95 over\n"
    "consecutive frame pairs 2 m apart, scale_drift_percent_per_100m, ms_per_frame_p50/p99 in thread CPU),\n"
    "report.md, rpe_rotation.png, rpe_direction.png and trajectory.csv.\n"
    "Defaults: --world default --seed 1 --out eval-vo.\n\n"
    "Options:\n"
    "  --altitude M        survey altitude (40)            --speed V      survey speed (5 m/s)\n"
    "  --overlap F         side overlap (0.3)              --camera-hz F  frame rate (5, the team runner's)\n"
    "  --max-duration T    stop after T simulated seconds (default: the whole survey)\n"
    "  --camera FILE       camera YAML (intrinsics, shading, sensor realism)\n"
    "  --attitude FILE     the autopilot attitude error model (YAML, see airground-sim config)\n"
    "  --no-attitude       vision only: no autopilot attitude (gravity) prior\n"
    "  --set KEY=VALUE     a vo stage parameter (repeatable)\n"
    "  --quiet             no progress line\n"
    "  --record none|mcap  DIR/recording.mcap (mcap, the default: the true flight, every 5th frame) or nothing\n";

struct Options {
  std::map<std::string, std::vector<std::string>> opt;
  [[nodiscard]] bool has(const std::string& k) const { return opt.count(k) != 0; }
  [[nodiscard]] std::string get(const std::string& k, const std::string& def = "") const {
    auto it = opt.find(k);
    return it == opt.end() || it->second.empty() ? def : it->second.back();
  }
};

[[noreturn]] void usage(const char* cmd, const std::string& msg) {
  std::fprintf(stderr, "airground-sim %s: %s (see airground-sim %s --help)\n", cmd, msg.c_str(), cmd);
  std::exit(2);
}

// --key value pairs; flags take no value; an option not in `valued` or `flags` is an error naming it.
Options parse(const char* cmd, int argc, char** argv, int first, const std::set<std::string>& valued, const std::set<std::string>& flags) {
  Options o;
  for (int i = first; i < argc; ++i) {
    const std::string s = argv[i];
    if (s.rfind("--", 0) != 0) usage(cmd, "unexpected argument '" + s + "'");
    const std::string k = s.substr(2);
    if (flags.count(k)) {
      o.opt[k];
      continue;
    }
    if (!valued.count(k)) usage(cmd, "unknown option '--" + k + "'");
    if (i + 1 >= argc) usage(cmd, "--" + k + " needs a value");
    o.opt[k].push_back(argv[++i]);
  }
  return o;
}

double number(const char* cmd, const Options& o, const std::string& k, double def) {
  if (!o.has(k)) return def;
  const std::string v = o.get(k);
  char* end = nullptr;
  const double d = std::strtod(v.c_str(), &end);
  if (v.empty() || *end != '\0' || !std::isfinite(d)) usage(cmd, "--" + k + " needs a number, got '" + v + "'");
  return d;
}

bool is_image(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return e == ".png" || e == ".jpg" || e == ".jpeg" || e == ".bmp" || e == ".tif" || e == ".tiff";
}

}  // namespace

int vo_cmd(int argc, char** argv) {
  for (int i = 2; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      std::fputs(kVoHelp, stdout);
      return 0;
    }
  const Options o = parse("vo", argc, argv, 2, {"images", "camera", "out", "set"}, {"quiet"});
  if (!o.has("images") || !o.has("camera") || !o.has("out")) usage("vo", "needs --images DIR, --camera CAMERA.yaml and --out DIR");
  const fs::path dir = o.get("images");
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) usage("vo", "--images " + dir.string() + " is not a directory");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_regular_file() && is_image(e.path())) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) usage("vo", "no image files (png, jpg, jpeg, bmp, tif, tiff) in " + dir.string());
  auto model = ag::sim::CameraModel::load_file(o.get("camera"));
  if (!model) usage("vo", "camera file: " + model.error().message);
  const ag::sim::CameraModel& m = model.value();
  // Resampled to 640x400 whatever the size: the intrinsics scale per axis (pixel centres at integers).
  const double sx = 640.0 / m.width, sy = 400.0 / m.height;
  ag::PinholeCamera cam;
  cam.fx = m.fx * sx;
  cam.fy = m.fy * sy;
  cam.cx = (m.cx + 0.5) * sx - 0.5;
  cam.cy = (m.cy + 0.5) * sy - 0.5;
  cam.k1 = m.k1;
  cam.k2 = m.k2;
  cam.p1 = m.p1;
  cam.p2 = m.p2;
  cam.k3 = m.k3;
  ag::vo::VoParams p;
  p.camera = cam;
  if (o.has("set"))
    for (const std::string& kv : o.opt.at("set")) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos) usage("vo", "--set needs KEY=VALUE, got '" + kv + "'");
      const std::string k = kv.substr(0, eq);
      char* end = nullptr;
      const double v = std::strtod(kv.c_str() + eq + 1, &end);
      if (*end != '\0') usage("vo", "--set " + kv + ": the value is not a number");
      if (k == "max_features") p.max_features = static_cast<int>(v);
      else if (k == "keyframe_parallax_px") p.keyframe_parallax_px = v;
      else if (k == "window_keyframes") p.window_keyframes = static_cast<int>(v);
      else if (k == "min_pose_inliers") p.min_pose_inliers = static_cast<int>(v);
      else if (k == "max_reprojection_px") p.max_reprojection_px = v;
      else usage("vo", "--set: unknown parameter '" + k + "'");
    }
  const fs::path out = o.get("out");
  fs::create_directories(out, ec);
  if (ec) {
    std::fprintf(stderr, "airground-sim vo: cannot create %s: %s\n", out.c_str(), ec.message().c_str());
    return 1;
  }
  ag::vo::VisualOdometry odo(p);
  std::ofstream csv(out / "trajectory.csv");
  csv << "image,tracking,segment,x,y,z,qw,qx,qy,qz\n";
  std::vector<double> xs, ys;
  std::map<std::uint32_t, Eigen::Isometry3d> first_camera;  // segment -> its first camera pose (segment frame)
  cv::Mat rgb;
  const bool quiet = o.has("quiet");
  for (std::size_t i = 0; i < files.size(); ++i) {
    cv::Mat img = cv::imread(files[i].string(), cv::IMREAD_COLOR);
    if (img.empty()) usage("vo", "cannot read image " + files[i].string());
    cv::resize(img, img, cv::Size(640, 400), 0, 0, cv::INTER_AREA);
    cv::cvtColor(img, rgb, cv::COLOR_BGR2RGB);
    const ag::vo::VoFrame f = odo.process(static_cast<ag::TimeNs>(i) * 100'000'000, rgb.ptr<std::uint8_t>(0), std::nullopt);
    Eigen::Isometry3d cam_in_seg = Eigen::Isometry3d::Identity();
    cam_in_seg.linear() = f.body_in_segment.linear() * ag::nadir_body_from_camera();
    cam_in_seg.translation() = f.body_in_segment.translation();
    if (f.tracking && !first_camera.count(f.segment)) first_camera[f.segment] = cam_in_seg;
    csv << files[i].filename().string() << ',' << (f.tracking ? 1 : 0) << ',' << f.segment;
    if (f.tracking) {
      const Eigen::Isometry3d rel = first_camera[f.segment].inverse() * cam_in_seg;
      const Eigen::Quaterniond q(rel.linear());
      csv << ',' << rel.translation().x() << ',' << rel.translation().y() << ',' << rel.translation().z() << ',' << q.w() << ',' << q.x()
          << ',' << q.y() << ',' << q.z() << '\n';
      if (f.segment == odo.stats().segments - 1) {
        xs.push_back(rel.translation().x());
        ys.push_back(-rel.translation().y());
      }
    } else {
      csv << ",,,,,,,\n";
    }
    if (!quiet && isatty(2)) std::fprintf(stderr, "\rvo: %zu / %zu images", i + 1, files.size());
  }
  if (!quiet && isatty(2)) std::fprintf(stderr, "\n");
  ag::sim::PlotOptions po;
  po.title = "camera positions from above (last segment, VO units)";
  po.x_label = "x (right of the first frame)";
  po.y_label = "forward";
  po.height = 700;
  po.width = 700;
  cv::imwrite((out / "trajectory.png").string(), ag::sim::line_plot({ag::sim::PlotSeries{"camera", xs, ys, ag::sim::series_colour(0), false}}, po));
  const auto& s = odo.stats();
  std::printf("%zu images: %llu tracked, %llu segments, %llu keyframes; %s/trajectory.csv\n", files.size(),
              static_cast<unsigned long long>(s.tracked_frames), static_cast<unsigned long long>(s.segments),
              static_cast<unsigned long long>(s.keyframes), out.c_str());
  return 0;
}

int eval_vo_cmd(int argc, char** argv) {
  for (int i = 3; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      std::fputs(kEvalVoHelp, stdout);
      return 0;
    }
  const Options a = parse("eval vo", argc, argv, 3,
                          {"world", "seed", "out", "altitude", "speed", "overlap", "camera-hz", "max-duration", "camera", "attitude", "set", "record"},
                          {"no-attitude", "quiet"});
  ag::sim::EvalVoOptions o;
  o.world = a.get("world", o.world);
  o.seed = static_cast<std::uint64_t>(number("eval vo", a, "seed", static_cast<double>(o.seed)));
  o.out_dir = a.get("out", o.out_dir);
  o.altitude_m = number("eval vo", a, "altitude", o.altitude_m);
  o.speed_mps = number("eval vo", a, "speed", o.speed_mps);
  o.overlap = number("eval vo", a, "overlap", o.overlap);
  o.camera_hz = number("eval vo", a, "camera-hz", o.camera_hz);
  o.max_duration_s = number("eval vo", a, "max-duration", o.max_duration_s);
  o.camera_config = a.get("camera");
  o.attitude_config = a.get("attitude");
  o.attitude = !a.has("no-attitude");
  o.quiet = a.has("quiet");
  if (a.has("set")) o.set = a.opt.at("set");
  const std::string record = a.get("record", "mcap");
  if (record != "none" && record != "mcap") usage("eval vo", "--record must be none or mcap, got '" + record + "'");
  o.record = record == "mcap";
  if (!(o.altitude_m > 0) || !(o.speed_mps > 0) || !(o.camera_hz > 0) || !(o.max_duration_s > 0))
    usage("eval vo", "--altitude, --speed, --camera-hz and --max-duration must be positive");
  const bool tty = isatty(2) != 0;
  std::fprintf(stderr, "VO evaluation on world '%s' (seed %llu) -> %s\n", o.world.c_str(), static_cast<unsigned long long>(o.seed), o.out_dir.c_str());
  int last = -1;
  auto m = ag::sim::eval_vo(o, [&](double f) {
    if (o.quiet) return;
    const int pct = static_cast<int>(100 * f);
    if (pct == last || (!tty && pct % 10 != 0)) return;
    last = pct;
    std::fprintf(stderr, "%ssurvey: %3d %%%s", tty ? "\r" : "", pct, tty ? "" : "\n");
  });
  if (!o.quiet && tty) std::fprintf(stderr, "\n");
  if (!m) {
    std::fprintf(stderr, "airground-sim eval vo: %s\n", m.error().message.c_str());
    return m.error().code == ag::ErrorCode::kInvalidArgument || m.error().code == ag::ErrorCode::kConfig ? 2 : 1;
  }
  const ag::sim::VoMetrics& r = m.value();
  std::printf("frames %llu  tracked_fraction %.4f  segments %llu  keyframes %llu\n", static_cast<unsigned long long>(r.frames),
              r.tracked_fraction, static_cast<unsigned long long>(r.segments), static_cast<unsigned long long>(r.keyframes));
  std::printf("rpe_rotation_deg p50 %.3f p95 %.3f  rpe_translation_direction_deg p50 %.2f p95 %.2f  (%llu pairs)\n", r.rpe_rotation_deg_p50,
              r.rpe_rotation_deg_p95, r.rpe_translation_direction_deg_p50, r.rpe_translation_direction_deg_p95,
              static_cast<unsigned long long>(r.rpe_pairs));
  std::printf("scale_drift_percent_per_100m %.2f  tilt p95 %.3f deg  ms_per_frame p50 %.1f p99 %.1f (render %.1f ms)\n",
              r.scale_drift_percent_per_100m, r.tilt_error_deg_p95, r.ms_per_frame_p50, r.ms_per_frame_p99, r.render_ms_per_frame);
  std::printf("metrics: %s/metrics.json\n", o.out_dir.c_str());
  return 0;
}
