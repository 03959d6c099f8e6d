// LidarSimulator and OusterBeamModel: real metadata, ranges to walls and ground, seeded noise, no allocation.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <new>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "airground/sim/lidar.hpp"
#include "test_sensors_world.hpp"

#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
#define AG_TEST_COUNT_ALLOCATIONS 1
// Counts every allocation in this test binary, to show that a repeated scan allocates nothing.
namespace {
std::atomic<long> g_allocations{0};
}
// GCC sees free() on memory from an operator new it inlined; for a replacement pair that is the point.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop
#endif

namespace ag::sim {
namespace {

using testing::fill_rect;
using testing::flat_world;

std::string metadata_path() { return std::string(AG_SOURCE_DIR) + "/config/sensors/ouster/os1-64_legacy_metadata.json"; }
std::string reduced_path() { return std::string(AG_SOURCE_DIR) + "/config/sensors/ouster/OS-1-64_sensor_config_reduced.json"; }

std::string read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string write_temp(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

OusterBeamModel beams(int columns = 1024) {
  auto m = OusterBeamModel::from_metadata_json(metadata_path(), columns);
  EXPECT_TRUE(m.ok()) << m.error().message;
  return m.value();
}

// The Ouster SDK's point for a range (make_xyz_lut): r d + offset in the lidar frame with
// offset = (cos te nx - dx ne, sin te nx - dy ne, nz - dz ne), ne = |(nx, nz)|, then lidar_to_sensor
// (translation in mm). Written from the SDK's formula, not taken from the simulator.
double beam_offset_m(const OusterBeamModel& b) {
  return std::hypot(b.lidar_origin_to_beam_origin_mm, b.beam_origin_z_mm) / 1000.0;
}
Eigen::Vector3d sdk_point(const OusterBeamModel& b, int ring, int col, double range) {
  const double te = 2.0 * kPi * (1.0 - static_cast<double>(col) / b.columns);
  const double ta = -b.azimuth_deg[static_cast<std::size_t>(ring)] * kPi / 180.0;
  const double phi = b.altitude_deg[static_cast<std::size_t>(ring)] * kPi / 180.0;
  const double nx = b.lidar_origin_to_beam_origin_mm / 1000.0, nz = b.beam_origin_z_mm / 1000.0;
  const double ne = beam_offset_m(b);
  const Eigen::Vector3d d(std::cos(te + ta) * std::cos(phi), std::sin(te + ta) * std::cos(phi), std::sin(phi));
  const Eigen::Vector3d offset(std::cos(te) * nx - d.x() * ne, std::sin(te) * nx - d.y() * ne, nz - d.z() * ne);
  const Eigen::Vector3d p = range * d + offset;
  return b.lidar_to_sensor.topLeftCorner<3, 3>() * p + b.lidar_to_sensor.topRightCorner<3, 1>() / 1000.0;
}
// Beam origin (range = |offset|) and unit direction in the sensor frame, from the same formula.
void sdk_ray(const OusterBeamModel& b, int ring, int col, Eigen::Vector3d& origin, Eigen::Vector3d& dir) {
  origin = sdk_point(b, ring, col, beam_offset_m(b));
  dir = (sdk_point(b, ring, col, beam_offset_m(b) + 1.0) - origin).normalized();
}

TEST(OusterBeamModel, LoadsTheRealMetadata) {
  const OusterBeamModel b = beams();
  ASSERT_EQ(b.rings(), 64);
  EXPECT_EQ(b.azimuth_deg.size(), 64u);
  EXPECT_DOUBLE_EQ(b.altitude_deg.front(), 16.729);
  EXPECT_DOUBLE_EQ(b.altitude_deg.back(), -16.679);
  EXPECT_DOUBLE_EQ(b.azimuth_deg.front(), 3.073);
  EXPECT_DOUBLE_EQ(b.lidar_origin_to_beam_origin_mm, 12.163);
  EXPECT_DOUBLE_EQ(b.lidar_to_sensor(0, 0), -1.0);
  EXPECT_DOUBLE_EQ(b.lidar_to_sensor(1, 1), -1.0);
  EXPECT_DOUBLE_EQ(b.lidar_to_sensor(2, 3), 36.18);
  EXPECT_EQ(b.columns, 1024);
  for (int i = 1; i < b.rings(); ++i) EXPECT_LT(b.altitude_deg[static_cast<std::size_t>(i)], b.altitude_deg[static_cast<std::size_t>(i - 1)]);

  // The reduced sensor config has only the angles: the OS-1 offsets are filled in.
  auto r = OusterBeamModel::from_metadata_json(reduced_path(), 2048);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r->rings(), 64);
  EXPECT_DOUBLE_EQ(r->altitude_deg.front(), 16.46);
  EXPECT_DOUBLE_EQ(r->altitude_deg.back(), -16.75);
  EXPECT_DOUBLE_EQ(r->lidar_origin_to_beam_origin_mm, 12.163);
  EXPECT_DOUBLE_EQ(r->lidar_to_sensor(2, 3), 36.18);
  EXPECT_EQ(r->columns, 2048);

  auto d = OusterBeamModel::load_default(512);
  ASSERT_TRUE(d.ok()) << d.error().message;
  EXPECT_EQ(OusterBeamModel::default_metadata_path(), metadata_path());
}

TEST(OusterBeamModel, RejectsBrokenMetadataNamingTheProblem) {
  const std::string good = read_all(metadata_path());
  ASSERT_GT(good.size(), 1000u);
  const std::string truncated = write_temp("ouster_truncated.json", good.substr(0, good.size() / 2));
  auto r = OusterBeamModel::from_metadata_json(truncated, 1024);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kMalformed);
  EXPECT_NE(r.error().message.find(truncated), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("not valid JSON"), std::string::npos) << r.error().message;

  const auto error_of = [](const std::string& json) {
    auto m = OusterBeamModel::from_metadata_string(json, "meta.json", 1024);
    EXPECT_FALSE(m.ok());
    return m.ok() ? std::string() : m.error().message;
  };
  EXPECT_NE(error_of(R"({"beam_altitude_angles": [1, 2]})").find("missing key 'beam_azimuth_angles'"), std::string::npos);
  EXPECT_NE(error_of(R"({"beam_altitude_angles": [1, 2], "beam_azimuth_angles": [0]})").find("beam_azimuth_angles"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"beam_altitude_angles": [1, "x"], "beam_azimuth_angles": [0, 0]})").find("beam_altitude_angles"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"beam_altitude_angles": [100], "beam_azimuth_angles": [0]})").find("outside"), std::string::npos);
  EXPECT_NE(error_of(R"({"beam_altitude_angles": [], "beam_azimuth_angles": []})").find("1 to 256"), std::string::npos);
  EXPECT_NE(error_of(R"({"beam_altitude_angles": [1], "beam_azimuth_angles": [0], "lidar_to_sensor_transform": [1, 0]})")
                .find("lidar_to_sensor_transform"),
            std::string::npos);
  EXPECT_NE(error_of("[1, 2, 3]").find("JSON object"), std::string::npos);

  auto cols = OusterBeamModel::from_metadata_json(metadata_path(), 1000);
  ASSERT_FALSE(cols.ok());
  EXPECT_EQ(cols.error().code, ErrorCode::kInvalidArgument);
  auto missing = OusterBeamModel::from_metadata_json("/nonexistent/meta.json", 1024);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::kIo);

  // SDK 0.11+ metadata nests the intrinsics.
  auto nested = OusterBeamModel::from_metadata_string(
      R"({"beam_intrinsics": {"beam_altitude_angles": [2, -2], "beam_azimuth_angles": [1, -1],
          "lidar_origin_to_beam_origin_mm": 15.8},
          "lidar_intrinsics": {"lidar_to_sensor_transform": [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 38.2, 0, 0, 0, 1]}})",
      "nested.json", 512);
  ASSERT_TRUE(nested.ok()) << nested.error().message;
  EXPECT_EQ(nested->rings(), 2);
  EXPECT_DOUBLE_EQ(nested->lidar_origin_to_beam_origin_mm, 15.8);
  EXPECT_DOUBLE_EQ(nested->lidar_to_sensor(2, 3), 38.2);
  auto b2l = OusterBeamModel::from_metadata_string(
      R"({"beam_intrinsics": {"beam_altitude_angles": [2, -2], "beam_azimuth_angles": [1, -1],
          "beam_to_lidar_transform": [1, 0, 0, 27.67, 0, 1, 0, 0, 0, 0, 1, 12.5, 0, 0, 0, 1]}})",
      "b2l.json", 2048);
  ASSERT_TRUE(b2l.ok()) << b2l.error().message;
  EXPECT_DOUBLE_EQ(b2l->lidar_origin_to_beam_origin_mm, 27.67);
  EXPECT_DOUBLE_EQ(b2l->beam_origin_z_mm, 12.5);
}

LidarNoise exact() {
  LidarNoise n;
  n.range_sigma_m = 0.0;
  return n;
}

// A long building whose west wall stands at x = 15 m, across the whole world; flat road elsewhere.
World wall_world() {
  World w = flat_world(320, 320, 0.25, -40.0, 40.0, ClassId::kRoad);
  fill_rect(w, 15.0, -40.0, 40.0, 40.0, ClassId::kBuilding, 12.0f, {90, 90, 100});
  return w;
}

// Every return of ring/col pixels facing the wall at x = 15 m: range and point from the SDK formula.
void expect_wall_ranges(const World& w, const OusterBeamModel& b, const Pose3& pose) {
  std::vector<LidarPoint> pts;
  int checked = 0;
  const LidarSimulator sim(w, b, exact());
  sim.scan(pose, 1, pts);
  std::map<std::pair<int, int>, LidarPoint> by_pixel;
  for (const LidarPoint& p : pts) by_pixel[{p.ring, p.col}] = p;
  for (int ring = 0; ring < b.rings(); ++ring) {
    for (int col = b.columns / 2 - 60; col <= b.columns / 2 + 60; ++col) {  // sensor +x is column W/2
      Eigen::Vector3d o, d;
      sdk_ray(b, ring, col, o, d);
      o += Eigen::Vector3d(pose.x, pose.y, pose.z);
      const double t = (15.0 - o.x()) / d.x();
      const double z_at_wall = o.z() + t * d.z();
      if (z_at_wall < 0.05 || z_at_wall > 11.95) continue;  // above the roof or into the ground first
      const auto it = by_pixel.find({ring, col});
      ASSERT_NE(it, by_pixel.end()) << "no return at ring " << ring << " col " << col;
      const LidarPoint& p = it->second;
      const double expected = t + beam_offset_m(b);
      ASSERT_NEAR(p.range, expected, 1e-4) << ring << "," << col;
      EXPECT_EQ(p.cls, raw(ClassId::kBuilding));
      EXPECT_NEAR(p.x, 15.0, 1e-4);  // the point lies on the wall plane
      const Eigen::Vector3d sdk = sdk_point(b, ring, col, p.range);
      EXPECT_NEAR((Eigen::Vector3d(p.x, p.y, p.z) - sdk).norm(), 0.0, 1e-4);
      ++checked;
    }
  }
  EXPECT_GT(checked, 3000);
}

TEST(Lidar, RangeToAWallMatchesTheAnalyticDistance) {
  const World w = wall_world();
  const OusterBeamModel b = beams();
  const Pose3 pose{0.0, 0.0, 1.0, 0, 0, 0};  // facing the wall (east), 15 m away
  expect_wall_ranges(w, b, pose);
  OusterBeamModel raised = b;  // a newer sensor's beam origin, above the lidar plane
  raised.lidar_origin_to_beam_origin_mm = 27.67;
  raised.beam_origin_z_mm = 20.0;
  expect_wall_ranges(w, raised, pose);
  std::vector<LidarPoint> pts;

  // With noise: the horizontal-most beam straight at the wall, over many columns and seeds.
  LidarNoise noisy;
  noisy.range_sigma_m = 0.03;
  const LidarSimulator nsim(w, b, noisy);
  double sum = 0, sum2 = 0;
  int n = 0;
  for (std::uint64_t seed = 0; seed < 40; ++seed) {
    nsim.scan(pose, seed, pts);
    for (const LidarPoint& p : pts) {
      if (p.ring != 31 || std::abs(static_cast<int>(p.col) - b.columns / 2) > 20) continue;
      Eigen::Vector3d o, d;
      sdk_ray(b, p.ring, p.col, o, d);
      const double expected = (15.0 - o.x()) / d.x() + beam_offset_m(b);
      const double e = static_cast<double>(p.range) - expected;
      ASSERT_LT(std::abs(e), 6 * noisy.range_sigma_m);
      sum += e, sum2 += e * e, ++n;
    }
  }
  ASSERT_EQ(n, 40 * 41);
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 0.0, 4 * noisy.range_sigma_m / std::sqrt(n));
  EXPECT_NEAR(sd, noisy.range_sigma_m, 0.1 * noisy.range_sigma_m);
}

TEST(Lidar, FlatGroundReturnsAtTheRangeOfEachBeamAltitude) {
  const World w = flat_world(1200, 1200, 0.25, -150.0, 150.0, ClassId::kGrass);
  const OusterBeamModel b = beams(512);
  const double h = 1.2;
  const LidarSimulator sim(w, b, exact());
  std::vector<LidarPoint> pts;
  sim.scan({3.0, -2.0, h, 0, 0, 0.4}, 9, pts);
  std::vector<int> per_ring(64, 0);
  for (const LidarPoint& p : pts) {
    Eigen::Vector3d o, d;
    sdk_ray(b, p.ring, p.col, o, d);
    // Ground at sensor-frame z = -h: the beam origin sits 36.18 mm above the sensor origin.
    const double t = (o.z() + h) / -d.z();
    ASSERT_NEAR(p.range, t + beam_offset_m(b), 1e-4) << "ring " << p.ring;
    ASSERT_NEAR(p.z, -h, 1e-4);
    EXPECT_EQ(p.cls, raw(ClassId::kGrass));
    ++per_ring[p.ring];
  }
  // Every beam pointing low enough to meet the ground within 120 m returns in every column, no other.
  for (int ring = 0; ring < 64; ++ring) {
    const double alt = b.altitude_deg[static_cast<std::size_t>(ring)] * kPi / 180.0;
    const double reach = alt < 0 ? (h + 0.03618) / std::sin(-alt) : 1e9;
    if (reach < 118.0) {
      EXPECT_EQ(per_ring[static_cast<std::size_t>(ring)], 512) << "ring " << ring;
    } else if (reach > 122.0) {
      EXPECT_EQ(per_ring[static_cast<std::size_t>(ring)], 0) << "ring " << ring;
    }
  }
  EXPECT_NEAR((h + 0.03618) / std::sin(16.679 * kPi / 180.0), 4.3, 0.05);  // the lowest beam's footprint
}

TEST(Lidar, PoseRotatesTheScan) {
  World w = flat_world(320, 320, 0.25, -40.0, 40.0, ClassId::kRoad);
  fill_rect(w, -40.0, 10.0, 40.0, 40.0, ClassId::kBuilding, 12.0f, {90, 90, 100});  // wall to the north at y = 10
  const LidarSimulator sim(w, beams(), exact());
  std::vector<LidarPoint> pts;
  sim.scan({0, 0, 1.0, 0, 0, kPi / 2}, 0, pts);  // facing north: the wall is ahead (+x)
  int ahead = 0;
  for (const LidarPoint& p : pts) {
    if (p.cls != raw(ClassId::kBuilding)) continue;
    EXPECT_NEAR(p.x, 10.0, 1e-4);
    ++ahead;
  }
  EXPECT_GT(ahead, 3000);
  sim.scan({0, 0, 1.0, 0, 0, 0}, 0, pts);  // facing east: the wall is on the left (+y)
  for (const LidarPoint& p : pts) {
    if (p.cls == raw(ClassId::kBuilding)) {
      EXPECT_NEAR(p.y, 10.0, 1e-4);
    }
  }
  // Tilted: every return from flat ground, taken back to the map frame, lies on the ground; nose up
  // (negative pitch) means fewer returns ahead and more behind.
  const World flat = flat_world(1200, 1200, 0.25, -150.0, 150.0);
  const LidarSimulator fsim(flat, beams(), exact());
  const Pose3 tilted{2, -1, 1.0, 0.05, -0.08, 0.3};
  const Eigen::Matrix3d rot = (Eigen::AngleAxisd(tilted.yaw, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(tilted.pitch, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(tilted.roll, Eigen::Vector3d::UnitX()))
                                  .toRotationMatrix();
  std::vector<LidarPoint> level, pitched;
  fsim.scan({2, -1, 1.0, 0, 0, 0.3}, 0, level);
  fsim.scan(tilted, 0, pitched);
  ASSERT_GT(pitched.size(), 10000u);
  for (const LidarPoint& p : pitched) {
    const Eigen::Vector3d m = rot * Eigen::Vector3d(p.x, p.y, p.z) + Eigen::Vector3d(tilted.x, tilted.y, tilted.z);
    ASSERT_NEAR(m.z(), 0.0, 1e-4);
  }
  const auto count_ahead = [](const std::vector<LidarPoint>& v) {
    return std::count_if(v.begin(), v.end(), [](const LidarPoint& p) { return p.x > 0.0f; });
  };
  EXPECT_LT(count_ahead(pitched), count_ahead(level) * 9 / 10);
  EXPECT_GT(static_cast<std::ptrdiff_t>(pitched.size()) - count_ahead(pitched), (static_cast<std::ptrdiff_t>(level.size()) - count_ahead(level)) * 11 / 10);
}

TEST(Lidar, SameSeedSameScanOtherSeedOtherNoise) {
  const World w = wall_world();
  LidarNoise n;
  n.range_sigma_m = 0.03;
  n.dropout_prob = 0.1;
  const LidarSimulator sim(w, beams(), n);
  const Pose3 pose{-3, 2, 1.1, 0.01, -0.02, 0.3};
  std::vector<LidarPoint> a, b, c;
  sim.scan(pose, 42, a);
  sim.scan(pose, 42, b);
  sim.scan(pose, 43, c);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GT(a.size(), 10000u);
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].range, b[i].range);
    ASSERT_EQ(a[i].x, b[i].x);
    ASSERT_EQ(a[i].ring, b[i].ring);
    ASSERT_EQ(a[i].col, b[i].col);
  }
  std::map<std::pair<int, int>, float> ra;
  for (const LidarPoint& p : a) ra[{p.ring, p.col}] = p.range;
  int same = 0, common = 0;
  for (const LidarPoint& p : c) {
    const auto it = ra.find({p.ring, p.col});
    if (it == ra.end()) continue;
    ++common;
    same += it->second == p.range ? 1 : 0;
  }
  EXPECT_GT(common, 10000);
  EXPECT_LT(same, common / 100);
  EXPECT_NE(a.size(), c.size());  // different dropouts
}

TEST(Lidar, DropoutAndRangeLimits) {
  const World w = wall_world();
  LidarNoise n = exact();
  const Pose3 pose{0, 0, 1.0, 0, 0, 0};
  std::vector<LidarPoint> all, some;
  LidarSimulator(w, beams(), n).scan(pose, 1, all);
  n.dropout_prob = 0.5;
  LidarSimulator(w, beams(), n).scan(pose, 1, some);
  EXPECT_NEAR(static_cast<double>(some.size()) / static_cast<double>(all.size()), 0.5, 0.02);
  n = exact();
  n.min_range_m = 6.0;
  n.max_range_m = 14.0;
  LidarSimulator(w, beams(), n).scan(pose, 1, some);
  ASSERT_FALSE(some.empty());
  for (const LidarPoint& p : some) {
    EXPECT_GE(p.range, 6.0f);
    EXPECT_LE(p.range, 14.0f);
  }
}

// Water is specular and absorbing at 865 nm: a pond is a hole in the scan, and the ground beyond it
// still returns (unless `water_returns`, the old model).
TEST(Lidar, WaterGivesNoReturnButTheFarShoreDoes) {
  World w = flat_world(400, 400, 0.25, -50.0, 50.0, ClassId::kGrass);
  for (int r = 0; r < 400; ++r)
    for (int c = 0; c < 400; ++c) {
      const double x = -50.0 + (c + 0.5) * 0.25, y = 50.0 - (r + 0.5) * 0.25;
      if (x > 4.0 && x < 12.0 && std::fabs(y) < 6.0) w.class_id.at<std::uint8_t>(r, c) = raw(ClassId::kWater);
    }
  const Pose3 pose{0, 0, 0.7, 0, 0, 0};
  for (const bool water_returns : {false, true}) {
    LidarNoise n = exact();
    n.water_returns = water_returns;
    std::vector<LidarPoint> pts;
    LidarSimulator(w, beams(512), n).scan(pose, 3, pts);
    int on_water = 0, far_shore = 0;
    for (const LidarPoint& p : pts) {
      on_water += p.cls == raw(ClassId::kWater) ? 1 : 0;
      far_shore += (p.x > 12.5F && p.x < 20.0F && std::fabs(p.y) < 1.0F) ? 1 : 0;
    }
    if (water_returns)
      EXPECT_GT(on_water, 500);
    else
      EXPECT_EQ(on_water, 0) << "no return from the pond";
    EXPECT_GE(far_shore, 15) << "the ground beyond the pond returns either way";
  }
}

TEST(Lidar, RepeatedScansReuseTheBuffer) {
  const World w = wall_world();
  const LidarSimulator sim(w, beams(2048), LidarNoise{});
  std::vector<LidarPoint> pts;
  sim.scan({0, 0, 1, 0, 0, 0}, 1, pts);
  const auto* data = pts.data();
  const auto capacity = pts.capacity();
  EXPECT_EQ(capacity, sim.rays_per_scan());
#ifdef AG_TEST_COUNT_ALLOCATIONS
  const long before = g_allocations.load();
#endif
  for (int i = 0; i < 5; ++i) sim.scan({-5.0 + i, 3.0, 1, 0, 0, 0.3 * i}, static_cast<std::uint64_t>(i), pts);
#ifdef AG_TEST_COUNT_ALLOCATIONS
  EXPECT_EQ(g_allocations.load(), before);
#endif
  EXPECT_EQ(pts.data(), data);
  EXPECT_EQ(pts.capacity(), capacity);
}

// A 150 m town on sloped, rolling terrain: streets with curbs, buildings, domed tree crowns, parked cars,
// one-cell poles; the world edge is within range of some poses.
World town_world() {
  World w = flat_world(600, 600, 0.25, -75.0, 75.0, ClassId::kGrass);
  const GridGeometry& g = w.grid();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (std::int32_t r = 0; r < g.height; ++r) {
    for (std::int32_t c = 0; c < g.width; ++c) {
      const double x = g.x_of(c), y = g.y_of(r);
      w.terrain.at<float>(r, c) = static_cast<float>(0.04 * x + 0.02 * y + 1.5 * std::sin(x / 17.0) * std::cos(y / 23.0));
      const double bx = std::fmod(x + 75.0, 40.0), by = std::fmod(y + 75.0, 40.0);
      if (bx < 8.0 || by < 8.0) {
        w.class_id.at<std::uint8_t>(r, c) = raw(ClassId::kRoad);
      } else if (bx < 8.5 || by < 8.5) {
        w.class_id.at<std::uint8_t>(r, c) = raw(ClassId::kDirt);
        w.height.at<float>(r, c) = 0.15f;  // curb
      }
    }
  }
  const auto put = [&](double x, double y, ClassId k, float h) {
    const std::int32_t c = g.col(x), r = g.row(y);
    if (!g.contains(c, r)) return;
    w.class_id.at<std::uint8_t>(r, c) = raw(k);
    w.height.at<float>(r, c) = h;
  };
  for (int b = 0; b < 30; ++b) {
    const double x0 = -75.0 + u01(rng) * 140.0, y0 = -75.0 + u01(rng) * 140.0, wx = 4 + u01(rng) * 14,
                 wy = 4 + u01(rng) * 14, h = 3 + u01(rng) * 25;
    for (double x = x0; x < x0 + wx; x += 0.25)
      for (double y = y0; y < y0 + wy; y += 0.25) put(x, y, ClassId::kBuilding, static_cast<float>(h));
  }
  for (int t = 0; t < 60; ++t) {
    const double cx = -75.0 + u01(rng) * 150.0, cy = -75.0 + u01(rng) * 150.0, rad = 1 + u01(rng) * 3, h = 4 + u01(rng) * 10;
    for (double x = cx - rad; x <= cx + rad; x += 0.25) {
      for (double y = cy - rad; y <= cy + rad; y += 0.25) {
        const double d2 = ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / (rad * rad);
        if (d2 <= 1.0) put(x, y, ClassId::kTree, static_cast<float>(h * (0.6 + 0.4 * std::sqrt(1.0 - d2))));
      }
    }
  }
  for (int v = 0; v < 60; ++v) {
    const double cx = -75.0 + u01(rng) * 150.0, cy = -75.0 + u01(rng) * 150.0;
    const bool along_x = u01(rng) < 0.5;
    for (double x = cx; x < cx + (along_x ? 4.5 : 1.75); x += 0.25)
      for (double y = cy; y < cy + (along_x ? 1.75 : 4.5); y += 0.25) put(x, y, ClassId::kVehicle, 1.5f);
  }
  // One-cell poles (as buildings): thin obstacles a fan could step past.
  for (int p = 0; p < 80; ++p) put(-75.0 + u01(rng) * 150.0, -75.0 + u01(rng) * 150.0, ClassId::kBuilding, 6.0f);
  return w;
}

// Same returns, in the same order, up to float rounding.
void expect_same_scan(const std::vector<LidarPoint>& fast, const std::vector<LidarPoint>& ref, const std::string& what) {
  std::map<std::pair<int, int>, const LidarPoint*> by_pixel;
  for (const LidarPoint& p : ref) by_pixel[{p.ring, p.col}] = &p;
  std::size_t missing = 0;
  for (const LidarPoint& p : fast) {
    const auto it = by_pixel.find({p.ring, p.col});
    if (it == by_pixel.end()) {
      ADD_FAILURE() << what << ": extra return at ring " << p.ring << " col " << p.col << " range " << p.range;
      continue;
    }
    const LidarPoint& q = *it->second;
    EXPECT_NEAR(p.x, q.x, 1e-4) << what << " ring " << p.ring << " col " << p.col;
    EXPECT_NEAR(p.y, q.y, 1e-4) << what << " ring " << p.ring << " col " << p.col;
    EXPECT_NEAR(p.z, q.z, 1e-4) << what << " ring " << p.ring << " col " << p.col;
    EXPECT_NEAR(p.range, q.range, 1e-4) << what << " ring " << p.ring << " col " << p.col;
    EXPECT_EQ(p.cls, q.cls) << what << " ring " << p.ring << " col " << p.col;
    by_pixel.erase(it);
  }
  for (const auto& [pixel, q] : by_pixel) {
    ++missing;
    if (missing < 10) ADD_FAILURE() << what << ": missing return at ring " << pixel.first << " col " << pixel.second << " range " << q->range;
  }
  EXPECT_EQ(missing, 0u) << what;
  ASSERT_EQ(fast.size(), ref.size()) << what;
  for (std::size_t i = 0; i < fast.size(); ++i) {
    ASSERT_EQ(fast[i].ring, ref[i].ring) << what << " at " << i;
    ASSERT_EQ(fast[i].col, ref[i].col) << what << " at " << i;
  }
}

TEST(Lidar, FastScanEqualsPerRayCastsOnRandomTiltedPoses) {
  const World w = town_world();
  const GridGeometry& g = w.grid();
  LidarNoise noise;  // noise and dropouts must follow (seed, ring, col) as well
  noise.dropout_prob = 0.05;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const double tilt = 5.0 * kPi / 180.0;
  std::size_t returns = 0;
  int poses = 0;
  for (const int cols : {512, 1024, 2048}) {
    const LidarSimulator sim(w, beams(cols), noise);
    const int n = cols == 512 ? 40 : 6;
    for (int i = 0; i < n; ++i) {
      Pose3 pose;
      // Mostly inside the town; a few near the edge, where rays leave the world.
      const double span = i % 7 == 3 ? 74.0 : 65.0;
      pose.x = -span + 2.0 * span * u01(rng);
      pose.y = -span + 2.0 * span * u01(rng);
      const std::int32_t c = std::clamp(g.col(pose.x), 0, g.width - 1), r = std::clamp(g.row(pose.y), 0, g.height - 1);
      pose.z = static_cast<double>(w.surface_at(c, r)) + (i % 5 == 0 ? 0.3 + 3.0 * u01(rng) : 0.8 + 0.6 * u01(rng));
      pose.yaw = 2.0 * kPi * u01(rng);
      if (i % 4 != 0) {  // a quarter level, the rest tilted up to 5 deg
        pose.roll = tilt * (2.0 * u01(rng) - 1.0);
        pose.pitch = tilt * (2.0 * u01(rng) - 1.0);
      }
      if (i == 1) pose.roll = tilt, pose.pitch = -tilt;
      const std::uint64_t seed = 1000u + static_cast<std::uint64_t>(i);
      std::vector<LidarPoint> fast, ref;
      sim.scan(pose, seed, fast);
      sim.scan_per_ray(pose, seed, ref);
      expect_same_scan(fast, ref, std::to_string(cols) + " columns, pose " + std::to_string(i));
      returns += ref.size();
      ++poses;
      if (HasFailure()) return;
    }
  }
  EXPECT_GT(returns, static_cast<std::size_t>(poses) * 10000u);
}

TEST(Lidar, ColumnChunksConcatenateToTheFullScan) {
  const World w = town_world();
  LidarNoise noise;
  noise.dropout_prob = 0.05;
  const LidarSimulator sim(w, beams(1024), noise);
  const GridGeometry& g = w.grid();
  for (Pose3 pose : {Pose3{3, -7, 0, 0.03, -0.02, 0.4}, Pose3{-20, 15, 0, 0, 0, -2.0}, Pose3{40, 30, 0, -0.05, 0.02, 1.0}}) {
    pose.z = static_cast<double>(w.surface_at(g.col(pose.x), g.row(pose.y))) + 1.0;  // 1 m above whatever is there
    std::vector<LidarPoint> full, part, joined;
    sim.scan(pose, 9, full);
    for (const auto& [c0, c1] : {std::pair{0, 100}, std::pair{100, 517}, std::pair{517, 1024}}) {
      sim.scan_columns(pose, 9, c0, c1, part);
      for (const auto& p : part) {
        ASSERT_GE(p.col, c0);
        ASSERT_LT(p.col, c1);
      }
      joined.insert(joined.end(), part.begin(), part.end());
    }
    ASSERT_GT(full.size(), 1000u);
    ASSERT_EQ(joined.size(), full.size());
    for (std::size_t i = 0; i < full.size(); ++i) {
      ASSERT_EQ(joined[i].col, full[i].col);
      ASSERT_EQ(joined[i].ring, full[i].ring);
      ASSERT_EQ(joined[i].range, full[i].range);
      ASSERT_EQ(joined[i].cls, full[i].cls);
    }
  }
}

TEST(Lidar, NoiseYamlIsValidated) {
  auto n = LidarNoise::load_string("lidar_noise:\n  range_sigma_m: 0.02\n  dropout_prob: 0.05\n", "lidar.yaml");
  ASSERT_TRUE(n.ok()) << n.error().message;
  EXPECT_DOUBLE_EQ(n->range_sigma_m, 0.02);
  EXPECT_DOUBLE_EQ(n->dropout_prob, 0.05);
  EXPECT_DOUBLE_EQ(n->max_range_m, 120.0);
  const auto error_of = [](const char* text) {
    auto r = LidarNoise::load_string(text, "lidar.yaml");
    EXPECT_FALSE(r.ok());
    return r.ok() ? std::string() : r.error().message;
  };
  EXPECT_NE(error_of("lidar_noise:\n  sigma: 1\n").find("lidar_noise.sigma"), std::string::npos);
  EXPECT_NE(error_of("lidar_noise:\n  dropout_prob: 2\n").find("lidar_noise.dropout_prob"), std::string::npos);
  EXPECT_NE(error_of("lidar_noise:\n  min_range_m: 5\n  max_range_m: 4\n").find("max_range_m"), std::string::npos);
  auto file = LidarNoise::load_file(std::string(AG_SOURCE_DIR) + "/config/sensors/lidar_noise.yaml");
  ASSERT_TRUE(file.ok()) << file.error().message;
  EXPECT_DOUBLE_EQ(file->range_sigma_m, LidarNoise{}.range_sigma_m);
}

TEST(Lidar, RejectsBadConfigurations) {
  const World w = wall_world();
  OusterBeamModel b = beams();
  b.columns = 1000;
  EXPECT_THROW(LidarSimulator(w, b, LidarNoise{}), std::invalid_argument);
  b = beams();
  b.azimuth_deg.pop_back();
  EXPECT_THROW(LidarSimulator(w, b, LidarNoise{}), std::invalid_argument);
  LidarNoise n;
  n.max_range_m = 0.1;
  EXPECT_THROW(LidarSimulator(w, beams(), n), std::invalid_argument);
}

}  // namespace
}  // namespace ag::sim
