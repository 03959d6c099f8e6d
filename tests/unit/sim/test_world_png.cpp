// Viewing pictures of a world: which files, display colours, scale bars, and never over a world's own files.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>

#include <unistd.h>

#include "airground/sim/generator.hpp"
#include "airground/sim/world_png.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

// Test files go under one directory per process (concurrent runs do not meet), removed at the end.
fs::path scratch_root() { return fs::path(::testing::TempDir()) / ("ag_world_png_" + std::to_string(::getpid())); }
class ScratchCleanup : public ::testing::Environment {
 public:
  void TearDown() override { fs::remove_all(scratch_root()); }
};
[[maybe_unused]] const ::testing::Environment* const kScratchCleanup = ::testing::AddGlobalTestEnvironment(new ScratchCleanup);

fs::path fresh_dir(const std::string& name) {
  const fs::path p = scratch_root() / name;
  fs::remove_all(p);
  return p;
}

const World& small_world() {
  static const World w = [] {
    GeneratorOptions o;
    o.seed = 11;
    o.size_m = 200;
    o.resolution = 0.5;
    o.targets = 4;
    return generate_world(o).value();
  }();
  return w;
}

TEST(WorldPng, ClassDisplayImageUsesTheTableColours) {
  cv::Mat ids(2, 3, CV_8UC1);
  ids.at<std::uint8_t>(0, 0) = 0;
  ids.at<std::uint8_t>(0, 1) = 6;
  ids.at<std::uint8_t>(0, 2) = 255;
  ids.at<std::uint8_t>(1, 0) = 5;
  ids.at<std::uint8_t>(1, 1) = 77;  // not in the table: black
  ids.at<std::uint8_t>(1, 2) = 2;
  const cv::Mat rgb = class_display_image(ids);
  ASSERT_EQ(rgb.type(), CV_8UC3);
  EXPECT_EQ(rgb.at<cv::Vec3b>(0, 0), cv::Vec3b(128, 64, 128));
  EXPECT_EQ(rgb.at<cv::Vec3b>(0, 1), cv::Vec3b(40, 110, 210));
  EXPECT_EQ(rgb.at<cv::Vec3b>(0, 2), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(rgb.at<cv::Vec3b>(1, 0), cv::Vec3b(230, 40, 40));
  EXPECT_EQ(rgb.at<cv::Vec3b>(1, 1), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(rgb.at<cv::Vec3b>(1, 2), cv::Vec3b(110, 190, 60));
}

TEST(WorldPng, WritesThePicturesAndTheirRanges) {
  const World& w = small_world();
  const fs::path dir = fresh_dir("pictures");
  const auto s = write_world_pngs(w, dir.string());
  ASSERT_TRUE(s.ok()) << s.error().message;
  const int n = w.grid().width;
  const cv::Mat cls = cv::imread((dir / "class.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(cls.type(), CV_8UC3);
  ASSERT_EQ(cls.size(), cv::Size(n, n));
  std::set<std::tuple<int, int, int>> allowed;
  for (const ClassInfo& c : ClassTable::builtin().all()) allowed.emplace(c.color.b, c.color.g, c.color.r);  // BGR on disk
  for (int r = 0; r < n; r += 7) {
    for (int c = 0; c < n; c += 7) {
      const cv::Vec3b p = cls.at<cv::Vec3b>(r, c);
      ASSERT_TRUE(allowed.count({p[0], p[1], p[2]})) << c << "," << r;
    }
  }
  const cv::Mat albedo = cv::imread((dir / "albedo.png").string(), cv::IMREAD_COLOR);
  ASSERT_EQ(albedo.size(), cv::Size(n, n));
  cv::Mat rgb;
  cv::cvtColor(albedo, rgb, cv::COLOR_BGR2RGB);
  EXPECT_EQ(cv::norm(rgb, w.albedo, cv::NORM_INF), 0.0);
  for (const char* f : {"height.png", "terrain.png"}) {
    const cv::Mat img = cv::imread((dir / f).string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(img.empty()) << f;
    EXPECT_EQ(img.rows, n) << f;
    EXPECT_GT(img.cols, n + 40) << f << " carries a scale bar on its right";
  }
  const cv::Mat shade = cv::imread((dir / "hillshade.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(shade.type(), CV_8UC1);
  ASSERT_EQ(shade.size(), cv::Size(n, n));
  cv::Scalar mean, sd;
  cv::meanStdDev(shade, mean, sd);
  EXPECT_GT(sd[0], 5.0) << "relief is visible";
  EXPECT_FALSE(cv::imread((dir / "legend.png").string()).empty());
  std::ifstream side(dir / "pngs.yaml");
  std::stringstream text;
  text << side.rdbuf();
  EXPECT_NE(text.str().find("height.png: {what: object height above terrain, unit: m, min: 0.00, max: "), std::string::npos) << text.str();
  EXPECT_NE(text.str().find("terrain.png:"), std::string::npos);
}

TEST(WorldPng, RefusesAWorldDirectory) {
  const World& w = small_world();
  const fs::path dir = fresh_dir("world_dir");
  ASSERT_TRUE(save_world(w, dir.string()).ok());
  const auto s = write_world_pngs(w, dir.string());
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("world.yaml"), std::string::npos) << s.error().message;
  EXPECT_TRUE(load_world(dir.string()).ok()) << "the world is untouched";
}

}  // namespace
}  // namespace ag::sim
