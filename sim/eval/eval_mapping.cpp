// The mapping evaluation: a survey flight through the lockstep runner, the map scored against the world.
#include "airground/sim/eval_mapping.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/messages/classes.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/map_export.hpp"
#include "airground/sim/model_params.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace ag::sim {

namespace {

namespace fs = std::filesystem;

bool ground_class(std::uint8_t c) noexcept {
  return c == raw(ClassId::kRoad) || c == raw(ClassId::kDirt) || c == raw(ClassId::kGrass) || c == raw(ClassId::kWater);
}

double quantile(std::vector<float>& v, double q) {
  if (v.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return static_cast<double>(v[k]);
}

// Signed elevation error per map cell (map - world surface range), north up: blue below, red above,
// saturated at +-3 m; grey where the map has no elevation.
cv::Mat error_image(const std::vector<float>& err, std::int32_t w, std::int32_t h) {
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(128, 128, 128));
  for (std::int32_t r = 0; r < h; ++r)
    for (std::int32_t c = 0; c < w; ++c) {
      const float e = err[static_cast<std::size_t>(r) * static_cast<std::size_t>(w) + static_cast<std::size_t>(c)];
      if (!std::isfinite(e)) continue;
      const double t = std::clamp(static_cast<double>(e) / 3.0, -1.0, 1.0);
      const auto hi = static_cast<std::uint8_t>(255), lo = static_cast<std::uint8_t>(255.0 * (1.0 - std::fabs(t)));
      img.at<cv::Vec3b>(r, c) = t >= 0 ? cv::Vec3b(lo, lo, hi) : cv::Vec3b(hi, lo, lo);
    }
  return img;
}

double resident_mb() {
  std::ifstream f("/proc/self/statm");
  long pages = 0, rss = 0;
  f >> pages >> rss;
  return static_cast<double>(rss) * 4096.0 / (1024.0 * 1024.0);
}

Pose3 truth_at(const std::vector<TruthSample>& truth, TimeNs t) {
  const auto it = std::lower_bound(truth.begin(), truth.end(), t, [](const TruthSample& s, TimeNs v) { return s.t < v; });
  if (it == truth.end()) return truth.back().pose;
  if (it == truth.begin() || it->t == t) return it->pose;
  const TruthSample& b = *it;
  const TruthSample& a = *(it - 1);
  const double w = static_cast<double>(t - a.t) / static_cast<double>(b.t - a.t);
  Pose3 p = a.pose;
  p.x += w * (b.pose.x - a.pose.x);
  p.y += w * (b.pose.y - a.pose.y);
  p.z += w * (b.pose.z - a.pose.z);
  return p;
}

// Writes model overrides (the caller's, plus the evaluation's fault injection) into out/models.
Result<std::string> model_dir(const EvalMappingOptions& o) {
  const fs::path dir = fs::path(o.out_dir) / "models";
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + dir.string() + ": " + ec.message());
  if (!o.config_dir.empty()) {
    for (const auto& e : fs::directory_iterator(o.config_dir, ec))
      if (e.path().extension() == ".yaml") fs::copy_file(e.path(), dir / e.path().filename(), fs::copy_options::overwrite_existing, ec);
  }
  // Merges `keys` into the model file `file` (section `section`): the caller's file may hold the keys at
  // its top level or under the section (as `airground-sim config --out` writes it); ours win.
  auto merge = [&](const char* file, const char* section, const std::vector<std::pair<std::string, std::string>>& keys) -> Status {
    const fs::path p = dir / file;
    YAML::Node model(YAML::NodeType::Map);
    if (fs::exists(p)) {
      try {
        const YAML::Node root = model_mapping(YAML::LoadFile(p.string()), section);
        if (root.IsMap()) model = root;
        else if (!root.IsNull()) return Error::make(ErrorCode::kConfig, "config error: " + p.string() + ": '" + section + "' must be a mapping of key: value");
      } catch (const YAML::Exception& e) {
        return Error::make(ErrorCode::kConfig, "config error: " + p.string() + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
      }
    }
    for (const auto& [k, v] : keys) model[k] = v;
    YAML::Node out;
    out[section] = model;
    std::ofstream f(p);
    f << out << "\n";
    if (!f) return Error::make(ErrorCode::kIo, "cannot write " + p.string());
    return ok_status();
  };
  std::vector<std::pair<std::string, std::string>> vo, gps;
  if (o.vo_scale > 0) {
    vo.emplace_back("scale_min", std::to_string(o.vo_scale));
    vo.emplace_back("scale_max", std::to_string(o.vo_scale));
  }
  if (o.tracking_loss_at_s >= 0) vo.emplace_back("forced_loss_at_s", std::to_string(o.tracking_loss_at_s));
  if (!o.random_faults) {
    vo.emplace_back("tracking_loss_rate_per_s", "0");
    gps.emplace_back("dropout_rate_per_s", "0");
  }
  if (o.gps_outlier_at_s >= 0) {
    gps.emplace_back("outlier_at_s", std::to_string(o.gps_outlier_at_s));
    gps.emplace_back("outlier_m", std::to_string(o.gps_outlier_m));
  }
  if (!vo.empty())
    if (auto st = merge("visual_odometry.yaml", "visual_odometry", vo); !st) return st.error();
  if (!gps.empty())
    if (auto st = merge("gps.yaml", "gps", gps); !st) return st.error();
  return dir.string();
}

// The survey flight: the quadrotor alone, until its survey is done.
RunOptions survey_run_options(const EvalMappingOptions& o, const std::string& models) {
  RunOptions r;
  r.world = o.world;
  r.out_dir = o.out_dir;
  r.ugvs = 0;
  r.uav = true;
  r.seed = o.seed;
  r.duration_s = o.max_duration_s;
  r.uav_altitude_m = o.altitude_m;
  r.uav_speed_mps = o.speed_mps;
  r.survey_overlap = o.overlap;
  r.config_dir = models;
  r.record = o.record ? RecordLevel::kMcap : RecordLevel::kNone;  // recording.mcap, no CSV streams
  r.keep_uav_truth = true;
  r.stop_when_survey_done = true;
  r.progress = !o.quiet;
  r.uav_config = o.set;
  r.oracles = o.oracles;
  r.compute_time = o.compute_time;
  r.target_cpu = o.target_cpu;
  return r;
}

// What the evaluation keeps of the run's end besides the figures: the map and its elevation errors.
struct SurveyMap {
  mapping::MapRaster raster;
  std::vector<float> error_map;  // signed elevation error per map cell (error_image)
  std::int32_t error_w{0}, error_h{0};
  Datum datum;
};

struct MappingStages {
  const mapping::PoseGraphStage* pg{nullptr};
  const mapping::OrthoMapStage* om{nullptr};
};

// The quadrotor's mapping stages; their step times and overruns go into m.
MappingStages mapping_stages(RoleInstance& uav, MappingMetrics& m) {
  MappingStages st;
  for (auto& slot : uav.stages()) {
    if (auto* p = dynamic_cast<const mapping::PoseGraphStage*>(slot.stage.get())) st.pg = p;
    if (auto* q = dynamic_cast<const mapping::OrthoMapStage*>(slot.stage.get())) st.om = q;
    const StagePerfSnapshot s = snapshot(*slot.perf);
    if (slot.spec->name == "pose_graph") m.pose_graph_p99_ms = to_seconds(s.exec_p99) * 1e3;
    if (slot.spec->name == "ortho_map") m.ortho_map_p99_ms = to_seconds(s.exec_p99) * 1e3;
    m.stage_overruns += s.overruns;
  }
  return st;
}

// |scale - 1| of the graph's last segment.
double scale_error(const RunInspection& in, const mapping::PoseGraphStage& pg) {
  const mapping::PoseGraph& graph = pg.graph();
  const mapping::NodeId last = graph.last();
  if (last == mapping::kNoNode || !graph.segment_initialised(graph.segment_of(last))) return 1.0;
  if (in.vo_scale > 0) return std::fabs(graph.scale(graph.segment_of(last)) * in.vo_scale - 1.0);  // the oracle VO's true scale is known
  // the robot's own VO: keyframe spacing as the graph has it against the truth's
  double est_d = 0, true_d = 0;
  for (std::uint32_t k = 1; k < pg.keyframes(); ++k) {
    est_d += (pg.keyframe_pose(k).translation() - pg.keyframe_pose(k - 1).translation()).norm();
    const Pose3 a = truth_at(*in.uav_truth, pg.keyframe_stamp(k - 1)), b = truth_at(*in.uav_truth, pg.keyframe_stamp(k));
    true_d += std::sqrt((b.x - a.x) * (b.x - a.x) + (b.y - a.y) * (b.y - a.y) + (b.z - a.z) * (b.z - a.z));
  }
  return true_d > 0 ? std::fabs(est_d / true_d - 1.0) : 1.0;
}

// The keyframes' poses against the truth: the RMSEs into m, every pose into keyframes.csv.
void score_keyframes(const RunInspection& in, const mapping::PoseGraphStage& pg, const std::string& out_dir, MappingMetrics& m) {
  double se = 0, ze = 0, tilt_e = 0, yaw_e = 0;
  std::uint64_t n = 0;
  // Every keyframe's pose as the graph has it and the truth, for a person to plot (roll, pitch, yaw: ZYX).
  std::ofstream kf_csv(fs::path(out_dir) / "keyframes.csv");
  kf_csv << "keyframe,t_s,x,y,z,roll_deg,pitch_deg,yaw_deg,true_x,true_y,true_z,true_roll_deg,true_pitch_deg,true_yaw_deg\n";
  const auto write_rpy_deg = [&kf_csv](const Eigen::Matrix3d& R) {
    const double d = 180.0 / M_PI;
    kf_csv << ',' << std::atan2(R(2, 1), R(2, 2)) * d << ',' << -std::asin(std::clamp(R(2, 0), -1.0, 1.0)) * d << ','
           << std::atan2(R(1, 0), R(0, 0)) * d;
  };
  for (std::uint32_t k = 0; k < pg.keyframes(); ++k) {
    const Eigen::Isometry3d est = pg.keyframe_pose(k);
    const Pose3 truth = truth_at(*in.uav_truth, pg.keyframe_stamp(k));
    kf_csv << k << ',' << to_seconds(pg.keyframe_stamp(k)) << ',' << est.translation().x() << ',' << est.translation().y() << ','
           << est.translation().z();
    write_rpy_deg(est.linear());
    kf_csv << ',' << truth.x << ',' << truth.y << ',' << truth.z;
    write_rpy_deg(to_isometry(truth).linear());
    kf_csv << '\n';
    se += std::pow(est.translation().x() - truth.x, 2) + std::pow(est.translation().y() - truth.y, 2);
    ze += std::pow(est.translation().z() - truth.z, 2);
    const Eigen::Matrix3d rt = to_isometry(truth).linear();
    const double tilt = std::acos(std::clamp(est.linear().col(2).dot(rt.col(2)), -1.0, 1.0));
    const Eigen::Vector3d fe = est.linear().col(0), ft = rt.col(0);
    const double yaw = std::remainder(std::atan2(fe.y(), fe.x()) - std::atan2(ft.y(), ft.x()), 2 * M_PI);
    tilt_e += tilt * tilt;
    yaw_e += yaw * yaw;
    ++n;
  }
  m.georeg_error_m = n ? std::sqrt(se / static_cast<double>(n)) : 1e9;
  m.pose_z_rmse_m = n ? std::sqrt(ze / static_cast<double>(n)) : 1e9;
  m.pose_tilt_rmse_deg = n ? std::sqrt(tilt_e / static_cast<double>(n)) * 180.0 / M_PI : 1e9;
  m.pose_yaw_rmse_deg = n ? std::sqrt(yaw_e / static_cast<double>(n)) * 180.0 / M_PI : 1e9;
}

// Score over the surveyed area at the map's resolution: classes and elevation against the world cells
// inside each map cell.
void score_map(const RunInspection& in, const mapping::OrthoMap& map, MappingMetrics& m, SurveyMap& s) {
  const World& w = in.world;
  m.tiles = map.tile_count();
  m.tiles_rebuilt = map.stats().tiles_rebuilt;
  const double res = map.params().resolution_m;
  GridGeometry g;
  g.resolution = res;
  g.origin_x = std::ceil(in.survey_x0 / res) * res;
  g.origin_y = std::floor(in.survey_y1 / res) * res;
  g.width = static_cast<std::int32_t>(std::floor((in.survey_x1 - g.origin_x) / res));
  g.height = static_cast<std::int32_t>(std::floor((g.origin_y - in.survey_y0) / res));
  s.raster = map.raster(g);
  const GridGeometry& wg = w.grid();
  const int sub = std::max(1, static_cast<int>(std::lround(res / wg.resolution)));
  std::uint64_t classified = 0, correct = 0, total = 0, ground_n = 0, all_n = 0;
  double ground_se = 0, all_se = 0, ground_sum = 0;
  std::vector<float> ground_abs, all_abs;
  std::uint64_t outliers = 0;
  s.error_map.assign(static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height), std::numeric_limits<float>::quiet_NaN());
  s.error_w = g.width;
  s.error_h = g.height;
  for (std::int32_t row = 0; row < g.height; ++row)
    for (std::int32_t col = 0; col < g.width; ++col) {
      const auto i = static_cast<std::size_t>(row) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(col);
      // The world cells inside this map cell.
      const double x0 = g.origin_x + col * res, y0 = g.origin_y - row * res;
      const std::int32_t wc0 = wg.col(x0 + 0.25 * wg.resolution), wr0 = wg.row(y0 - 0.25 * wg.resolution);
      bool any_class[256] = {};
      bool all_ground = true;
      double smin = 1e9, smax = -1e9, ssum = 0;
      int cnt = 0;
      for (int dr = 0; dr < sub; ++dr)
        for (int dc = 0; dc < sub; ++dc) {
          const std::int32_t wc = wc0 + dc, wr = wr0 + dr;
          if (!wg.contains(wc, wr)) continue;
          const std::uint8_t c = w.class_id.at<std::uint8_t>(wr, wc);
          any_class[c] = true;
          const double sv = static_cast<double>(w.surface_at(wc, wr));
          all_ground = all_ground && ground_class(c) && w.height.at<float>(wr, wc) < 0.3F;
          smin = std::min(smin, sv);
          smax = std::max(smax, sv);
          ssum += sv;
          ++cnt;
        }
      if (cnt == 0) continue;
      ++total;
      const std::uint8_t mc = s.raster.cls[i];
      if (mc != 255) {
        ++classified;
        if (any_class[mc]) ++correct;
      }
      const float e = s.raster.elevation[i];
      if (!std::isfinite(e)) continue;
      const double ev = static_cast<double>(e);
      const double err = ev < smin ? smin - ev : (ev > smax ? ev - smax : 0.0);
      all_se += err * err;
      ++all_n;
      all_abs.push_back(static_cast<float>(err));
      if (err > 2.0) ++outliers;
      s.error_map[i] = static_cast<float>(ev < smin ? ev - smin : (ev > smax ? ev - smax : 0.0));
      if (all_ground) {
        const double d = ev - ssum / cnt;
        ground_se += d * d;
        ground_sum += d;
        ground_abs.push_back(static_cast<float>(std::fabs(d)));
        ++ground_n;
      }
    }
  m.cells_evaluated = total;
  m.map_coverage = total ? static_cast<double>(classified) / static_cast<double>(total) : 0.0;
  m.elevation_coverage = total ? static_cast<double>(all_n) / static_cast<double>(total) : 0.0;
  m.map_class_accuracy = classified ? static_cast<double>(correct) / static_cast<double>(classified) : 0.0;
  m.elevation_rmse_ground_m = ground_n ? std::sqrt(ground_se / static_cast<double>(ground_n)) : 1e9;
  m.elevation_rmse_m = all_n ? std::sqrt(all_se / static_cast<double>(all_n)) : 1e9;
  m.elevation_bias_ground_m = ground_n ? ground_sum / static_cast<double>(ground_n) : 0.0;
  m.elevation_p50_ground_m = quantile(ground_abs, 0.5);
  m.elevation_p95_ground_m = quantile(ground_abs, 0.95);
  m.elevation_p95_m = quantile(all_abs, 0.95);
  m.elevation_outliers = all_n ? static_cast<double>(outliers) / static_cast<double>(all_n) : 0.0;
}

// The run's end: the stages' costs, memory, the pose graph against the truth and the map against the world.
Status inspect_survey(const RunInspection& in, const std::string& out_dir, double start_rss, MappingMetrics& m, SurveyMap& s) {
  if (in.uav == nullptr) return Error::make(ErrorCode::kInternal, "no quadrotor in the run");
  const MappingStages st = mapping_stages(*in.uav, m);
  if (st.pg == nullptr || st.om == nullptr) return Error::make(ErrorCode::kInternal, "the uav role has no mapping stages");
  s.datum = in.world.header.datum;
  m.resident_mb = resident_mb();
  m.resident_growth_mb = start_rss > 0 ? m.resident_mb - start_rss : 0.0;
  m.map_memory_mb = static_cast<double>(st.om->map().memory_bytes()) / (1024.0 * 1024.0);
  m.keyframes = st.pg->keyframes();
  m.gps_rejected = st.pg->graph().stats().gps_rejected_gate;
  m.vo_segments = in.vo_segments;
  m.scale_error = scale_error(in, *st.pg);
  score_keyframes(in, *st.pg, out_dir, m);
  score_map(in, st.om->map(), m, s);
  return ok_status();
}

// metrics.json and the evaluation's part of report.md (after the runner's); false when either could not be written.
bool write_mapping_files(const EvalMappingOptions& o, const MappingMetrics& m) {
  std::ofstream j(fs::path(o.out_dir) / "metrics.json");
  RunOptions oracle_list;
  oracle_list.oracles = o.oracles;
  j << "{\n  \"oracles\": " << oracle_list.oracles_json() << ",\n  \"map_class_accuracy\": " << m.map_class_accuracy << ",\n  \"map_coverage\": " << m.map_coverage
    << ",\n  \"elevation_rmse_ground_m\": " << m.elevation_rmse_ground_m << ",\n  \"elevation_rmse_m\": " << m.elevation_rmse_m << ",\n  \"elevation_coverage\": " << m.elevation_coverage
    << ",\n  \"elevation_bias_ground_m\": " << m.elevation_bias_ground_m << ",\n  \"elevation_p50_ground_m\": " << m.elevation_p50_ground_m
    << ",\n  \"elevation_p95_ground_m\": " << m.elevation_p95_ground_m << ",\n  \"elevation_p95_m\": " << m.elevation_p95_m
    << ",\n  \"elevation_outliers\": " << m.elevation_outliers
    << ",\n  \"georeg_error_m\": " << m.georeg_error_m << ",\n  \"scale_error\": " << m.scale_error << ",\n  \"pose_z_rmse_m\": " << m.pose_z_rmse_m
    << ",\n  \"pose_tilt_rmse_deg\": " << m.pose_tilt_rmse_deg << ",\n  \"pose_yaw_rmse_deg\": " << m.pose_yaw_rmse_deg
    << ",\n  \"keyframes\": " << m.keyframes << ",\n  \"cells_evaluated\": " << m.cells_evaluated << ",\n  \"tiles\": " << m.tiles
    << ",\n  \"tiles_rebuilt\": " << m.tiles_rebuilt << ",\n  \"gps_rejected\": " << m.gps_rejected
    << ",\n  \"vo_segments\": " << m.vo_segments << ",\n  \"stage_overruns\": " << m.stage_overruns
    << ",\n  \"pose_graph_p99_ms\": " << m.pose_graph_p99_ms << ",\n  \"ortho_map_p99_ms\": " << m.ortho_map_p99_ms
    << ",\n  \"resident_mb\": " << m.resident_mb << ",\n  \"resident_growth_mb\": " << m.resident_growth_mb
    << ",\n  \"map_memory_mb\": " << m.map_memory_mb << ",\n  \"sim_s\": " << m.sim_s << ",\n  \"wall_s\": " << m.wall_s << "\n}\n";
  std::ofstream md(fs::path(o.out_dir) / "report.md", std::ios::app);
  md << "\n## Mapping evaluation\n\n" << oracle_list.oracles_line() << "\n\n| metric | value | goal |\n|---|---|---|\n"
     << "| map_class_accuracy | " << m.map_class_accuracy << " | >= 0.95 |\n| map_coverage | " << m.map_coverage << " | >= 0.90 |\n"
     << "| elevation_rmse_ground_m | " << m.elevation_rmse_ground_m << " | <= 0.5 |\n| elevation_rmse_m | " << m.elevation_rmse_m << " | <= 1.5 |\n"
     << "| georeg_error_m | " << m.georeg_error_m << " | <= 0.5 |\n| scale_error | " << m.scale_error << " | <= 0.01 |\n"
     << "| keyframes | " << m.keyframes << " | |\n"
     << "| pose_graph / ortho_map step p99 ("
     << (o.compute_time == ComputeTimeMode::kModel ? "compute-time model, target CPU" : o.compute_time == ComputeTimeMode::kMeasured ? "thread CPU, scaled to the target" : "thread CPU here")
     << ") | " << m.pose_graph_p99_ms << " / " << m.ortho_map_p99_ms << " ms | <= 150 ms |\n"
     << "| UAV stages' memory growth (resident) / map | " << m.resident_growth_mb << " / " << m.map_memory_mb << " MB | <= 600 MB |\n\n![class](map_class.png) ![rgb](map_rgb.png) ![elevation](map_elevation.png) ![elevation error](map_elevation_error.png)\n\n"
     << "GeoTIFFs (UTM of the datum): map_class.tif, map_elevation.tif, map_rgb.tif.\n";
  return j && md;
}

}  // namespace

Result<MappingMetrics> eval_mapping(const EvalMappingOptions& o, const ProgressFn& progress) {
  const bool oracle_vo = std::find(o.oracles.begin(), o.oracles.end(), "vo") != o.oracles.end();
  if (!oracle_vo && (o.vo_scale > 0 || o.tracking_loss_at_s >= 0))
    return Error::make(ErrorCode::kInvalidArgument,
                       "eval mapping: vo_scale and tracking_loss_at_s shape the simulator's VO model; they need the oracle \"vo\"");
  auto models = model_dir(o);
  if (!models) return models.error();
  RunOptions r = survey_run_options(o, models.value());

  MappingMetrics m;
  SurveyMap survey;
  // The resident set once the run is set up (world, sensors, stages initialised): the baseline the
  // mapping state grows from.
  double start_rss = -1;
  r.inspect = [&](const RunInspection& in) -> Status { return inspect_survey(in, o.out_dir, start_rss, m, survey); };
  auto watch = [&](double sim_s, double total_s, double rtf) {
    if (start_rss < 0) start_rss = resident_mb();
    if (progress) progress(sim_s, total_s, rtf);
  };
  auto run = run_team(r, watch);
  if (!run) return run.error();
  m.sim_s = run.value().sim_s;
  m.wall_s = run.value().wall_s;

  if (auto st = write_map_exports(o.out_dir, survey.raster, survey.datum); !st) return st.error();
  if (survey.error_w > 0 &&
      !cv::imwrite((fs::path(o.out_dir) / "map_elevation_error.png").string(), error_image(survey.error_map, survey.error_w, survey.error_h)))
    return Error::make(ErrorCode::kIo, "cannot write map_elevation_error.png in " + o.out_dir);
  if (!write_mapping_files(o, m)) return Error::make(ErrorCode::kIo, "cannot write metrics.json / report.md in " + o.out_dir);
  return m;
}

}  // namespace ag::sim
