// The planning evaluation: roadmap routes vs the 8-connected grid optimum on the true class map, then
// driven on the simulated robot.
#include "airground/sim/eval_planning.hpp"

#include <algorithm>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <span>

#include "airground/messages/messages.hpp"
#include "airground/planning/drive_control.hpp"
#include "airground/planning/grid_reference.hpp"
#include "airground/planning/roadmap.hpp"
#include "airground/planning/stages.hpp"
#include "airground/platform/config.hpp"
#include "airground/sim/diff_drive.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"
#include "airground/sim/runner.hpp"

namespace ag::sim {

namespace {
namespace fs = std::filesystem;

// Thread CPU time [ms]: the figures hold on a busy machine.
double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

// The world's class raster at the map's 0.5 m cells: the majority class of the world cells whose
// centres fall in a map cell (the cell under its centre when none do). Row 0 south; tile-aligned.
struct MapRaster {
  std::int32_t tx0{0}, ty0{0}, tiles_x{0}, tiles_y{0};
  std::int32_t w{0}, h{0};
  double ox{0}, oy{0};
  std::vector<std::uint8_t> cls;
};

MapRaster resample(const World& world) {
  const GridGeometry& g = world.grid();
  const double res = kMapResolutionM, tile = res * kTileCells;
  MapRaster m;
  const double x0 = g.origin_x, x1 = g.origin_x + g.size_x(), y1 = g.origin_y, y0 = g.origin_y - g.size_y();
  m.tx0 = static_cast<std::int32_t>(std::floor(x0 / tile));
  m.ty0 = static_cast<std::int32_t>(std::floor(y0 / tile));
  m.tiles_x = static_cast<std::int32_t>(std::ceil(x1 / tile)) - m.tx0;
  m.tiles_y = static_cast<std::int32_t>(std::ceil(y1 / tile)) - m.ty0;
  m.w = m.tiles_x * kTileCells;
  m.h = m.tiles_y * kTileCells;
  m.ox = m.tx0 * tile;
  m.oy = m.ty0 * tile;
  m.cls.assign(static_cast<std::size_t>(m.w) * static_cast<std::size_t>(m.h), 255);
  for (std::int32_t r = 0; r < m.h; ++r)
    for (std::int32_t c = 0; c < m.w; ++c) {
      const double x = m.ox + (c + 0.5) * res, y = m.oy + (r + 0.5) * res;
      m.cls[static_cast<std::size_t>(r) * static_cast<std::size_t>(m.w) + static_cast<std::size_t>(c)] = summarise_cell(world, x, y, res).cls;
    }
  return m;
}

std::string json_escape(const std::string& s) {
  std::string o;
  for (char ch : s) {
    if (ch == '"' || ch == '\\') o += '\\';
    o += ch;
  }
  return o;
}

// The planner's and the drive controller's parameters: the ugv role's sections with the overrides, the
// drive's held to the simulated robot.
struct PlannerParams {
  plan::RoadmapParams rp;
  plan::DriveParams dp;
};

Result<PlannerParams> planner_params(const EvalPlanningOptions& o, const DiffDriveConfig& dd) {
  static constexpr ParamSection kSections[] = {{"planner", plan::PlannerStage::kParams, ""}, {"drive", plan::DriveStage::kParams, ""}};
  Config cfg = Config::defaults(kSections);
  for (const std::string& s : o.set)
    if (Status st = cfg.set(s, "--set"); !st) return st.error();
  PlannerParams p{plan::load_roadmap_params(SectionView(cfg, "planner"), kMapResolutionM, kTileCells), plan::load_drive_params(SectionView(cfg, "drive"))};
  p.dp.track_m = dd.track_width_m;
  p.dp.max_speed_mps = std::min(p.dp.max_speed_mps, o.speed_mps);
  p.dp.max_wheel_speed_mps = std::min(p.dp.max_wheel_speed_mps, dd.max_wheel_speed_rad_s * dd.wheel_radius_m);
  return p;
}

// Every tile of the resampled class map into the roadmap.
void set_tiles(plan::Roadmap& rm, const MapRaster& m) {
  std::vector<std::uint8_t> tile(kTileCellCount);
  for (std::int32_t ty = 0; ty < m.tiles_y; ++ty)
    for (std::int32_t tx = 0; tx < m.tiles_x; ++tx) {
      for (int r = 0; r < kTileCells; ++r)
        for (int c = 0; c < kTileCells; ++c)
          tile[static_cast<std::size_t>(r * kTileCells + c)] =
              m.cls[static_cast<std::size_t>(ty * kTileCells + r) * static_cast<std::size_t>(m.w) + static_cast<std::size_t>(tx * kTileCells + c)];
      (void)rm.set_tile(m.tx0 + tx, m.ty0 + ty, 1, tile);
    }
}

using PointPair = std::pair<plan::Point2, plan::Point2>;

// Random reachable pairs (seeded): cells that keep the clearance, in the same grid component, apart.
Result<std::vector<PointPair>> draw_pairs(const EvalPlanningOptions& o, const World& world, const MapRaster& m, const plan::GridReference& ref,
                                          const DiffDriveConfig& dd) {
  const auto& comp = ref.components();
  Rng rng(o.seed * 0x9E3779B97F4A7C15ULL + 17);
  std::vector<PointPair> pairs;
  for (int guard = 0; static_cast<int>(pairs.size()) < o.pairs && guard < 200000; ++guard) {
    const auto ac = static_cast<std::int32_t>(rng.uniform() * m.w), ar = static_cast<std::int32_t>(rng.uniform() * m.h);
    const auto bc = static_cast<std::int32_t>(rng.uniform() * m.w), br = static_cast<std::int32_t>(rng.uniform() * m.h);
    if (!ref.keeps_clearance(ac, ar) || !ref.keeps_clearance(bc, br)) continue;
    const std::size_t ia = static_cast<std::size_t>(ar) * static_cast<std::size_t>(m.w) + static_cast<std::size_t>(ac);
    const std::size_t ib = static_cast<std::size_t>(br) * static_cast<std::size_t>(m.w) + static_cast<std::size_t>(bc);
    if (comp[ia] != comp[ib]) continue;
    const plan::Point2 a{m.ox + (ac + 0.5) * kMapResolutionM, m.oy + (ar + 0.5) * kMapResolutionM};
    const plan::Point2 b{m.ox + (bc + 0.5) * kMapResolutionM, m.oy + (br + 0.5) * kMapResolutionM};
    if (std::hypot(a.x - b.x, a.y - b.y) < o.min_pair_distance_m) continue;
    // The robot must fit where it starts and ends (the vehicle model's footprint on the 0.25 m world).
    DiffDriveRobot probe(dd, Pose2{a.x, a.y, 0});
    (void)probe.step(1e-9, world);
    if (!probe.footprint_free(world, a.x, a.y, probe.pose3().z) || !probe.footprint_free(world, b.x, b.y, probe.pose3().z)) continue;
    pairs.emplace_back(a, b);
  }
  if (static_cast<int>(pairs.size()) < o.pairs)
    return Error::make(ErrorCode::kInvalidArgument, "world '" + o.world + "' has only " + std::to_string(pairs.size()) + " reachable pairs " +
                                                        std::to_string(static_cast<int>(o.min_pair_distance_m)) + " m apart");
  return pairs;
}

// The sums over the planned pairs the means are made of.
struct PlanSums {
  double ratio{0}, clearance{0}, query_ms{0};
};

// Plans a pair on the roadmap into `path` and checks it on the grid reference.
PlanningPairResult plan_pair(plan::Roadmap& rm, const plan::GridReference& ref, double min_clearance_m, const PointPair& pair,
                             plan::PlannedPath& path, PlanningMetrics& out, PlanSums& sums) {
  const auto [a, b] = pair;
  PlanningPairResult res;
  res.sx = a.x;
  res.sy = a.y;
  res.gx = b.x;
  res.gy = b.y;
  const double t0 = cpu_ms();
  rm.plan(a, b, path);
  res.query_ms = cpu_ms() - t0;
  sums.query_ms += res.query_ms;
  out.query_ms_max = std::max(out.query_ms_max, res.query_ms);
  res.status = plan::to_string(path.status);
  res.grid_length_m = ref.shortest_m(a, b);
  res.planned = path.status == plan::PlanStatus::kOk;
  if (res.planned) {
    const plan::PathCheck pc = ref.check(std::span<const plan::Point2>(path.points.data(), path.count));
    res.length_m = path.length_m;
    res.ratio = res.grid_length_m > 0 ? path.length_m / res.grid_length_m : 0;
    res.min_clearance_m = pc.min_clearance_m;
    res.through_blocked = !pc.traversable;
    res.too_close = !pc.clearance;
    sums.ratio += res.ratio;
    out.path_length_ratio_max = std::max(out.path_length_ratio_max, res.ratio);
    const double cr = pc.min_clearance_m / std::max(min_clearance_m, 1e-6);
    sums.clearance += cr;
    out.min_clearance_ratio_min = std::min(out.min_clearance_ratio_min, cr);
    out.through_blocked += res.through_blocked ? 1 : 0;
    out.too_close += res.too_close ? 1 : 0;
  }
  return res;
}

// Drives the route with the robot's own stages: the lockstep runner, its localizer's pose, the planner
// re-planning from it, the tracker and the drive stage commanding the simulated wheels. `index` numbers
// the drive's folder and seed.
Status drive_with_stages(const EvalPlanningOptions& o, std::size_t index, const PointPair& pair, const plan::PlannedPath& path,
                         const plan::DriveParams& dp, PlanningPairResult& res) {
  const auto [a, b] = pair;
  const plan::Point2 p1 = path.points[1];
  RunOptions r;
  r.world = o.world;
  r.out_dir = (fs::path(o.out_dir) / ("drive_" + std::to_string(index))).string();
  r.ugvs = 1;
  r.uav = false;
  r.seed = o.seed * 1000 + index;
  r.ugv_map = UgvMapSource::kGroundTruth;
  r.drive_by_stages = true;
  r.lidar_columns = 512;
  r.record = o.record ? RecordLevel::kMcap : RecordLevel::kNone;  // the drive's recording.mcap
  r.progress = false;
  RunOptions::UgvStart st;
  st.has_start = true;
  st.start = Pose2{a.x, a.y, std::atan2(p1.y - a.y, p1.x - a.x)};
  st.has_guess = true;
  st.guess = st.start;
  st.guess_sigma_m = 1.0;
  r.ugv_starts = {st};
  r.ugv_goals = {Eigen::Vector2d(b.x, b.y)};
  r.ugv_config = o.set;
  r.oracles = o.oracles;
  r.compute_time = o.compute_time;
  r.target_cpu = o.target_cpu;
  r.duration_s = 60.0 + 3.0 * path.length_m / std::max(0.1, dp.max_speed_mps);
  r.sample_hz = 5;
  double closest = 1e18, err_sum = 0;
  std::uint64_t err_n = 0;
  TimeNs reached_at = -1;
  r.sample = [&](const UgvSample& s) {
    const double d = std::hypot(s.truth.x - b.x, s.truth.y - b.y);
    closest = std::min(closest, d);
    if (d <= 1.0 && reached_at < 0) reached_at = s.now;
    if (s.localization_received && s.localization->status == LocalizationStatus::kTracking) {
      err_sum += std::hypot(s.localization->pose.x - s.truth_at_localization.x, s.localization->pose.y - s.truth_at_localization.y);
      ++err_n;
    }
  };
  r.stop_when = [&](TimeNs, bool) { return reached_at >= 0; };
  auto run = run_team(r);
  if (!run) return run.error();
  // keep the drive's recording (recording.mcap, recording.json), nothing else of its folder
  std::error_code ec;
  std::vector<fs::path> rest;
  for (const auto& e : fs::directory_iterator(r.out_dir, ec))
    if (!o.record || e.path().filename().string().rfind("recording.", 0) != 0) rest.push_back(e.path());
  for (const fs::path& p : rest) fs::remove_all(p, ec);
  if (!o.record) fs::remove_all(r.out_dir, ec);
  res.drive_time_s = reached_at >= 0 ? to_seconds(reached_at) : run.value().sim_s;
  res.final_error_m = closest;
  res.collisions = run.value().ugvs.at(0).collisions;
  res.reached = reached_at >= 0;
  res.loc_error_mean_m = err_n ? err_sum / static_cast<double>(err_n) : -1;
  return ok_status();
}

// Drives the route with the ground-truth pose: the drive controller at 20 Hz, the vehicle model at 100 Hz.
void drive_with_truth(const World& world, const DiffDriveConfig& dd, const plan::DriveParams& dp, const PointPair& pair,
                      const plan::PlannedPath& path, PlanningPairResult& res) {
  const auto [a, b] = pair;
  const plan::Point2 p1 = path.points[1];
  DiffDriveRobot robot(dd, Pose2{a.x, a.y, std::atan2(p1.y - a.y, p1.x - a.x)});
  (void)robot.step(1e-9, world);
  plan::PathFollower f(dp);
  f.set_path(path.points.data(), path.count);
  const double limit_s = 60.0 + 3.0 * path.length_m / std::max(0.1, dp.max_speed_mps);
  double t = 0;
  while (t < limit_s && f.state() != plan::FollowState::kArrived) {
    const plan::TwistCommand tw = f.step(robot.pose(), 0.05);
    const plan::WheelSpeeds ws = plan::wheels_from_twist(tw.v_mps, tw.w_radps, dp.track_m, dp.max_wheel_speed_mps);
    robot.command_wheels(ws.left_mps / dd.wheel_radius_m, ws.right_mps / dd.wheel_radius_m);
    for (int s = 0; s < 5; ++s) (void)robot.step(0.01, world);
    t += 0.05;
  }
  res.drive_time_s = t;
  res.final_error_m = std::hypot(robot.pose().x - b.x, robot.pose().y - b.y);
  res.collisions = robot.collisions();
  res.reached = f.state() == plan::FollowState::kArrived && res.final_error_m <= 1.0;
}

// metrics.json; false when it could not be written.
bool write_planning_metrics(const EvalPlanningOptions& o, double min_clearance_m, const PlanningMetrics& out) {
  std::ofstream js(fs::path(o.out_dir) / "metrics.json");
  char buf[512];
  js << "{\n";
  std::snprintf(buf, sizeof buf,
                "  \"world\": \"%s\",\n  \"seed\": %llu,\n  \"pairs\": %d,\n  \"path_length_ratio_mean\": %.4f,\n  \"path_length_ratio_max\": %.4f,\n"
                "  \"min_clearance_ratio_mean\": %.4f,\n  \"min_clearance_ratio_min\": %.4f,\n  \"reached\": %d,\n  \"collisions\": %llu,\n"
                "  \"failures\": %d,\n  \"through_blocked\": %d,\n  \"too_close\": %d,\n  \"min_clearance_m\": %.3f,\n"
                "  \"build_ms\": %.1f,\n  \"query_ms_mean\": %.3f,\n  \"query_ms_max\": %.3f,\n  \"nodes\": %u,\n  \"edges\": %u,\n"
                "  \"driven\": %s,\n  \"pose\": \"%s\",\n",
                json_escape(o.world).c_str(), static_cast<unsigned long long>(o.seed), out.pairs, out.path_length_ratio_mean, out.path_length_ratio_max,
                out.min_clearance_ratio_mean, out.min_clearance_ratio_min, out.reached, static_cast<unsigned long long>(out.collisions),
                out.failures, out.through_blocked, out.too_close, min_clearance_m, out.build_ms, out.query_ms_mean, out.query_ms_max, out.nodes,
                out.edges, o.drive ? "true" : "false", o.localizer_pose ? "localizer" : "ground truth");
  RunOptions oracle_list;
  oracle_list.oracles = o.oracles;
  js << buf << "  \"oracles\": " << oracle_list.oracles_json() << ",\n  \"pair_results\": [\n";
  for (std::size_t k = 0; k < out.results.size(); ++k) {
    const auto& r = out.results[k];
    std::snprintf(buf, sizeof buf,
                  "    {\"start\": [%.2f, %.2f], \"goal\": [%.2f, %.2f], \"status\": \"%s\", \"length_m\": %.2f, \"grid_length_m\": %.2f, "
                  "\"ratio\": %.4f, \"min_clearance_m\": %.3f, \"through_blocked\": %s, \"too_close\": %s, \"reached\": %s, \"collisions\": %llu, "
                  "\"drive_time_s\": %.1f, \"final_error_m\": %.2f, \"query_ms\": %.3f}%s\n",
                  r.sx, r.sy, r.gx, r.gy, r.status.c_str(), r.length_m, r.grid_length_m, r.ratio, r.min_clearance_m, r.through_blocked ? "true" : "false",
                  r.too_close ? "true" : "false", r.reached ? "true" : "false", static_cast<unsigned long long>(r.collisions), r.drive_time_s,
                  r.final_error_m, r.query_ms, k + 1 < out.results.size() ? "," : "");
    js << buf;
  }
  js << "  ]\n}\n";
  return static_cast<bool>(js);
}

}  // namespace

Result<PlanningMetrics> eval_planning(const EvalPlanningOptions& o, const std::function<void(const PlanningProgress&)>& progress) {
  auto world_r = resolve_world(o.world);
  if (!world_r) return world_r.error();
  const World& world = *world_r.value();
  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (ec) return Error::make(ErrorCode::kIo, "cannot create " + o.out_dir + ": " + ec.message());
  const DiffDriveConfig dd;  // the simulated robot (Jackal class)
  auto params = planner_params(o, dd);
  if (!params) return params.error();
  const plan::RoadmapParams& rp = params.value().rp;
  const plan::DriveParams& dp = params.value().dp;

  if (progress) progress({0, o.pairs, "building the roadmap"});
  const MapRaster m = resample(world);
  plan::Roadmap rm(rp, ClassTable::builtin(), TileExtent{m.tx0, m.ty0, m.tiles_x, m.tiles_y});
  set_tiles(rm, m);
  const double t0 = cpu_ms();
  rm.rebuild();
  PlanningMetrics out;
  out.build_ms = cpu_ms() - t0;
  out.nodes = rm.stats().nodes;
  out.edges = rm.stats().edges;
  out.min_clearance_m = rp.min_clearance_m;
  const plan::GridReference ref(m.cls, m.w, m.h, kMapResolutionM, m.ox, m.oy, ClassTable::builtin(), rp.max_level, rp.min_clearance_m);
  auto drawn = draw_pairs(o, world, m, ref, dd);
  if (!drawn) return drawn.error();
  const std::vector<PointPair>& pairs = drawn.value();

  auto path = std::make_unique<plan::PlannedPath>();
  PlanSums sums;
  out.min_clearance_ratio_min = 1e9;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    if (progress) progress({static_cast<int>(k + 1), o.pairs, "planning and driving"});
    PlanningPairResult res = plan_pair(rm, ref, rp.min_clearance_m, pairs[k], *path, out, sums);
    if (res.planned && o.drive) {
      if (o.localizer_pose) {
        if (auto st = drive_with_stages(o, out.results.size(), pairs[k], *path, dp, res); !st) return st.error();
      } else {
        drive_with_truth(world, dd, dp, pairs[k], *path, res);
      }
      out.collisions += res.collisions;
      out.reached += res.reached ? 1 : 0;
    }
    const bool failed = !res.planned || res.through_blocked || res.too_close || (o.drive && !res.reached);
    out.failures += failed ? 1 : 0;
    out.results.push_back(res);
  }
  const int n = static_cast<int>(pairs.size());
  const int planned = static_cast<int>(std::count_if(out.results.begin(), out.results.end(), [](const auto& r) { return r.planned; }));
  out.pairs = n;
  out.path_length_ratio_mean = planned > 0 ? sums.ratio / planned : 0;
  out.min_clearance_ratio_mean = planned > 0 ? sums.clearance / planned : 0;
  if (planned == 0) out.min_clearance_ratio_min = 0;
  out.query_ms_mean = n > 0 ? sums.query_ms / n : 0;
  if (!write_planning_metrics(o, rp.min_clearance_m, out))
    return Error::make(ErrorCode::kIo, "cannot write " + (fs::path(o.out_dir) / "metrics.json").string());
  return out;
}

}  // namespace ag::sim
