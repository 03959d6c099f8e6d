// The localization evaluation: one ground robot on a long road loop through the lockstep runner, its
// published pose scored against the truth.
#include "airground/sim/eval_localization.hpp"

#include <yaml-cpp/yaml.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "airground/messages/messages.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/log.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/scripted_driver.hpp"
#include "airground/sim/world_png.hpp"
#include "roles.hpp"

namespace ag::sim {

namespace {

namespace fs = std::filesystem;

struct Sample {
  double t_s{0};
  bool released{false}, held{false}, received{false}, good{false};
  LocalizationStatus status{LocalizationStatus::kNoMap};
  Pose2 truth, est, truth_at_est, odom;
  double est_age_s{0};
  double err_m{-1}, yaw_err_deg{-1}, odom_err_m{0};
  double spread_m{0};
  std::uint32_t particles{0};
  double distance_m{0};
};

const char* status_name(LocalizationStatus s) noexcept {
  switch (s) {
    case LocalizationStatus::kNoMap: return "no map";
    case LocalizationStatus::kInitialising: return "initialising";
    case LocalizationStatus::kTracking: return "tracking";
    case LocalizationStatus::kLost: return "lost";
  }
  return "?";
}

// Copies the caller's model overrides into out/models and adds the evaluation's (odometry yaw drift at rest).
Result<std::string> model_dir(const EvalLocalizationOptions& o) {
  if (!o.yaw_drift_at_rest_set) return o.config_dir;
  const fs::path dir = fs::path(o.out_dir) / "models";
  std::error_code ec;
  fs::remove_all(dir, ec);  // what an earlier run into this folder left
  fs::create_directories(dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + dir.string() + ": " + ec.message());
  if (!o.config_dir.empty())
    for (const auto& e : fs::directory_iterator(o.config_dir, ec))
      if (e.path().extension() == ".yaml") fs::copy_file(e.path(), dir / e.path().filename(), fs::copy_options::overwrite_existing, ec);
  const fs::path p = dir / "wheel_odometry.yaml";
  YAML::Node root(YAML::NodeType::Map);
  if (fs::exists(p)) {
    try {
      root = YAML::LoadFile(p.string());
    } catch (const YAML::Exception& e) {
      return Error::make(ErrorCode::kConfig, "config error: " + p.string() + ": malformed YAML: " + e.msg);
    }
    if (!root.IsMap()) return Error::make(ErrorCode::kConfig, "config error: " + p.string() + ": not a mapping");
  }
  const YAML::Node& croot = root;
  if (croot["wheel_odometry"]) root["wheel_odometry"]["yaw_drift_at_rest_rad_per_s"] = o.yaw_drift_at_rest;
  else root["yaw_drift_at_rest_rad_per_s"] = o.yaw_drift_at_rest;
  std::ofstream out(p);
  out << "# written by airground-sim eval localization (--yaw-drift-at-rest)\n" << root << "\n";
  if (!out) return Error::make(ErrorCode::kIo, "cannot write " + p.string());
  return dir.string();
}

std::string num(double v) {
  if (!std::isfinite(v)) return "null";
  char b[32];
  std::snprintf(b, sizeof b, "%.4g", v);
  return b;
}

// The class map with the true path (white), the odometry alone (orange), the estimate (blue where good,
// red where tracking but off), the start (circle) and the initial guess (cross).
cv::Mat trajectory_image(const World& w, const std::vector<Sample>& s, const std::vector<Eigen::Vector2d>& route,
                         const Pose2* initial_guess) {
  cv::Mat bgr;
  cv::cvtColor(class_display_image(w.class_id), bgr, cv::COLOR_RGB2BGR);
  bgr = bgr * 0.6;  // dimmed so the tracks stand out
  const double scale = std::min(1.0, 1600.0 / std::max(bgr.cols, bgr.rows));
  if (scale < 1.0) cv::resize(bgr, bgr, cv::Size(), scale, scale, cv::INTER_AREA);
  const GridGeometry& g = w.grid();
  auto px = [&](double x, double y) { return cv::Point(static_cast<int>(g.col_f(x) * scale), static_cast<int>(g.row_f(y) * scale)); };
  for (std::size_t i = 1; i < route.size(); ++i)
    cv::line(bgr, px(route[i - 1].x(), route[i - 1].y()), px(route[i].x(), route[i].y()), cv::Scalar(90, 90, 90), 5, cv::LINE_AA);
  for (std::size_t i = 1; i < s.size(); ++i) {
    cv::line(bgr, px(s[i - 1].odom.x, s[i - 1].odom.y), px(s[i].odom.x, s[i].odom.y), cv::Scalar(0, 140, 255), 2, cv::LINE_AA);
    cv::line(bgr, px(s[i - 1].truth.x, s[i - 1].truth.y), px(s[i].truth.x, s[i].truth.y), cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
  }
  for (std::size_t i = 1; i < s.size(); ++i) {
    const bool tracking = s[i].received && s[i].status == LocalizationStatus::kTracking && s[i - 1].received &&
                          s[i - 1].status == LocalizationStatus::kTracking;
    if (!tracking) continue;
    const cv::Scalar c = s[i].good ? cv::Scalar(255, 120, 0) : cv::Scalar(0, 0, 255);
    cv::line(bgr, px(s[i - 1].est.x, s[i - 1].est.y), px(s[i].est.x, s[i].est.y), c, 2, cv::LINE_AA);
  }
  if (!s.empty()) cv::circle(bgr, px(s.front().truth.x, s.front().truth.y), 7, cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
  if (initial_guess != nullptr)
    cv::drawMarker(bgr, px(initial_guess->x, initial_guess->y), cv::Scalar(255, 0, 255), cv::MARKER_CROSS, 16, 2, cv::LINE_AA);
  const char* labels[] = {"truth", "estimate (good)", "estimate (tracking, > radius)", "odometry only", "x initial guess"};
  const cv::Scalar cols[] = {{255, 255, 255}, {255, 120, 0}, {0, 0, 255}, {0, 140, 255}, {255, 0, 255}};
  cv::rectangle(bgr, cv::Rect(8, 8, 300, 20 * 5 + 10), cv::Scalar(30, 30, 30), cv::FILLED);
  for (int i = 0; i < 5; ++i) {
    cv::line(bgr, cv::Point(16, 24 + 20 * i), cv::Point(40, 24 + 20 * i), cols[i], 3);
    cv::putText(bgr, labels[i], cv::Point(48, 29 + 20 * i), cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
  }
  return bgr;
}

// Error over time: the estimate's (blue when good, red otherwise) and the odometry's (orange); the
// convergence radius dashed, convergence as a green line, standing still shaded.
cv::Mat error_image(const std::vector<Sample>& s, double radius, double conv_t, double released_s) {
  constexpr int W = 1200, H = 520, L = 70, R = 20, T = 36, B = 50;
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  const double t0 = s.empty() ? 0 : s.front().t_s, t1 = s.empty() ? 1 : std::max(s.back().t_s, t0 + 1);
  double ymax = 2 * radius;
  for (const auto& q : s) {
    ymax = std::max(ymax, std::min(q.odom_err_m, 60.0));
    if (q.err_m >= 0) ymax = std::max(ymax, std::min(q.err_m, 60.0));
  }
  ymax = std::ceil(ymax / 5.0) * 5.0;
  auto X = [&](double t) { return L + static_cast<int>((t - t0) / (t1 - t0) * (W - L - R)); };
  auto Y = [&](double e) { return H - B - static_cast<int>(std::min(e, ymax) / ymax * (H - T - B)); };
  for (std::size_t i = 0; i < s.size(); ++i)
    if (s[i].held) cv::line(img, cv::Point(X(s[i].t_s), T), cv::Point(X(s[i].t_s), H - B), cv::Scalar(225, 225, 225), 2);
  cv::rectangle(img, cv::Point(L, T), cv::Point(W - R, H - B), cv::Scalar(0, 0, 0), 1);
  for (int k = 0; k <= 5; ++k) {
    const double e = ymax * k / 5.0;
    cv::line(img, cv::Point(L - 4, Y(e)), cv::Point(W - R, Y(e)), cv::Scalar(235, 235, 235), 1);
    cv::putText(img, num(e), cv::Point(8, Y(e) + 5), cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    const double t = t0 + (t1 - t0) * k / 5.0;
    cv::putText(img, num(std::round(t)), cv::Point(X(t) - 12, H - B + 20), cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  for (int x = L; x < W - R; x += 12) cv::line(img, cv::Point(x, Y(radius)), cv::Point(x + 6, Y(radius)), cv::Scalar(0, 160, 0), 1);
  if (released_s > t0) cv::line(img, cv::Point(X(released_s), T), cv::Point(X(released_s), H - B), cv::Scalar(128, 128, 128), 1);
  if (conv_t >= 0) cv::line(img, cv::Point(X(conv_t), T), cv::Point(X(conv_t), H - B), cv::Scalar(0, 160, 0), 2);
  for (std::size_t i = 1; i < s.size(); ++i) {
    cv::line(img, cv::Point(X(s[i - 1].t_s), Y(s[i - 1].odom_err_m)), cv::Point(X(s[i].t_s), Y(s[i].odom_err_m)), cv::Scalar(0, 140, 255), 2, cv::LINE_AA);
    if (s[i].err_m < 0 || s[i - 1].err_m < 0) continue;
    const bool tracking = s[i].status == LocalizationStatus::kTracking && s[i - 1].status == LocalizationStatus::kTracking;
    const cv::Scalar c = !tracking ? cv::Scalar(170, 170, 170) : (s[i].good ? cv::Scalar(255, 120, 0) : cv::Scalar(0, 0, 255));
    cv::line(img, cv::Point(X(s[i - 1].t_s), Y(s[i - 1].err_m)), cv::Point(X(s[i].t_s), Y(s[i].err_m)), c, tracking ? 2 : 1, cv::LINE_AA);
  }
  cv::putText(img, "position error [m] / simulated time [s]. Estimate: blue good, red off, grey not tracking. Odometry only: orange.",
              cv::Point(L, 14), cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  cv::putText(img, "Dashed: convergence radius; green: convergence; thin grey: start of driving; shaded: standing still.",
              cv::Point(L, 27), cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  return img;
}

// The run: one robot driving the route on the chosen map, with the evaluation's holds and labeller;
// m.labels says which labeller.
Result<RunOptions> drive_run_options(const EvalLocalizationOptions& o, const std::string& models, const std::vector<Eigen::Vector2d>& route,
                                     LocalizationMetrics& m) {
  RunOptions r;
  r.world = o.world;
  r.out_dir = o.out_dir;
  r.ugvs = 1;
  r.uav = o.map == UgvMapSource::kOnline;
  r.seed = o.seed;
  r.lidar_columns = o.lidar_columns;
  r.ugv_speed_mps = o.speed_mps;
  r.survey_overlap = 0.3;  // as eval mapping
  r.config_dir = models;
  r.record = o.record ? RecordLevel::kMcap : RecordLevel::kNone;  // recording.mcap, no CSV streams
  r.threads = o.threads;
  r.progress = !o.quiet;
  r.ugv_map = o.map;
  r.init_error_m = o.init_error_m;
  r.init_yaw_error_deg = o.init_yaw_error_deg;
  r.ugv_routes = {route};
  r.stop_when_routes_done = true;
  if (o.map == UgvMapSource::kOnline) {
    r.ugv_wait_map_radius_m = o.wait_map_radius_m;
    r.ugv_wait_map_fraction = o.wait_map_fraction;
    r.ugv_wait_map_route_fraction = o.wait_map_route;
  }
  if (o.stand_still_s > 0) r.ugv_holds.push_back(UgvHold{0, o.stand_still_at_s, o.stand_still_s});
  // Turning in place and slowing for corners: about 1.4 x the straight-line time; waiting for the
  // online map at most a survey's worth.
  r.duration_s = o.max_duration_s > 0 ? o.max_duration_s
                                      : 1.5 * m.route_length_m / o.speed_mps + 60.0 + std::max(0.0, o.stand_still_s) +
                                            (o.map == UgvMapSource::kOnline ? 3600.0 : 0.0);
  r.ugv_config = o.set;
  r.oracles = o.oracles;
  r.compute_time = o.compute_time;
  r.target_cpu = o.target_cpu;
  // The shipped labeller (geometric), or the true classes in the labels ablation.
  m.labels = r.oracle("labels") ? "gt" : "geometric";
  if (!o.labels.empty()) {
    if (o.labels != "gt" && o.labels != "geometric") return Error::make(ErrorCode::kInvalidArgument, "--labels must be gt or geometric");
    if (o.labels == "gt" && !r.oracle("labels"))
      return Error::make(ErrorCode::kInvalidArgument, "--labels gt needs the scans' true classes, which a LiDAR does not give: name the ablation --oracle labels");
    r.ugv_config.push_back("localization.labels=" + o.labels);
    m.labels = o.labels;
  }
  r.sample_hz = 10;
  return r;
}

// One 10 Hz sample: the truth, the odometry and the published estimate against the truth at its stamp.
Sample to_sample(const UgvSample& u, double stale_after_s, double radius) {
  Sample s;
  s.t_s = to_seconds(u.now);
  s.released = u.released;
  s.held = u.held;
  s.received = u.localization_received;
  s.truth = u.truth;
  s.odom = u.odometry_in_map;
  s.odom_err_m = std::hypot(u.odometry_in_map.x - u.truth.x, u.odometry_in_map.y - u.truth.y);
  s.distance_m = u.distance_m;
  if (u.localization_received) {
    const LocalizationMsg& l = *u.localization;
    s.status = l.status;
    s.est = l.pose;
    s.truth_at_est = u.truth_at_localization;
    s.est_age_s = to_seconds(u.now - l.stamp);
    s.err_m = std::hypot(l.pose.x - u.truth_at_localization.x, l.pose.y - u.truth_at_localization.y);
    s.yaw_err_deg = std::abs(wrap_angle(l.pose.yaw - u.truth_at_localization.yaw)) * 180.0 / kPi;
    s.spread_m = l.spread_m;
    s.particles = l.particles;
    s.good = l.status == LocalizationStatus::kTracking && s.est_age_s <= stale_after_s && s.err_m <= radius;
  }
  return s;
}

struct DriveScore {
  bool scored_any{false};    // some sample was good: the errors are scored from the first of them
  double converged_t{-1};    // [s] simulated time of convergence; -1: not converged
};

// Scoring over the samples after the start of driving, into m.
DriveScore score_drive(const std::vector<Sample>& samples, const EvalLocalizationOptions& o, LocalizationMetrics& m) {
  std::vector<const Sample*> drive;
  for (const auto& s : samples)
    if (s.released) drive.push_back(&s);
  m.samples = drive.size();
  for (const auto& s : samples) m.localization_published = m.localization_published || s.received;
  std::size_t conv = drive.size();
  while (conv > 0 && drive[conv - 1]->good) --conv;
  std::uint64_t good = 0;
  bool seen_good = false, prev_good = false;
  for (const Sample* s : drive) {
    if (s->good) {
      ++good;
      if (!seen_good) m.first_tracking_s = s->t_s - m.released_s;
      seen_good = true;
    } else if (prev_good) {
      ++m.divergences;
    }
    prev_good = s->good;
  }
  m.good_fraction = drive.empty() ? 0.0 : static_cast<double>(good) / static_cast<double>(drive.size());
  m.converged = conv < drive.size();
  // Errors over every sample from the first good one on (a stale estimate counts as not tracking).
  std::vector<LocErrorSample> loc;
  for (const Sample* s : drive)
    loc.push_back(LocErrorSample{s->received, s->received && s->status == LocalizationStatus::kTracking && s->est_age_s <= o.stale_after_s, s->err_m});
  LocErrorScore score(o.convergence_radius_m);
  const std::size_t first = score.add_robot(loc);
  m.loc = score.stats();
  m.tracking_fraction = m.loc.tracking_fraction;
  m.within_fraction = m.loc.within_fraction;
  const bool scored_any = first < drive.size();
  double yaw_sum = 0, odom_sum = 0, conv_sum = 0;
  std::size_t yaw_n = 0;
  const std::size_t from = scored_any ? first : 0;
  for (std::size_t i = from; i < drive.size(); ++i) {
    odom_sum += drive[i]->odom_err_m;
    if (scored_any && drive[i]->received) {
      yaw_sum += drive[i]->yaw_err_deg;
      ++yaw_n;
    }
    if (m.converged && i >= conv) conv_sum += drive[i]->err_m;
  }
  const std::size_t scored = drive.size() - from;
  m.samples_scored = scored_any ? scored : 0;
  m.odom_only_error_mean_m = scored ? odom_sum / static_cast<double>(scored) : 0.0;
  m.odom_only_error_final_m = drive.empty() ? 0.0 : drive.back()->odom_err_m;
  if (scored_any) {
    m.loc_error_mean_m = m.loc.mean_m;
    m.loc_error_p95_m = m.loc.p95_m;
    m.loc_error_max_m = m.loc.max_m;
    m.yaw_error_mean_deg = yaw_n ? yaw_sum / static_cast<double>(yaw_n) : -1;
  }
  if (m.converged) {
    m.convergence_time_s = drive[conv]->t_s - m.released_s;
    m.convergence_distance_m = drive[conv]->distance_m;
    m.converged_error_mean_m = conv_sum / static_cast<double>(drive.size() - conv);
  }
  return DriveScore{scored_any, m.converged ? drive[conv]->t_s : -1};
}

Status write_samples_csv(const fs::path& out, const std::vector<Sample>& samples) {
  std::ofstream c(out / "samples.csv");
  c << "t_s,released,held,received,status,good,truth_x_m,truth_y_m,truth_yaw_rad,est_x_m,est_y_m,est_yaw_rad,est_age_s,"
       "err_m,yaw_err_deg,odom_x_m,odom_y_m,odom_yaw_rad,odom_err_m,spread_m,particles,distance_m\n";
  char line[512];
  for (const auto& s : samples) {
    std::snprintf(line, sizeof line, "%.2f,%d,%d,%d,%s,%d,%.3f,%.3f,%.4f,%.3f,%.3f,%.4f,%.3f,%.3f,%.3f,%.3f,%.3f,%.4f,%.3f,%.3f,%u,%.2f\n",
                  s.t_s, s.released ? 1 : 0, s.held ? 1 : 0, s.received ? 1 : 0, s.received ? status_name(s.status) : "none",
                  s.good ? 1 : 0, s.truth.x, s.truth.y, s.truth.yaw, s.est.x, s.est.y, s.est.yaw, s.est_age_s, s.err_m,
                  s.yaw_err_deg, s.odom.x, s.odom.y, s.odom.yaw, s.odom_err_m, s.spread_m, s.particles, s.distance_m);
    c << line;
  }
  if (!c) return Error::make(ErrorCode::kIo, "cannot write " + (out / "samples.csv").string());
  return ok_status();
}

const char* map_name(UgvMapSource map) noexcept {
  return map == UgvMapSource::kOnline ? "online" : (map == UgvMapSource::kGroundTruth ? "gt" : "none");
}

// metrics.json; false when it could not be written.
bool write_localization_metrics(const fs::path& out, const EvalLocalizationOptions& o, const RunOptions& r, const LocalizationMetrics& m,
                                bool scored_any) {
  std::ofstream j(out / "metrics.json");
  j << "{\n  \"converged\": " << (m.converged ? "true" : "false")
    << ",\n  \"convergence_time_s\": " << (m.converged ? num(m.convergence_time_s) : "null")
    << ",\n  \"convergence_distance_m\": " << (m.converged ? num(m.convergence_distance_m) : "null")
    << ",\n  \"loc_error_mean_m\": " << (scored_any ? num(m.loc_error_mean_m) : "null")
    << ",\n  \"loc_error_p95_m\": " << (scored_any ? num(m.loc_error_p95_m) : "null")
    << ",\n  \"loc_error_max_m\": " << (scored_any ? num(m.loc_error_max_m) : "null")
    << ",\n  \"loc_error_tracking_mean_m\": " << (m.loc.tracking_mean_m >= 0 ? num(m.loc.tracking_mean_m) : "null")
    << ",\n  \"loc_error_tracking_p95_m\": " << (m.loc.tracking_p95_m >= 0 ? num(m.loc.tracking_p95_m) : "null")
    << ",\n  \"loc_error_tracking_max_m\": " << (m.loc.tracking_max_m >= 0 ? num(m.loc.tracking_max_m) : "null")
    << ",\n  \"within_3m_fraction\": " << num(m.within_fraction)
    << ",\n  \"converged_error_mean_m\": " << (m.converged ? num(m.converged_error_mean_m) : "null")
    << ",\n  \"yaw_error_mean_deg\": " << (scored_any && m.yaw_error_mean_deg >= 0 ? num(m.yaw_error_mean_deg) : "null")
    << ",\n  \"odom_only_error_mean_m\": " << num(m.odom_only_error_mean_m)
    << ",\n  \"odom_only_error_final_m\": " << num(m.odom_only_error_final_m)
    << ",\n  \"localization_published\": " << (m.localization_published ? "true" : "false")
    << ",\n  \"first_tracking_s\": " << (m.first_tracking_s >= 0 ? num(m.first_tracking_s) : "null")
    << ",\n  \"divergences\": " << m.divergences << ",\n  \"tracking_fraction\": " << num(m.tracking_fraction)
    << ",\n  \"good_fraction\": " << num(m.good_fraction) << ",\n  \"scoring\": \"strict\""
    << ",\n  \"samples\": " << m.samples << ",\n  \"samples_scored\": " << m.samples_scored
    << ",\n  \"route_length_m\": " << num(m.route_length_m) << ",\n  \"distance_m\": " << num(m.distance_m)
    << ",\n  \"released_s\": " << num(m.released_s) << ",\n  \"tiles_published\": " << m.tiles_published
    << ",\n  \"scans_published\": " << m.scans_published << ",\n  \"sim_s\": " << num(m.sim_s) << ",\n  \"wall_s\": " << num(m.wall_s)
    << ",\n  \"oracles\": " << r.oracles_json() << ",\n  \"config\": {\"world\": \"" << o.world << "\", \"seed\": " << o.seed << ", \"map\": \"" << map_name(o.map)
    << "\", \"init_error_m\": " << num(o.init_error_m) << ", \"init_yaw_error_deg\": " << num(o.init_yaw_error_deg)
    << ", \"route_km\": " << num(o.route_km) << ", \"labels\": \"" << m.labels << "\", \"convergence_radius_m\": " << num(o.convergence_radius_m)
    << ", \"stand_still_s\": " << num(o.stand_still_s) << ", \"stand_still_at_s\": " << num(o.stand_still_at_s)
    << ", \"yaw_drift_at_rest_rad_per_s\": " << num(o.yaw_drift_at_rest_set ? o.yaw_drift_at_rest : 0.0) << "}\n}\n";
  return static_cast<bool>(j);
}

// report.md: the runner wrote its own; the evaluation's replaces it. False when it could not be written.
bool write_localization_report(const fs::path& out, const EvalLocalizationOptions& o, const RunOptions& r, const LocalizationMetrics& m,
                               bool scored_any) {
  const double radius = o.convergence_radius_m;
  std::ofstream md(out / "report.md");
  md << "# Localization evaluation\n\n" << r.oracles_line() << "\n\nWorld `" << o.world << "`, seed " << o.seed << ", map `" << map_name(o.map) << "`, labels `" << m.labels
     << "`, initial guess off by " << o.init_error_m << " m and " << o.init_yaw_error_deg << " deg. Route " << num(m.route_length_m)
     << " m over the roads (driven " << num(m.distance_m) << " m); " << num(m.sim_s) << " s simulated in " << num(m.wall_s) << " s.\n\n";
  if (!m.localization_published)
    md << "**The robot never published on its `localization` channel** (no localization stage in its role table): not converged.\n\n";
  md << "| metric | value | goal |\n|---|---|---|\n"
     << "| converged | " << (m.converged ? "yes" : "no") << " | yes |\n"
     << "| convergence_time_s (driving) | " << (m.converged ? num(m.convergence_time_s) : "-") << " | <= 60 |\n"
     << "| loc_error_mean_m | " << (scored_any ? num(m.loc_error_mean_m) : "-") << " | <= 1.5 |\n"
     << "| loc_error_p95_m | " << (scored_any ? num(m.loc_error_p95_m) : "-") << " | <= 3.0 |\n"
     << "| loc_error_max_m | " << (scored_any ? num(m.loc_error_max_m) : "-") << " | |\n"
     << "| tracking only: mean / p95 / max [m] | " << (m.loc.tracking_mean_m >= 0 ? num(m.loc.tracking_mean_m) + " / " + num(m.loc.tracking_p95_m) + " / " + num(m.loc.tracking_max_m) : "-") << " | |\n"
     << "| within_3m_fraction (within " << num(radius) << " m) | " << num(m.within_fraction) << " | |\n"
     << "| error mean from convergence on (old figure) | " << (m.converged ? num(m.converged_error_mean_m) : "-") << " | |\n"
     << "| yaw_error_mean_deg | " << (scored_any && m.yaw_error_mean_deg >= 0 ? num(m.yaw_error_mean_deg) : "-") << " | <= 2 |\n"
     << "| odom_only_error_mean_m | " << num(m.odom_only_error_mean_m) << " | (reference) |\n"
     << "| divergences after the first good sample | " << m.divergences << " | 0 |\n"
     << "| tracking_fraction | " << num(m.tracking_fraction) << " | |\n"
     << "| good_fraction (of all samples while driving) | " << num(m.good_fraction) << " | |\n\n"
     << "![trajectory](trajectory.png)\n\n![error](error.png)\n\n"
     << "Definitions. Samples at 10 Hz after the robot began to drive";
  if (o.map == UgvMapSource::kOnline) md << " (it waited at its start until the quadrotor's map knew " << o.wait_map_fraction * 100 << " % of the cells within " << o.wait_map_radius_m << " m; released at " << num(m.released_s) << " s)";
  md << ". A sample is *good* when the `localization` channel was published, its status is tracking, its stamp is at most "
     << o.stale_after_s << " s old and its position is within " << num(radius) << " m of the true pose at that stamp. "
     << "*Converged*: some sample is good and every later one is too; convergence_time_s is the driving time to the first of them. "
     << "The errors are over every sample from the first good one on, good or not (an excursion counts; it does not restart "
     << "them): position error mean, 95th percentile (nearest rank) and max, mean absolute yaw error; the tracking-only figures "
     << "over the tracking, fresh samples among them; tracking_fraction and within_3m_fraction are shares of the same samples. "
     << "odom_only_error_mean_m: the wheel odometry put into the map frame with the true start pose, over "
     << "the same samples (all samples after the start when none is good). Per-sample values: `samples.csv`.\n";
  return static_cast<bool>(md);
}

}  // namespace

double polyline_length(const std::vector<Eigen::Vector2d>& path) noexcept {
  double L = 0;
  for (std::size_t i = 1; i < path.size(); ++i) L += (path[i] - path[i - 1]).norm();
  return L;
}

Result<std::vector<Eigen::Vector2d>> plan_road_loop(const World& w, double length_m, std::uint64_t seed, double clearance_m) {
  if (!(length_m > 0)) return Error::make(ErrorCode::kInvalidArgument, "the route length must be positive");
  const RoadRouter router(w, 1.0, clearance_m);
  if (router.drivable_cells() == 0) return Error::make(ErrorCode::kInvalidArgument, "the world has no drivable road or dirt cells");
  const Pose2& staging = w.header.staging;
  Eigen::Vector2d start;
  if (!router.nearest_drivable(staging.x, staging.y, 40.0, start)) start = router.pick_drivable(derive_seed(seed, 0x726f757465));
  const double world_m = std::min(w.grid().size_x(), w.grid().size_y());
  std::vector<Eigen::Vector2d> route{start};
  std::vector<Eigen::Vector2d> waypoints{start};
  Eigen::Vector2d cur = start;
  double total = 0;
  std::vector<Eigen::Vector2d> path;
  for (std::uint64_t leg = 0; leg < 64; ++leg) {
    const double remaining = length_m - total;
    if (leg > 0 && total + 1.2 * (cur - start).norm() >= length_m) break;
    // A leg of about remaining / 2.5 (room to come back), to a point far from those already visited.
    const double want = std::clamp(remaining / 2.5, 15.0, 0.7 * world_m);
    bool found = false;
    Eigen::Vector2d best;
    double best_score = -1e18;
    for (std::uint64_t k = 0; k < 48; ++k) {
      const Eigen::Vector2d c = router.pick_drivable(derive_seed(seed, leg * 1000 + k + 1));
      const double d = (c - cur).norm();
      if (d < 10.0) continue;
      double sep = 1e18;
      for (const auto& p : waypoints) sep = std::min(sep, (c - p).norm());
      const double score = -std::abs(d - want) + 0.5 * std::min(sep, want);
      if (score > best_score) {
        best_score = score;
        best = c;
        found = true;
      }
    }
    if (!found) break;
    path.clear();
    if (!router.route(cur.x(), cur.y(), best.x(), best.y(), path) || path.size() < 2) continue;  // unreachable: another draw
    total += polyline_length(path);
    route.insert(route.end(), path.begin() + 1, path.end());
    waypoints.push_back(best);
    cur = best;
  }
  if (route.size() < 2) return Error::make(ErrorCode::kInvalidArgument, "no road route found from the staging pad");
  path.clear();
  if (router.route(cur.x(), cur.y(), start.x(), start.y(), path) && path.size() >= 2) route.insert(route.end(), path.begin() + 1, path.end());
  return route;
}

Result<LocalizationMetrics> eval_localization(const EvalLocalizationOptions& o, const LocalizationProgressFn& progress) {
  if (!(o.route_km > 0)) return Error::make(ErrorCode::kInvalidArgument, "--route-km must be positive");
  if (!(o.speed_mps > 0)) return Error::make(ErrorCode::kInvalidArgument, "--speed must be positive");
  if (!(o.convergence_radius_m > 0)) return Error::make(ErrorCode::kInvalidArgument, "the convergence radius must be positive");
  auto world = resolve_world(o.world);
  if (!world) return world.error();
  const World& w = *world.value();
  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + o.out_dir + ": " + ec.message());
  auto models = model_dir(o);
  if (!models) return models.error();

  const DiffDriveConfig dd{};
  auto route = plan_road_loop(w, o.route_km * 1000.0, o.seed, dd.footprint_radius_m + 0.2);
  if (!route) return route.error();
  LocalizationMetrics m;
  m.route_length_m = polyline_length(route.value());
  auto run_options = drive_run_options(o, models.value(), route.value(), m);
  if (!run_options) return run_options.error();
  RunOptions& r = run_options.value();

  std::vector<Sample> samples;
  samples.reserve(static_cast<std::size_t>(r.duration_s * 10.0) + 16);
  Sample last;
  Pose2 guess;
  r.sample = [&](const UgvSample& u) {
    const Sample s = to_sample(u, o.stale_after_s, o.convergence_radius_m);
    if (samples.empty()) guess = u.initial_guess;
    samples.push_back(s);
    last = s;
  };
  auto watch = [&](double sim_s, double total_s, double rtf) {
    if (!progress) return;
    LocalizationProgress p;
    p.sim_s = sim_s;
    p.total_s = total_s;
    p.rtf = rtf;
    p.distance_m = last.distance_m;
    p.route_m = m.route_length_m;
    p.released = last.released;
    p.status = last.received ? status_name(last.status) : "no output";
    p.error_m = last.received ? last.err_m : -1;
    progress(p);
  };
  auto run = run_team(r, watch);
  if (!run) return run.error();
  const RunSummary& sum = run.value();
  m.sim_s = sum.sim_s;
  m.wall_s = sum.wall_s;
  if (!sum.ugvs.empty()) {
    m.distance_m = sum.ugvs.front().distance_m;
    m.tiles_published = sum.ugvs.front().tiles_published;
    m.scans_published = sum.ugvs.front().scans_published;
    m.released_s = sum.ugvs.front().released_s;
  }
  const DriveScore score = score_drive(samples, o, m);

  // Files.
  const fs::path out(o.out_dir);
  if (auto st = write_samples_csv(out, samples); !st) return st.error();
  const bool img_ok = cv::imwrite((out / "trajectory.png").string(), trajectory_image(w, samples, route.value(), samples.empty() ? nullptr : &guess)) &&
                      cv::imwrite((out / "error.png").string(), error_image(samples, o.convergence_radius_m, score.converged_t, m.released_s));
  if (!img_ok) return Error::make(ErrorCode::kIo, "cannot write the plots in " + o.out_dir);
  const bool metrics_ok = write_localization_metrics(out, o, r, m, score.scored_any);
  const bool report_ok = write_localization_report(out, o, r, m, score.scored_any);
  if (!metrics_ok || !report_ok) return Error::make(ErrorCode::kIo, "cannot write metrics.json / report.md in " + o.out_dir);
  return m;
}

}  // namespace ag::sim
