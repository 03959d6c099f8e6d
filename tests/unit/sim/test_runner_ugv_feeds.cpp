// The lockstep runner as the ground robots' drivers: what arrives on a robot's "lidar_scan",
// "wheel_odometry", "initial_pose" and "map_tiles" channels, scripted routes, holds and the sampler.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <set>
#include <vector>

#include <unistd.h>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/runner.hpp"
#include "saved_world.hpp"
#include "airground/sim/scripted_driver.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

// A scan travels by copy into every reader's ring slot, and a copy moves only the valid points.
TEST(LidarScanMsgCopy, CarriesTheHeaderTheValidPointsAndAClaimedCountAsItIs) {
  auto a = std::make_unique<LidarScanMsg>();
  a->stamp = 123;
  a->seq = 7;
  a->rings = 64;
  a->columns = 1024;
  a->labels = LabelSource::kGroundTruth;
  a->sensor_in_body = Pose3{0, 0, 0.5, 0, 0, 0};
  a->count = 3;
  for (std::uint16_t k = 0; k < 4; ++k) a->points[k] = ScanReturn{1.0f * k, 2.0f, 3.0f, 4.0f, 5, k, 9};
  auto b = std::make_unique<LidarScanMsg>(*a);
  EXPECT_EQ(b->stamp, 123);
  EXPECT_EQ(b->seq, 7u);
  EXPECT_EQ(b->columns, 1024);
  EXPECT_EQ(b->labels, LabelSource::kGroundTruth);
  EXPECT_DOUBLE_EQ(b->sensor_in_body.z, 0.5);
  ASSERT_EQ(b->count, 3u);
  for (std::uint16_t k = 0; k < 3; ++k) {
    EXPECT_EQ(b->points[k].x, 1.0f * k);
    EXPECT_EQ(b->points[k].ring, k);
    EXPECT_EQ(b->points[k].cls, 5);
  }
  auto c = std::make_unique<LidarScanMsg>();
  c->points[0].x = -1.0f;
  *c = *a;  // assignment likewise
  EXPECT_EQ(c->count, 3u);
  EXPECT_EQ(c->points[2].x, 2.0f);
  a->count = static_cast<std::uint32_t>(kMaxScanPoints + 5);  // a broken producer's claim
  *c = *a;
  EXPECT_EQ(c->count, kMaxScanPoints + 5) << "the claim travels as it is, for the reader to refuse";
  EXPECT_EQ(c->valid(), kMaxScanPoints);
  EXPECT_EQ(c->points[3].x, 3.0f);
}

double length(const std::vector<Eigen::Vector2d>& p) {
  double L = 0;
  for (std::size_t i = 1; i < p.size(); ++i) L += (p[i] - p[i - 1]).norm();
  return L;
}

// Out along the roads from the staging pad to a drivable point 25-60 m away, and back.
std::vector<Eigen::Vector2d> out_and_back(const World& w) {
  const RoadRouter router(w, 1.0, 0.5);
  Eigen::Vector2d start;
  if (!router.nearest_drivable(w.header.staging.x, w.header.staging.y, 40.0, start)) return {};
  for (std::uint64_t k = 0; k < 500; ++k) {
    const Eigen::Vector2d goal = router.pick_drivable(k);
    const double d = (goal - start).norm();
    if (d < 25 || d > 60) continue;
    std::vector<Eigen::Vector2d> there, back;
    if (!router.route(start.x(), start.y(), goal.x(), goal.y(), there) || !router.route(goal.x(), goal.y(), start.x(), start.y(), back)) continue;
    there.insert(there.end(), back.begin() + 1, back.end());
    return there;
  }
  return {};
}

class UgvFeeds : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    saved_ = new test::SavedWorld("ugv_feeds");
    ASSERT_TRUE(saved_->ok()) << saved_->error();
    dir_ = saved_->dir();
    world_ = saved_->world();
  }
  static void TearDownTestSuite() {
    delete saved_;
    saved_ = nullptr;
    world_ = nullptr;
  }
  static RunOptions options(const std::string& out) {
    RunOptions o;
    o.world = dir_;
    o.out_dir = (fs::path(::testing::TempDir()) / ("ugv_feeds_" + out)).string();
    o.ugvs = 1;
    o.uav = false;
    o.seed = 3;
    o.duration_s = 3;
    o.lidar_columns = 512;
    o.record = RecordLevel::kNone;
    o.threads = 2;
    o.progress = false;
    return o;
  }
  static inline std::string dir_;
  static inline const World* world_{nullptr};
  static inline test::SavedWorld* saved_{nullptr};
};

TEST_F(UgvFeeds, ScansOdometryInitialPoseAndGroundTruthTilesArrive) {
  RunOptions o = options("feeds");
  // The simulator's true point classes are the ablation --oracle labels (field mode's scans carry none:
  // test_runner_shipped_config.cpp); this checks that the truth it hands over is right.
  o.oracles = {"labels"};
  o.ugv_map = UgvMapSource::kGroundTruth;
  o.init_error_m = 16;
  o.init_yaw_error_deg = 30;
  std::map<TimeNs, Pose2> truth;  // at the physics rate, from the sampler
  o.sample_hz = o.physics_hz;
  o.sample = [&](const UgvSample& s) { truth[s.now] = s.truth; };
  std::vector<TimeNs> scan_stamps;
  struct Hit {
    TimeNs t;
    ScanReturn q;
  };
  std::vector<Hit> hits;  // every 37th return, checked against the world after the run
  o.ugv_tap.scan = [&](int ugv, const LidarScanMsg& m) {
    EXPECT_EQ(ugv, 0);
    EXPECT_EQ(m.labels, LabelSource::kGroundTruth);
    EXPECT_EQ(m.rings, 64);
    EXPECT_EQ(m.columns, 512);
    EXPECT_DOUBLE_EQ(m.sensor_in_body.z, o.lidar_mount_height_m);
    EXPECT_EQ(m.seq, scan_stamps.size() + 1) << "the lidar stage numbers its revolutions from 1";
    ASSERT_GT(m.count, 10000u) << "a revolution in a town sees most of its rays return";
    scan_stamps.push_back(m.stamp);
    for (std::uint32_t k = 0; k < m.count; k += 37) hits.push_back(Hit{m.stamp, m.points[k]});
  };
  std::vector<WheelOdometryMsg> odom;
  o.ugv_tap.odometry = [&](int, const WheelOdometryMsg& m) { odom.push_back(m); };
  std::vector<InitialPoseMsg> inits;
  o.ugv_tap.initial_pose = [&](int, const InitialPoseMsg& m) { inits.push_back(m); };
  std::map<std::pair<int, int>, int> tiles;
  std::uint64_t cells_checked = 0, cells_matching = 0, unknown_cells = 0;
  const GridGeometry& g = world_->grid();
  o.ugv_tap.tile = [&](int, const MapTileMsg& m) {
    ++tiles[{m.tx, m.ty}];
    EXPECT_EQ(m.version, 1u);
    for (int r = 0; r < kTileCells; r += 3)
      for (int c = 0; c < kTileCells; c += 3) {
        const auto i = static_cast<std::size_t>(r) * kTileCells + static_cast<std::size_t>(c);
        const double x = (m.tx * kTileCells + c + 0.5) * kMapResolutionM, y = (m.ty * kTileCells + r + 0.5) * kMapResolutionM;
        const int wc = g.col(x), wr = g.row(y);
        if (!g.contains(wc, wr)) {
          EXPECT_EQ(m.cls[i], 255) << "outside the world: unknown";
          EXPECT_TRUE(std::isnan(m.elevation[i]));
          ++unknown_cells;
          continue;
        }
        // The class is the majority of the four 0.25 m world cells under the 0.5 m cell.
        bool among = false;
        double lo = 1e9, hi = -1e9;
        for (double dx : {-0.125, 0.125})
          for (double dy : {-0.125, 0.125}) {
            const int cc = g.col(x + dx), rr = g.row(y + dy);
            if (!g.contains(cc, rr)) continue;
            among = among || world_->class_id.at<std::uint8_t>(rr, cc) == m.cls[i];
            lo = std::min(lo, static_cast<double>(world_->surface_at(cc, rr)));
            hi = std::max(hi, static_cast<double>(world_->surface_at(cc, rr)));
          }
        ++cells_checked;
        cells_matching += among ? 1 : 0;
        EXPECT_GE(m.elevation[i], lo - 1e-3);
        EXPECT_LE(m.elevation[i], hi + 1e-3);
      }
  };
  auto r = run_team(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const RobotSummary& s = r.value().ugvs.at(0);

  // LiDAR: every revolution at 10 Hz from t = 0, labelled with the world's classes (--oracle labels).
  EXPECT_EQ(scan_stamps.size(), 31u);
  EXPECT_EQ(s.scans_published, 31u);
  EXPECT_EQ(s.channel_drops, 0u);
  for (std::size_t k = 0; k < scan_stamps.size(); ++k) EXPECT_EQ(scan_stamps[k], static_cast<TimeNs>(k) * 100'000'000) << k;
  // The label of a return is the world's class where it hit (the scan is taken at the pose of its step;
  // the sensor frame is the body's, raised by the mount).
  std::uint64_t points_on_class = 0, points_checked = 0;
  for (const Hit& h : hits) {
    if (h.q.cls == 255) continue;
    const Pose2 p = truth.at(h.t);
    const double c = std::cos(p.yaw), sn = std::sin(p.yaw);
    const double qx = static_cast<double>(h.q.x), qy = static_cast<double>(h.q.y);
    const double x = p.x + c * qx - sn * qy, y = p.y + sn * qx + c * qy;
    ++points_checked;
    bool near = false;  // the class of the hit cell or a neighbour (returns on a cell edge, range noise)
    for (double dx : {-0.15, 0.0, 0.15})
      for (double dy : {-0.15, 0.0, 0.15}) near = near || raw(world_->class_at_xy(x + dx, y + dy)) == h.q.cls;
    points_on_class += near ? 1 : 0;
  }
  ASSERT_GT(points_checked, 1000u);
  EXPECT_GT(static_cast<double>(points_on_class), 0.97 * static_cast<double>(points_checked));

  // Wheel odometry: every physics step, increments that add up to the distance driven.
  ASSERT_EQ(odom.size(), 151u);
  EXPECT_EQ(s.odometry_published, 151u);
  double travelled = 0;
  int moving = 0;
  for (std::size_t k = 1; k < odom.size(); ++k) {
    EXPECT_EQ(odom[k].stamp - odom[k - 1].stamp, 20'000'000);
    const double step = std::hypot(odom[k].pose.x - odom[k - 1].pose.x, odom[k].pose.y - odom[k - 1].pose.y);
    EXPECT_LE(step, 1.6 * 0.02 + 1e-6) << "no faster than the robot";
    EXPECT_NEAR(step, std::abs(odom[k].v_mps) * 0.02, 0.01);
    if (!odom[k].moving) {
      EXPECT_EQ(step, 0.0) << "at rest the odometry stands (no drift at rest configured)";
      EXPECT_EQ(odom[k].pose.yaw, odom[k - 1].pose.yaw);
    }
    moving += odom[k].moving ? 1 : 0;
    travelled += step;
  }
  EXPECT_GT(moving, 50);
  EXPECT_GT(s.distance_m, 0.5) << "the robot drove";
  EXPECT_NEAR(travelled, s.distance_m, 0.05 * s.distance_m + 0.02);

  // The initial pose: once, exactly 16 m and 30 deg off the true start, with those sigmas.
  ASSERT_EQ(inits.size(), 1u);
  ASSERT_TRUE(s.initial_pose_published);
  const Pose2 start = truth.begin()->second;
  EXPECT_NEAR(std::hypot(inits[0].pose.x - start.x, inits[0].pose.y - start.y), 16.0, 1e-9);
  EXPECT_NEAR(std::abs(wrap_angle(inits[0].pose.yaw - start.yaw)), 30.0 * kPi / 180.0, 1e-9);
  EXPECT_DOUBLE_EQ(inits[0].sigma_xy_m, 16.0);
  EXPECT_NEAR(inits[0].sigma_yaw_rad, 30.0 * kPi / 180.0, 1e-12);

  // Ground-truth tiles: every tile of the 300 m world (-150..150 m: tiles -5..4 each way) exactly once.
  EXPECT_EQ(tiles.size(), 100u);
  for (const auto& [k, n] : tiles) EXPECT_EQ(n, 1) << k.first << "," << k.second;
  EXPECT_EQ(s.tiles_published, 100u);
  EXPECT_GT(unknown_cells, 0u) << "the edge tiles reach past the world";
  ASSERT_GT(cells_checked, 10000u);
  EXPECT_EQ(cells_matching, cells_checked);
}

TEST_F(UgvFeeds, TilesRespectTheRingAndAllArrive) {
  RunOptions o = options("ring");
  o.duration_s = 1;
  o.ugv_map = UgvMapSource::kGroundTruth;
  o.map_tiles_per_tick = 1000;  // more than the ring holds: the rest must follow on later steps
  std::map<std::pair<int, int>, int> tiles;
  std::uint64_t received = 0;
  o.ugv_tap.tile = [&](int, const MapTileMsg& m) {
    ++tiles[{m.tx, m.ty}];
    ++received;
  };
  auto r = run_team(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const RobotSummary& s = r.value().ugvs.at(0);
  EXPECT_EQ(s.tiles_refused, 0u) << "100 tiles, 64 slots: the runner holds back what the rings cannot take";
  EXPECT_EQ(s.tiles_published, 100u);
  EXPECT_EQ(tiles.size(), 100u) << "no tile lost to a full ring";
  EXPECT_EQ(received, 100u) << "each tile exactly once, though the localization stage reads the channel too";
}

TEST_F(UgvFeeds, ScriptedRouteHoldAndSampler) {
  RunOptions o = options("route");
  const std::vector<Eigen::Vector2d> route = out_and_back(*world_);
  ASSERT_GE(route.size(), 3u);
  o.ugv_routes = {route};
  o.ugv_holds = {UgvHold{0, 2.0, 3.0}};
  o.stop_when_routes_done = true;
  o.duration_s = 300;
  o.lidar_hz = 2;  // the LiDAR is not what this test looks at
  std::vector<UgvSample> samples;
  o.sample = [&](const UgvSample& s) {
    ASSERT_NE(s.localization, nullptr);
    ASSERT_NE(s.role, nullptr);
    samples.push_back(s);
  };
  auto r = run_team(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const RobotSummary& s = r.value().ugvs.at(0);
  EXPECT_TRUE(s.route_done);
  EXPECT_EQ(s.collisions, 0u);
  EXPECT_LT(r.value().sim_s, 299.0) << "the run ended with the route";
  EXPECT_GT(s.distance_m, 0.9 * length(route)) << "all the way out and back (not turning back early)";
  ASSERT_GT(samples.size(), 100u);
  // 10 Hz from t = 0; the robot starts on the route's first point.
  EXPECT_EQ(samples[0].now, 0);
  EXPECT_EQ(samples[1].now, 100'000'000);
  EXPECT_NEAR(samples[0].truth.x, route.front().x(), 1e-9);
  EXPECT_NEAR(samples[0].truth.y, route.front().y(), 1e-9);
  // Standing still for the hold (2-5 s), moving before and after; odometry aligned at the start.
  const UgvSample& a = samples[35];  // braking took the first moments of the hold
  const UgvSample& b = samples[49];
  EXPECT_TRUE(samples[21].held && a.held && b.held);
  EXPECT_FALSE(samples[19].held);
  EXPECT_FALSE(samples[51].held);
  EXPECT_NEAR(a.truth.x, b.truth.x, 0.02);
  EXPECT_NEAR(a.truth.y, b.truth.y, 0.02);
  EXPECT_GT(samples[70].distance_m, b.distance_m + 0.5);
  EXPECT_LT(std::hypot(samples[70].odometry_in_map.x - samples[70].truth.x, samples[70].odometry_in_map.y - samples[70].truth.y), 1.0);
  EXPECT_TRUE(samples.back().route_done);
  for (const auto& q : samples) EXPECT_TRUE(q.released);
}

TEST_F(UgvFeeds, OnlineTilesFollowTheQuadrotorsMapAndTheRobotWaitsForIt) {
  RunOptions o = options("online");
  o.uav = true;
  o.duration_s = 26;
  o.survey_overlap = 0.3;
  o.ugv_map = UgvMapSource::kOnline;
  o.ugv_wait_map_radius_m = 30;
  o.ugv_wait_map_fraction = 0.3;
  o.lidar_hz = 2;
  std::map<std::pair<int, int>, MapTileMsg> last;  // newest version received per tile
  std::uint64_t received = 0, newer = 0;
  o.ugv_tap.tile = [&](int, const MapTileMsg& m) {
    ++received;
    auto it = last.find({m.tx, m.ty});
    if (it != last.end()) {
      EXPECT_GE(m.version, it->second.version) << "versions only grow";
      if (m.version > it->second.version) ++newer;
    }
    last[{m.tx, m.ty}] = m;
  };
  std::vector<UgvSample> samples;
  o.sample = [&](const UgvSample& s) { samples.push_back(s); };
  std::size_t map_tiles = 0, same = 0;
  o.inspect = [&](const RunInspection& in) -> Status {
    const mapping::OrthoMap* map = nullptr;
    for (auto& slot : in.uav->stages())
      if (auto* om = dynamic_cast<const mapping::OrthoMapStage*>(slot.stage.get())) map = &om->map();
    if (map == nullptr) return Error::make(ErrorCode::kInternal, "no ortho-map stage");
    map->for_each_tile([&](const mapping::Tile& t) {
      ++map_tiles;
      auto it = last.find({t.key.tx, t.key.ty});
      if (it == last.end()) return;
      EXPECT_LE(it->second.version, t.version);
      if (it->second.version != t.version) return;  // changed in the last step(s): not sent yet
      ++same;
      for (std::size_t i = 0; i < kTileCellCount; ++i) {
        ASSERT_EQ(it->second.cls[i], t.live[i].cls) << i;
        // The map's reported elevation: NaN until the cell has min_elevation_points.
        const float want = t.live[i].reported_elevation(static_cast<std::uint32_t>(map->params().min_elevation_points));
        if (std::isnan(want)) {
          ASSERT_TRUE(std::isnan(it->second.elevation[i])) << i;
        } else {
          ASSERT_FLOAT_EQ(it->second.elevation[i], want) << i;
        }
      }
    });
    return ok_status();
  };
  auto r = run_team(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const RobotSummary& s = r.value().ugvs.at(0);
  ASSERT_GT(map_tiles, 0u) << "the quadrotor mapped";
  EXPECT_EQ(last.size(), map_tiles) << "every tile of the map reached the robot";
  // The run ends while the quadrotor maps: each keyframe (a 60 m footprint) changes several tiles of 20 kB,
  // and the shared radio needs about a second for them, so the newest versions of some are in the air.
  // The others arrived as the map holds them, cell for cell (checked above).
  EXPECT_GE(3 * same, map_tiles) << "at least a third of the tiles are sent as they are at the end";
  EXPECT_GT(newer, 0u) << "changed tiles are sent again";
  EXPECT_EQ(received, s.tiles_published);
  // The robot stood at its start until the map knew its surroundings, then drove.
  ASSERT_GT(s.released_s, 0.0);
  ASSERT_FALSE(samples.empty());
  for (const auto& q : samples) {
    EXPECT_EQ(q.released, to_seconds(q.now) >= s.released_s);
    if (!q.released) {
      EXPECT_EQ(q.distance_m, 0.0);
    }
  }
  EXPECT_GT(s.distance_m, 0.5);
}

// Compute time: the localizer's modelled step time scales with the target CPU, two runs of a seed give
// the same counters, and the report names the mode.
TEST_F(UgvFeeds, ComputeTimeIsModelledPerTargetCpuAndRepeatsExactly) {
  const auto run = [&](const std::string& name, ComputeTimeMode mode, std::optional<TargetCpu> cpu) {
    RunOptions o = options(name);
    o.duration_s = 4;
    o.ugv_map = UgvMapSource::kGroundTruth;
    o.compute_time = mode;
    o.target_cpu = cpu;
    auto r = run_team(o);
    EXPECT_TRUE(r.ok()) << r.error().message;
    return r.ok() ? r.value() : RunSummary{};
  };
  const auto stage = [](const RunSummary& s, const std::string& name) {
    for (const auto& c : s.stages)
      if (c.name == name) return c;
    ADD_FAILURE() << "no stage " << name;
    return RunSummary::StageCounters{};
  };
  const RunSummary ryzen = run("ct_ryzen", ComputeTimeMode::kModel, std::nullopt);  // a ground robot's default
  const RunSummary again = run("ct_again", ComputeTimeMode::kModel, std::nullopt);
  const RunSummary nx = run("ct_nx", ComputeTimeMode::kModel, TargetCpu::kXavierNx);
  EXPECT_EQ(ryzen.compute_time, "model");
  const auto loc = stage(ryzen, "ugv1/localization"), loc_nx = stage(nx, "ugv1/localization");
  ASSERT_GT(loc.runs, 30u);
  const StageCost* row = find_stage_cost("localization");
  ASSERT_NE(row, nullptr);
  // The p99 is a step with one scan update (or two, when two scans wait) on the target CPU (histogram
  // buckets are ~3 % wide).
  const double f = target_cpu_info(TargetCpu::kRyzen).factor;
  EXPECT_GE(loc.exec_p99_ms, 0.96 * (row->idle_us + row->per_unit_us) * 1e-3 * f);
  EXPECT_LE(loc.exec_p99_ms, 1.04 * (row->idle_us + 2 * row->per_unit_us) * 1e-3 * f);
  EXPECT_NEAR(loc_nx.exec_p99_ms / loc.exec_p99_ms, target_cpu_info(TargetCpu::kXavierNx).factor / target_cpu_info(TargetCpu::kRyzen).factor, 0.1);
  ASSERT_EQ(ryzen.stages.size(), again.stages.size());
  for (std::size_t i = 0; i < ryzen.stages.size(); ++i) {
    EXPECT_EQ(ryzen.stages[i].runs, again.stages[i].runs) << ryzen.stages[i].name;
    EXPECT_EQ(ryzen.stages[i].slips, again.stages[i].slips) << ryzen.stages[i].name;
    EXPECT_EQ(ryzen.stages[i].exec_p99_ms, again.stages[i].exec_p99_ms) << ryzen.stages[i].name;
  }
  ASSERT_EQ(ryzen.ugvs.size(), 1u);
  EXPECT_EQ(ryzen.ugvs[0].loc_error_mean_m, again.ugvs[0].loc_error_mean_m) << "what reaches the robot does not depend on this machine";
  EXPECT_EQ(ryzen.ugvs[0].distance_m, again.ugvs[0].distance_m);
}

}  // namespace
}  // namespace ag::sim
