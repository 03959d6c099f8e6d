// Mapping mission: a quadrotor surveys a generated 200 m world through the real UAV stages in the
// lockstep runner, with one odometry tracking loss mid-flight and one GPS fix 50 m off, and the map it
// builds is scored against the world (issue 4). The exported GeoTIFF is read back with GDAL's gdalinfo.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include <yaml-cpp/yaml.h>

#include "airground/sim/eval_mapping.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

// Issue 4's goals: 0.5 m (flat ground) and 1.5 m (every cell). Measured on this mission (docs/mapping.md):
// 0.28 m and 0.54 m since min_elevation_points is 32 (0.56 m and 0.92 m with 16).
constexpr double kElevationGroundBoundM = 0.5;
constexpr double kElevationAllBoundM = 1.5;

fs::path out_root() {
  const char* b = std::getenv("AG_BINARY_DIR");
  return fs::path(b != nullptr ? b : fs::temp_directory_path().string()) / "mission-mapping";
}

std::string run_command(const std::string& cmd) {
  std::string out;
  std::unique_ptr<FILE, int (*)(FILE*)> p(popen(cmd.c_str(), "r"), pclose);
  if (!p) return out;
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), static_cast<int>(buf.size()), p.get()) != nullptr) out += buf.data();
  return out;
}

class MappingMission : public testing::Test {
 protected:
  static void SetUpTestSuite() {
    const fs::path root = out_root();
    fs::create_directories(root);
    GeneratorOptions g;
    g.seed = 7;
    g.size_m = 200;
    auto w = generate_world(g);
    ASSERT_TRUE(w.ok()) << w.error().message;
    const fs::path world_dir = root / "world";
    ASSERT_TRUE(save_world(w.value(), world_dir.string()).ok());

    // The user's model folder (section form, as `airground-sim config --out` writes it): the odometry
    // starts at scale 3 (issue 4: the map must not care), and the evaluation's fault injection below
    // must be merged into that file, not replace it or be lost.
    const fs::path models = root / "user-models";
    fs::create_directories(models);
    {
      std::ofstream f(models / "visual_odometry.yaml");
      f << "visual_odometry:\n  scale_min: 3\n  scale_max: 3\n";
    }
    EvalMappingOptions o;
    // An ablation by name: the two faults are injected into the simulator's VO model (a forced tracking
    // loss, a start at scale 3), which only the oracle VO has. Field mode: MappingMissionField below.
    o.oracles = {"vo"};
    o.config_dir = models.string();
    o.world = world_dir.string();
    o.seed = 3;
    o.out_dir = (root / "faults").string();
    o.random_faults = false;       // exactly the two faults below
    o.tracking_loss_at_s = 70;     // mid-flight (the survey takes about 3 minutes)
    o.gps_outlier_at_s = 100;
    o.gps_outlier_m = 50;
    o.quiet = true;
    auto m = eval_mapping(o);
    ASSERT_TRUE(m.ok()) << m.error().message;
    metrics_ = new MappingMetrics(m.value());
    out_dir_ = new std::string(o.out_dir);
  }
  static void TearDownTestSuite() {
    delete metrics_;
    delete out_dir_;
  }
  static MappingMetrics* metrics_;
  static std::string* out_dir_;
};

MappingMetrics* MappingMission::metrics_ = nullptr;
std::string* MappingMission::out_dir_ = nullptr;

// The checks of the one mission (one test case: ctest runs each case in its own process, and the
// mission is the expensive part).

void both_faults_happened_and_were_handled(const MappingMetrics* metrics_) {
  ASSERT_NE(metrics_, nullptr);
  EXPECT_GE(metrics_->vo_segments, 2u) << "the forced tracking loss must start a new odometry segment";
  EXPECT_GE(metrics_->gps_rejected, 1u) << "the 50 m outlier must be gated out";
  EXPECT_GT(metrics_->keyframes, 150u);
}

void map_stays_within_the_bounds_through_the_faults(const MappingMetrics* metrics_) {
  ASSERT_NE(metrics_, nullptr);
  const MappingMetrics& m = *metrics_;
  EXPECT_GE(m.map_class_accuracy, 0.95);
  EXPECT_GE(m.map_coverage, 0.90);
  EXPECT_LE(m.georeg_error_m, 0.5);
  EXPECT_LE(m.scale_error, 0.01);
  // Issue 4 asks for 0.5 m (ground) and 1.5 m (all cells); see docs/benchmarks.md for where we are.
  EXPECT_LE(m.elevation_rmse_ground_m, kElevationGroundBoundM);
  EXPECT_LE(m.elevation_rmse_m, kElevationAllBoundM);
}

void gdalinfo_reads_the_exported_crs_and_geotransform(const std::string* out_dir_) {
  ASSERT_NE(out_dir_, nullptr);
  for (const char* name : {"map_class.tif", "map_elevation.tif", "map_rgb.tif"}) {
    const fs::path tif = fs::path(*out_dir_) / name;
    ASSERT_TRUE(fs::exists(tif)) << tif;
    const std::string info = run_command("gdalinfo '" + tif.string() + "' 2>&1");
    EXPECT_NE(info.find("Driver: GTiff/GeoTIFF"), std::string::npos) << info;
    EXPECT_NE(info.find("UTM zone"), std::string::npos) << info;
    EXPECT_NE(info.find("ID[\"EPSG\",326"), std::string::npos) << info;
    // The map frame is local ENU; UTM grid north differs from true north by the meridian convergence, so
    // the geotransform is a 0.5 m rotated grid: GDAL prints its six terms instead of origin and pixel size.
    const std::size_t gt = info.find("GeoTransform =");
    ASSERT_NE(gt, std::string::npos) << info;
    double t[6] = {};
    ASSERT_EQ(std::sscanf(info.c_str() + gt, "GeoTransform = %lf, %lf, %lf %lf, %lf, %lf", &t[0], &t[1], &t[2], &t[3], &t[4], &t[5]), 6)
        << info.substr(gt, 200);
    EXPECT_NEAR(std::hypot(t[1], t[4]), 0.5, 1e-3) << "column step is one 0.5 m cell";
    EXPECT_NEAR(std::hypot(t[2], t[5]), 0.5, 1e-3) << "row step is one 0.5 m cell";
    EXPECT_LT(t[5], 0.0) << "north up: rows go south";
    EXPECT_GT(t[0], 166000.0) << "UTM easting";
    EXPECT_LT(t[0], 834000.0) << "UTM easting";
  }
  const std::string elev = run_command("gdalinfo '" + (fs::path(*out_dir_) / "map_elevation.tif").string() + "' 2>&1");
  EXPECT_NE(elev.find("Type=Float32"), std::string::npos) << elev;
  EXPECT_NE(elev.find("NoData Value=nan"), std::string::npos) << elev;
  const std::string rgb = run_command("gdalinfo '" + (fs::path(*out_dir_) / "map_rgb.tif").string() + "' 2>&1");
  EXPECT_NE(rgb.find("Band 3"), std::string::npos) << rgb;
}

// The models folder the run used: the user's keys kept under their section, the faults added to it.
void the_fault_injection_merged_into_the_users_model_file(const std::string* out_dir_) {
  ASSERT_NE(out_dir_, nullptr);
  const YAML::Node vo = YAML::LoadFile((fs::path(*out_dir_) / "models" / "visual_odometry.yaml").string());
  ASSERT_TRUE(vo["visual_odometry"].IsMap());
  EXPECT_DOUBLE_EQ(vo["visual_odometry"]["scale_min"].as<double>(), 3.0);
  EXPECT_DOUBLE_EQ(vo["visual_odometry"]["scale_max"].as<double>(), 3.0);
  EXPECT_DOUBLE_EQ(vo["visual_odometry"]["forced_loss_at_s"].as<double>(), 70.0);
  EXPECT_DOUBLE_EQ(vo["visual_odometry"]["tracking_loss_rate_per_s"].as<double>(), 0.0);
  EXPECT_EQ(vo.size(), 1u) << "one section, no stray top-level keys";
  const YAML::Node gps = YAML::LoadFile((fs::path(*out_dir_) / "models" / "gps.yaml").string());
  EXPECT_DOUBLE_EQ(gps["gps"]["outlier_m"].as<double>(), 50.0);
}

TEST_F(MappingMission, BothFaultsAreHandledTheMapStaysWithinBoundsAndGdalReadsTheExport) {
  {
    SCOPED_TRACE("the fault injection merged into the user's model file");
    the_fault_injection_merged_into_the_users_model_file(out_dir_);
  }
  {
    SCOPED_TRACE("both faults happened and were handled");
    both_faults_happened_and_were_handled(metrics_);
  }
  {
    SCOPED_TRACE("the map stays within the bounds through the faults");
    map_stays_within_the_bounds_through_the_faults(metrics_);
  }
  {
    SCOPED_TRACE("gdalinfo reads the exported CRS and geotransform");
    gdalinfo_reads_the_exported_crs_and_geotransform(out_dir_);
  }
}

// A user model file the fault injection cannot merge into is refused before any flight, naming it.
// Field mode: the quadrotor's own vo stage on the rendered frames with the simulated autopilot's attitude
// (no oracle), on the same world, no injected faults: issue 4's goals still hold (issue 24). Measured
// 2026-12-05: class 0.984, coverage 0.943, ground RMSE 0.300 m, all cells 0.512 m, georeg 0.136 m,
// scale error 0.0004, one VO segment.
TEST(MappingMissionField, TheQuadrotorsOwnOdometryMapsWithinIssue4sGoals) {
  const fs::path root = out_root() / "field";
  fs::create_directories(root);
  GeneratorOptions g;
  g.seed = 7;
  g.size_m = 200;
  auto w = generate_world(g);
  ASSERT_TRUE(w.ok()) << w.error().message;
  ASSERT_TRUE(save_world(w.value(), (root / "world").string()).ok());
  EvalMappingOptions o;
  o.world = (root / "world").string();
  o.seed = 3;
  o.out_dir = (root / "out").string();
  o.random_faults = false;
  o.quiet = true;
  auto r = eval_mapping(o);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const MappingMetrics& m = r.value();
  EXPECT_GE(m.map_class_accuracy, 0.95);
  EXPECT_GE(m.map_coverage, 0.90);
  EXPECT_LE(m.georeg_error_m, 0.5);
  EXPECT_LE(m.scale_error, 0.01);
  EXPECT_LE(m.elevation_rmse_ground_m, kElevationGroundBoundM);
  EXPECT_LE(m.elevation_rmse_m, kElevationAllBoundM);
  EXPECT_EQ(m.vo_segments, 1u) << "the survey should not lose tracking";
  EXPECT_GT(m.keyframes, 150u);
  std::ifstream j(fs::path(o.out_dir) / "metrics.json");
  std::string text;
  std::getline(j, text, '\0');
  EXPECT_NE(text.find("\"oracles\": []"), std::string::npos) << "field mode lists no oracle";
}

// The oracle VO's own user-model check.
TEST(MappingEvalModels, AMalformedUserModelFileIsAClearErrorNamingIt) {
  const fs::path root = out_root() / "bad-models";
  fs::create_directories(root / "user-models");
  {
    std::ofstream f(root / "user-models" / "visual_odometry.yaml");
    f << "visual_odometry:\n  scale_min: [3\n";  // an unclosed list
  }
  EvalMappingOptions o;
  o.config_dir = (root / "user-models").string();
  o.out_dir = (root / "out").string();
  o.tracking_loss_at_s = 10;
  o.oracles = {"vo"};
  o.quiet = true;
  auto m = eval_mapping(o);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.error().message.find("visual_odometry.yaml"), std::string::npos) << m.error().message;
  EXPECT_NE(m.error().message.find("malformed YAML"), std::string::npos) << m.error().message;
}

}  // namespace
}  // namespace ag::sim
