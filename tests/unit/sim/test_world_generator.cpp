// Procedural world generator: determinism by seed, the content the missions rely on (all classes,
// exactly N target clusters of 1.5 m cars, 5-30 m buildings, connected roads, a free staging pad),
// textured colour, sizes from 200 m to 1 km, and targets.yaml.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <string>
#include <vector>

#include <unistd.h>

#include "airground/sim/generator.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

// Test files go under one directory per process (concurrent runs do not meet), removed at the end.
fs::path scratch_root() { return fs::path(::testing::TempDir()) / ("ag_world_gen_" + std::to_string(::getpid())); }
class ScratchCleanup : public ::testing::Environment {
 public:
  void TearDown() override { fs::remove_all(scratch_root()); }
};
[[maybe_unused]] const ::testing::Environment* const kScratchCleanup = ::testing::AddGlobalTestEnvironment(new ScratchCleanup);

std::string fresh_dir(const std::string& name) {
  const fs::path p = scratch_root() / name;
  fs::remove_all(p);
  return p.string();
}

std::vector<char> file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::vector<char> bytes(fs::exists(p) ? fs::file_size(p) : 0);
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

GeneratorOptions small_options(std::uint64_t seed) {
  GeneratorOptions o;
  o.seed = seed;
  o.size_m = 200;
  o.resolution = 0.5;
  o.targets = 5;
  return o;
}

cv::Mat class_mask(const World& w, ClassId c) { return w.class_id == raw(c); }

// Groups vehicle pixels into cars (8-connected) and cars into clusters (centres within `link` metres,
// single linkage); returns the cluster index of every car and the car centroids.
struct VehicleGroups {
  std::vector<cv::Point2d> cars;  // [m]
  std::vector<int> cluster;
  int clusters{0};
};

VehicleGroups group_vehicles(const World& w, double link) {
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(class_mask(w, ClassId::kVehicle), labels, stats, centroids, 8, CV_32S);
  VehicleGroups g;
  for (int i = 1; i < n; ++i) {
    g.cars.emplace_back(w.grid().x_of(centroids.at<double>(i, 0)), w.grid().y_of(centroids.at<double>(i, 1)));
  }
  std::vector<int> parent(g.cars.size());
  std::iota(parent.begin(), parent.end(), 0);
  const auto find = [&](int a) {
    while (parent[static_cast<std::size_t>(a)] != a) a = parent[static_cast<std::size_t>(a)];
    return a;
  };
  for (std::size_t a = 0; a < g.cars.size(); ++a) {
    for (std::size_t b = a + 1; b < g.cars.size(); ++b) {
      if (cv::norm(g.cars[a] - g.cars[b]) <= link) parent[static_cast<std::size_t>(find(static_cast<int>(a)))] = find(static_cast<int>(b));
    }
  }
  std::vector<int> root_to_cluster(g.cars.size(), -1);
  for (std::size_t a = 0; a < g.cars.size(); ++a) {
    const auto root = static_cast<std::size_t>(find(static_cast<int>(a)));
    if (root_to_cluster[root] < 0) root_to_cluster[root] = g.clusters++;
    g.cluster.push_back(root_to_cluster[root]);
  }
  return g;
}

TEST(WorldGenerator, SameSeedGivesByteIdenticalFiles) {
  std::vector<TargetCluster> ta, tb;
  const auto a = generate_world(small_options(7), &ta);
  const auto b = generate_world(small_options(7), &tb);
  ASSERT_TRUE(a.ok()) << a.error().message;
  ASSERT_TRUE(b.ok()) << b.error().message;
  const std::string da = fresh_dir("same_a"), db = fresh_dir("same_b");
  ASSERT_TRUE(save_world(a.value(), da).ok());
  ASSERT_TRUE(save_targets(ta, a->header.staging, da).ok());
  ASSERT_TRUE(save_world(b.value(), db).ok());
  ASSERT_TRUE(save_targets(tb, b->header.staging, db).ok());
  for (const char* f : {"world.yaml", "class.png", "albedo.png", "height.tif", "terrain.tif", "targets.yaml"}) {
    const auto x = file_bytes(fs::path(da) / f), y = file_bytes(fs::path(db) / f);
    EXPECT_FALSE(x.empty()) << f;
    EXPECT_EQ(x, y) << f << " differs between two generations with the same seed";
  }
}

TEST(WorldGenerator, DifferentSeedGivesADifferentWorld) {
  const auto a = generate_world(small_options(7));
  const auto b = generate_world(small_options(8));
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_GT(cv::countNonZero(a->class_id != b->class_id), 5000);
  const std::string da = fresh_dir("diff_a"), db = fresh_dir("diff_b");
  ASSERT_TRUE(save_world(a.value(), da).ok());
  ASSERT_TRUE(save_world(b.value(), db).ok());
  for (const char* f : {"class.png", "albedo.png", "height.tif", "terrain.tif"}) {
    EXPECT_NE(file_bytes(fs::path(da) / f), file_bytes(fs::path(db) / f)) << f;
  }
}

TEST(WorldGenerator, DefaultWorldIsTheSeed42WorldAndStable) {
  const World& w = default_world();
  EXPECT_EQ(&w, &default_world()) << "generated once per process";
  EXPECT_EQ(w.header.seed, 42U);
  EXPECT_EQ(w.header.grid.width, 1600);
  EXPECT_EQ(w.header.grid.height, 1600);
  EXPECT_DOUBLE_EQ(w.header.grid.resolution, 0.25);
  EXPECT_DOUBLE_EQ(w.header.grid.origin_x, -200.0);
  EXPECT_DOUBLE_EQ(w.header.grid.origin_y, 200.0);
  EXPECT_EQ(default_targets().size(), 13U);
  GeneratorOptions o;
  o.seed = 42;
  const auto again = generate_world(o);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(cv::countNonZero(again->class_id != w.class_id), 0);
  EXPECT_EQ(cv::norm(again->height, w.height, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(again->terrain, w.terrain, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(again->albedo, w.albedo, cv::NORM_INF), 0.0);
}

TEST(WorldGenerator, AllClassesArePresent) {
  const World& w = default_world();
  const double cells = static_cast<double>(w.class_id.total());
  for (const ClassId c : {ClassId::kRoad, ClassId::kDirt, ClassId::kGrass, ClassId::kTree, ClassId::kBuilding, ClassId::kVehicle, ClassId::kWater}) {
    const int n = cv::countNonZero(class_mask(w, c));
    EXPECT_GT(n, 100) << ClassTable::builtin().info(c).name;
    EXPECT_LT(n, 0.7 * cells) << ClassTable::builtin().info(c).name;
  }
  EXPECT_EQ(cv::countNonZero(class_mask(w, ClassId::kUnknown)), 0);
  EXPECT_GT(cv::countNonZero(class_mask(w, ClassId::kGrass)), 0.2 * cells) << "grass is the default ground";
  EXPECT_TRUE(w.validate().ok());
}

TEST(WorldGenerator, TargetsAreExactlyTheVehicleClusters) {
  const World& w = default_world();
  const auto& targets = default_targets();
  ASSERT_EQ(targets.size(), 13U);
  const VehicleGroups groups = group_vehicles(w, 12.0);
  EXPECT_EQ(groups.clusters, 13) << "vehicles must form exactly one group per target";
  int cars = 0;
  for (std::size_t i = 0; i < targets.size(); ++i) {
    const TargetCluster& t = targets[i];
    EXPECT_EQ(t.id, static_cast<int>(i));
    EXPECT_GE(t.cars, 2);
    EXPECT_LE(t.cars, 8);
    ASSERT_EQ(static_cast<std::size_t>(t.cars), t.car_poses.size());
    double mx = 0, my = 0;
    std::vector<int> group_of_car;
    for (const Pose2& p : t.car_poses) {
      EXPECT_EQ(w.class_at_xy(p.x, p.y), ClassId::kVehicle) << "car centre of target " << t.id;
      // Every car footprint corner is vehicle too: the pose matches the raster.
      for (const double u : {-1.9, 1.9}) {
        for (const double v : {-0.6, 0.6}) {
          const double x = p.x + u * std::cos(p.yaw) - v * std::sin(p.yaw), y = p.y + u * std::sin(p.yaw) + v * std::cos(p.yaw);
          EXPECT_EQ(w.class_at_xy(x, y), ClassId::kVehicle) << "target " << t.id;
        }
      }
      mx += p.x / t.cars;
      my += p.y / t.cars;
      std::size_t nearest = 0;
      for (std::size_t k = 1; k < groups.cars.size(); ++k) {
        if (cv::norm(groups.cars[k] - cv::Point2d(p.x, p.y)) < cv::norm(groups.cars[nearest] - cv::Point2d(p.x, p.y))) nearest = k;
      }
      group_of_car.push_back(groups.cluster[nearest]);
    }
    EXPECT_NEAR(t.x, mx, 1e-9);
    EXPECT_NEAR(t.y, my, 1e-9);
    EXPECT_TRUE(std::all_of(group_of_car.begin(), group_of_car.end(), [&](int g) { return g == group_of_car.front(); }))
        << "all cars of target " << t.id << " in one group";
    cars += t.cars;
  }
  EXPECT_EQ(static_cast<std::size_t>(cars), groups.cars.size()) << "every vehicle on the map belongs to a target";
}

TEST(WorldGenerator, HeightsPerClass) {
  const World& w = default_world();
  int curbs = 0;
  for (int r = 0; r < w.grid().height; ++r) {
    for (int c = 0; c < w.grid().width; ++c) {
      const float h = w.height.at<float>(r, c);
      switch (w.class_at(c, r)) {
        case ClassId::kVehicle: ASSERT_EQ(h, 1.5F) << c << "," << r; break;
        case ClassId::kBuilding:
          ASSERT_GE(h, 5.0F) << c << "," << r;
          ASSERT_LE(h, 30.0F) << c << "," << r;
          break;
        case ClassId::kTree: ASSERT_GE(h, 0.5F) << c << "," << r; break;
        case ClassId::kRoad:
          ASSERT_TRUE(h == 0.0F || h == 0.15F) << h;
          curbs += h > 0 ? 1 : 0;
          break;
        default: ASSERT_EQ(h, 0.0F) << c << "," << r; break;
      }
    }
  }
  EXPECT_GT(curbs, 5000) << "curbs along the roads";
  double tallest = 0;
  cv::minMaxLoc(w.height, nullptr, &tallest, nullptr, nullptr, class_mask(w, ClassId::kBuilding));
  EXPECT_GT(tallest, 15.0) << "some tall buildings";
}

TEST(WorldGenerator, TerrainIsGentle) {
  const World& w = default_world();
  double lo = 0, hi = 0;
  cv::minMaxLoc(w.terrain, &lo, &hi);
  EXPECT_LT(hi - lo, 15.0);
  EXPECT_GT(hi - lo, 0.5) << "not flat either";
  EXPECT_NEAR(w.terrain.at<float>(800, 800), 0.0F, 0.05F) << "the datum is the ground at the map origin";
  cv::Mat gx, gy;
  cv::Sobel(w.terrain, gx, CV_32F, 1, 0, 3, 1.0 / (8 * 0.25));
  cv::Sobel(w.terrain, gy, CV_32F, 0, 1, 3, 1.0 / (8 * 0.25));
  cv::Mat slope;
  cv::magnitude(gx, gy, slope);
  double steepest = 0;
  cv::minMaxLoc(slope, nullptr, &steepest);
  EXPECT_LT(steepest, 0.25) << "no cliffs, also around the pond";
}

TEST(WorldGenerator, RoadsAreConnected) {
  const World& w = default_world();
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(class_mask(w, ClassId::kRoad), labels, stats, centroids, 8, CV_32S);
  int total = 0, largest = 0;
  for (int i = 1; i < n; ++i) {
    total += stats.at<int>(i, cv::CC_STAT_AREA);
    largest = std::max(largest, stats.at<int>(i, cv::CC_STAT_AREA));
  }
  EXPECT_GT(largest, 0.9 * total) << n - 1 << " road components";
}

TEST(WorldGenerator, StagingPadIsFreeRoadInTheSouthWest) {
  const World& w = default_world();
  const Pose2 s = w.header.staging;
  EXPECT_LT(s.x, 0.0);
  EXPECT_LT(s.y, 0.0);
  for (double dx = -10; dx <= 10; dx += 0.5) {
    for (double dy = -10; dy <= 10; dy += 0.5) {
      ASSERT_EQ(w.class_at_xy(s.x + dx, s.y + dy), ClassId::kRoad) << dx << "," << dy;
      ASSERT_EQ(w.height.at<float>(w.grid().row(s.y + dy), w.grid().col(s.x + dx)), 0.0F);
    }
  }
  for (const TargetCluster& t : default_targets()) {
    for (const Pose2& p : t.car_poses) EXPECT_GT(std::hypot(p.x - s.x, p.y - s.y), 25.0);
  }
}

TEST(WorldGenerator, AlbedoIsTexturedNotFlat) {
  const World& w = default_world();
  for (const ClassId c : {ClassId::kRoad, ClassId::kDirt, ClassId::kGrass, ClassId::kTree, ClassId::kBuilding, ClassId::kWater}) {
    cv::Mat mask = class_mask(w, c);
    // Away from class edges: variation within a class, not just between neighbours.
    cv::erode(mask, mask, cv::Mat::ones(5, 5, CV_8UC1));
    cv::Scalar mean, sd;
    cv::meanStdDev(w.albedo, mean, sd, mask);
    EXPECT_GT(sd[1], 4.0) << ClassTable::builtin().info(c).name << " green channel spread";
    // Local detail for stereo matching: neighbouring cells differ.
    cv::Mat grey, lap;
    cv::cvtColor(w.albedo, grey, cv::COLOR_RGB2GRAY);
    cv::Laplacian(grey, lap, CV_32F);
    cv::Scalar lm, lsd;
    cv::meanStdDev(lap, lm, lsd, mask);
    EXPECT_GT(lsd[0], 3.0) << ClassTable::builtin().info(c).name << " fine texture";
  }
  // Greens are green and water is blue-ish, in RGB order.
  const cv::Scalar grass = cv::mean(w.albedo, class_mask(w, ClassId::kGrass));
  EXPECT_GT(grass[1], grass[0]);
  EXPECT_GT(grass[1], grass[2]);
  const cv::Scalar water = cv::mean(w.albedo, class_mask(w, ClassId::kWater));
  EXPECT_GT(water[2], water[0]);
  // Road markings: bright paint on some road cells.
  cv::Mat bright;
  cv::inRange(w.albedo, cv::Scalar(170, 170, 150), cv::Scalar(255, 255, 255), bright);
  EXPECT_GT(cv::countNonZero(bright & class_mask(w, ClassId::kRoad)), 2000);
}

TEST(WorldGenerator, SizesFrom200mTo1km) {
  for (const auto& [size, res, targets] : std::vector<std::tuple<double, double, int>>{{200, 0.25, 13}, {1000, 0.25, 13}, {600, 0.5, 30}}) {
    GeneratorOptions o;
    o.seed = 3;
    o.size_m = size;
    o.resolution = res;
    o.targets = targets;
    std::vector<TargetCluster> t;
    const auto w = generate_world(o, &t);
    ASSERT_TRUE(w.ok()) << size << " m: " << w.error().message;
    EXPECT_EQ(w->grid().width, static_cast<int>(size / res));
    EXPECT_DOUBLE_EQ(w->grid().origin_x, -size / 2);
    EXPECT_DOUBLE_EQ(w->grid().origin_y, size / 2);
    EXPECT_EQ(t.size(), static_cast<std::size_t>(targets));
    EXPECT_EQ(group_vehicles(w.value(), 12.0).clusters, targets) << size << " m";
    EXPECT_EQ(w->class_at_xy(w->header.staging.x, w->header.staging.y), ClassId::kRoad);
  }
}

TEST(WorldGenerator, RejectsBadOptions) {
  for (const auto& mod : std::vector<void (*)(GeneratorOptions&)>{
           [](GeneratorOptions& o) { o.size_m = 50; }, [](GeneratorOptions& o) { o.resolution = 0; },
           [](GeneratorOptions& o) { o.targets = -1; }, [](GeneratorOptions& o) { o.size_m = 2000, o.resolution = 0.1; }}) {
    GeneratorOptions o;
    mod(o);
    const auto w = generate_world(o);
    ASSERT_FALSE(w.ok());
    EXPECT_EQ(w.error().code, ErrorCode::kInvalidArgument);
  }
  GeneratorOptions crowded = small_options(1);
  crowded.targets = 64;
  const auto w = generate_world(crowded);
  ASSERT_FALSE(w.ok());
  EXPECT_NE(w.error().message.find("target clusters"), std::string::npos) << w.error().message;
}

TEST(WorldGenerator, TargetsFileRoundTrip) {
  const std::string dir = fresh_dir("targets");
  ASSERT_TRUE(save_targets(default_targets(), default_world().header.staging, dir).ok());
  const auto t = load_targets(dir);
  ASSERT_TRUE(t.ok()) << t.error().message;
  EXPECT_DOUBLE_EQ(t->staging.x, default_world().header.staging.x);
  EXPECT_DOUBLE_EQ(t->staging.y, default_world().header.staging.y);
  ASSERT_EQ(t->targets.size(), default_targets().size());
  for (std::size_t i = 0; i < t->targets.size(); ++i) {
    const TargetCluster& a = t->targets[i];
    const TargetCluster& b = default_targets()[i];
    EXPECT_EQ(a.id, b.id);
    EXPECT_DOUBLE_EQ(a.x, b.x);
    EXPECT_DOUBLE_EQ(a.y, b.y);
    ASSERT_EQ(a.car_poses.size(), b.car_poses.size());
    for (std::size_t k = 0; k < a.car_poses.size(); ++k) {
      EXPECT_DOUBLE_EQ(a.car_poses[k].x, b.car_poses[k].x);
      EXPECT_DOUBLE_EQ(a.car_poses[k].yaw, b.car_poses[k].yaw);
    }
  }
}

TEST(WorldGenerator, BrokenTargetsFiles) {
  const auto write = [](const std::string& dir, const std::string& text) {
    fs::create_directories(dir);
    std::ofstream(fs::path(dir) / "targets.yaml") << text;
  };
  const std::string missing = fresh_dir("targets_missing");
  fs::create_directories(missing);
  auto r = load_targets(missing);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kIo);
  EXPECT_NE(r.error().message.find("targets.yaml"), std::string::npos);
  for (const std::string& text :
       {std::string("format_version: 1\nstaging: {x: 0, y: 0, yaw: 0}\ntargets:\n  - {id: 0, x: 1, y: 2, cars: 3, car_poses: [[1, 2, 0]]}\n"),
        std::string("format_version: 1\nstaging: {x: 0, y: 0, yaw: 0}\ntargets:\n  - {id: 0, x: 1, y: 2, cars: 1, car_poses: [[1, 2]]}\n"),
        std::string("format_version: 1\nstaging: {x: 0, y: 0}\ntargets: []\n"), std::string("format_version: 1\ntargets: [\n"),
        std::string("")}) {
    const std::string dir = fresh_dir("targets_bad");
    write(dir, text);
    r = load_targets(dir);
    ASSERT_FALSE(r.ok()) << text;
    EXPECT_EQ(r.error().code, ErrorCode::kMalformed) << r.error().message;
    EXPECT_NE(r.error().message.find("targets.yaml"), std::string::npos) << r.error().message;
  }
}

}  // namespace
}  // namespace ag::sim
