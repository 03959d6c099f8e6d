// The recorder stage in a role of synthetic sources (wheel odometry, GPS, LiDAR, map tiles, the
// localizer's pose, the scheduler's counters), run in lockstep: its MCAP files read back by @mcap/core
// hold the simulator's topics and schemas with what was published minus the drops it counted; small
// limits rotate files that are each complete and keep the newest under the total cap; a path that
// cannot take files stops the robot at start-up, naming it.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "airground/messages/messages.hpp"
#include "airground/drivers/recording/recorder/recorder_stage.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/status_stage.hpp"
#include "mcap_read.hpp"
#include "synthetic_role.hpp"

namespace ag {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using recording::RecorderStage;
using test::g_published;
using test::g_scan_points;
using test::Published;
using test::run_role;

std::string source_dir() {
  const char* e = std::getenv("AG_SOURCE_DIR");
  return e ? e : AG_TEST_SOURCE_DIR;
}

struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() / ("ag_recorder_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
};

std::vector<fs::path> mcap_files(const fs::path& dir) {
  std::vector<fs::path> v;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".mcap") v.push_back(e.path());
  std::sort(v.begin(), v.end());
  return v;
}

std::vector<std::uint8_t> base64_decode(const std::string& in) {
  static const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::vector<std::uint8_t> out;
  std::uint32_t acc = 0;
  int bits = 0;
  for (const char ch : in) {
    if (ch == '=') break;
    const std::size_t v = alphabet.find(ch);
    if (v == std::string::npos) continue;
    acc = (acc << 6) | static_cast<std::uint32_t>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<std::uint8_t>((acc >> bits) & 0xFFu));
    }
  }
  return out;
}

std::string reader() {
  std::string why;
  std::string s = test::mcap_reader_script(source_dir(), &why);
  EXPECT_FALSE(s.empty()) << why;
  return s;
}

TEST(RecorderStage, RecordsEveryChannelWithWhatWasPublishedMinusTheCountedDrops) {
  const std::string script = reader();
  if (script.empty()) return;
  TempDir dir;
  const fs::path rec = dir.path / "rec";  // created by the recorder
  auto run = run_role({"recorder.path=" + rec.string(), "recorder.gps_channel=gps", "recorder.lidar_every=2",
                       "recorder.lidar_column_stride=4", "recorder.scheduler_period_s=1", "recorder.camera_channel=camera",
                       "recorder.camera_period_s=1"},
                      6.0);
  ASSERT_TRUE(run.ok()) << run.error().message;
  const recording::RecorderCounters& c = run.value().counters;
  const Published p = g_published;
  EXPECT_EQ(c.write_errors, 0u);
  // The LiDAR outpaces the recorder (50 Hz into a ring of 2, drained at 10 Hz): drops, counted; the
  // slower channels lose nothing.
  EXPECT_GT(c.lidar.drops, p.lidar / 2);
  EXPECT_EQ(c.lidar.read + c.lidar.drops, p.lidar);
  EXPECT_EQ(c.odometry.drops, 0u);
  EXPECT_EQ(c.odometry.read, p.odometry);
  EXPECT_EQ(c.gps.read, p.gps);
  EXPECT_EQ(c.map_tiles.read, p.tiles);
  // Camera: 5 Hz into a ring of 4 drained at 10 Hz, nothing lost; one image a second kept (t = 0 .. 6 s).
  EXPECT_EQ(c.camera.read + c.camera.drops, p.images);
  EXPECT_EQ(c.camera.drops, 0u);
  EXPECT_EQ(c.camera.written, 7u);

  const auto files = mcap_files(rec);
  ASSERT_EQ(files.size(), 1u);
  const std::string name = files[0].filename().string();
  EXPECT_EQ(name.rfind("test-rob1-", 0), 0u) << name;
  EXPECT_EQ(name.substr(name.size() - 9), "-000.mcap") << name;
  EXPECT_EQ(name.size(), std::string("test-rob1-20261205T063000Z-000.mcap").size()) << name;

  const json j = test::read_mcap(script, files[0].string(), {"--dump", "/rob1/gps", "--dump", "/rob1/lidar/points", "--dump", "/rob1/camera/image", "--max", "2"});
  ASSERT_TRUE(j["ok"].get<bool>()) << j.dump();
  EXPECT_EQ(j["header"]["library"], "airground-recorder");
  EXPECT_TRUE(j["problems"].empty()) << j["problems"].dump();
  std::map<std::string, std::string> schema_of;
  for (const auto& ch : j["channels"]) schema_of[ch["topic"]] = ch["schema_name"];
  EXPECT_EQ(schema_of, (std::map<std::string, std::string>{{"/tf", "foxglove.FrameTransforms"},
                                                           {"/rob1/pose", "foxglove.PoseInFrame"},
                                                           {"/rob1/odometry", "foxglove.PoseInFrame"},
                                                           {"/rob1/gps", "foxglove.LocationFix"},
                                                           {"/rob1/lidar/points", "foxglove.PointCloud"},
                                                           {"/rob1/map_tiles", "foxglove.Grid"},
                                                           {"/rob1/camera/image", "foxglove.RawImage"},
                                                           {"/scheduler", "airground.SchedulerCounters"}}));
  const std::uint64_t lidar_written = (c.lidar.read + 1) / 2;  // every 2nd scan read
  EXPECT_EQ(c.lidar.written, lidar_written);
  const json want = {{"/rob1/odometry", p.odometry - c.odometry.drops},
                     {"/rob1/gps", p.gps - c.gps.drops},
                     {"/rob1/map_tiles", p.tiles - c.map_tiles.drops},
                     {"/rob1/lidar/points", lidar_written},
                     {"/rob1/pose", c.pose.written},
                     {"/tf", c.pose.written + lidar_written},
                     {"/rob1/camera/image", c.camera.written},
                     {"/scheduler", c.scheduler.written}};
  EXPECT_EQ(j["counts"], want);
  EXPECT_EQ(j["statistics"]["channel_message_counts"], want);
  // The latest-value pose: one per release of the 10 Hz source, as many as it published.
  EXPECT_EQ(c.pose.written, p.poses);
  EXPECT_GE(c.scheduler.written, 5u);
  // Contents: the fixes around the datum, the decimated cloud (every 4th column, 16 bytes a point).
  const auto& fixes = j["dumps"]["/rob1/gps"];
  ASSERT_EQ(fixes.size(), 2u);
  EXPECT_NEAR(fixes[0]["data"]["latitude"].get<double>(), 47.0, 1e-9);
  EXPECT_NEAR(fixes[0]["data"]["altitude"].get<double>(), 400.0, 1e-3);
  // 111 m north at 47 deg, 400 m up: 111 / (M + h) with the meridian radius M = 6369620.0 m (WGS-84), to 1 mm
  EXPECT_NEAR(fixes[1]["data"]["latitude"].get<double>() - fixes[0]["data"]["latitude"].get<double>(), 0.00099840055, 1e-8);
  EXPECT_NEAR(fixes[1]["data"]["longitude"].get<double>(), 8.0, 1e-9);
  const auto& cloud = j["dumps"]["/rob1/lidar/points"][0]["data"];
  EXPECT_EQ(cloud["frame_id"], "rob1/lidar");
  EXPECT_EQ(cloud["point_stride"], 16);
  const std::size_t b64 = cloud["data"].get<std::string>().size();
  EXPECT_EQ(b64, (g_scan_points / 4 * 16 + 2) / 3 * 4);
  // The image at half size, rgb8, its ramp averaged over 2x2 pixels: output column x holds columns 2x, 2x+1.
  const auto& image = j["dumps"]["/rob1/camera/image"][0]["data"];
  EXPECT_EQ(image["frame_id"], "rob1/camera");
  EXPECT_EQ(image["width"], 320);
  EXPECT_EQ(image["height"], 200);
  EXPECT_EQ(image["encoding"], "rgb8");
  EXPECT_EQ(image["step"], 960);
  const std::vector<std::uint8_t> px = base64_decode(image["data"].get<std::string>());
  ASSERT_EQ(px.size(), 320u * 200u * 3u);
  for (const std::size_t x : {0u, 1u, 100u, 319u}) {
    const auto a = static_cast<unsigned>(static_cast<double>(2 * x) / 2.5), b = static_cast<unsigned>(static_cast<double>(2 * x + 1) / 2.5);
    EXPECT_EQ(px[(57 * 320 + x) * 3], (2 + 2 * a + 2 * b) / 4) << x;
    EXPECT_EQ(px[(57 * 320 + x) * 3 + 1], 100);
    EXPECT_EQ(px[(57 * 320 + x) * 3 + 2], 200);
  }
}

TEST(RecorderStage, RotatesIntoCompleteFilesAndKeepsTheNewestUnderTheTotalCap) {
  const std::string script = reader();
  if (script.empty()) return;
  TempDir dir;
  // An older run of this robot (deleted first) and another robot's file (never touched).
  { std::ofstream(dir.path / "test-rob1-20000101T000000Z-000.mcap") << std::string(200'000, 'x'); }
  { std::ofstream(dir.path / "test-other-20000101T000000Z-000.mcap") << std::string(200'000, 'x'); }
  g_scan_points = 16384;  // 256 KiB of points a recorded scan (350 KB of JSON), stored uncompressed: ~2 a file
  auto run = run_role({"recorder.path=" + dir.path.string(), "recorder.max_file_mb=1", "recorder.max_total_mb=3", "recorder.zstd_level=0",
                       "recorder.lidar_every=1", "recorder.lidar_column_stride=1"},
                      4.0);
  g_scan_points = 2048;
  ASSERT_TRUE(run.ok()) << run.error().message;
  const recording::RecorderCounters& c = run.value().counters;
  EXPECT_EQ(c.write_errors, 0u);
  EXPECT_GT(c.files_opened, 10u);
  EXPECT_FALSE(fs::exists(dir.path / "test-rob1-20000101T000000Z-000.mcap"));
  EXPECT_TRUE(fs::exists(dir.path / "test-other-20000101T000000Z-000.mcap"));

  std::vector<fs::path> ours;
  std::uint64_t total = 0;
  for (const fs::path& f : mcap_files(dir.path))
    if (f.filename().string().rfind("test-rob1-2", 0) == 0 && f.filename().string().find("20000101") == std::string::npos) {
      ours.push_back(f);
      total += fs::file_size(f);
    }
  ASSERT_GE(ours.size(), 2u);
  EXPECT_LE(total, 3u << 20);
  EXPECT_EQ(c.files_deleted, c.files_opened - ours.size() + 1) << "the older run's file and every rotated file past the cap";
  // The newest survive: the last indexes, without a gap.
  for (std::size_t k = 0; k < ours.size(); ++k) {
    char idx[16];
    std::snprintf(idx, sizeof idx, "-%03llu.mcap", static_cast<unsigned long long>(c.files_opened - ours.size() + k));
    EXPECT_NE(ours[k].filename().string().find(idx), std::string::npos) << ours[k];
  }
  std::uint64_t scans = 0;
  for (const fs::path& f : ours) {
    EXPECT_LE(fs::file_size(f), (1u << 20) + (64u << 10)) << f << " past max_file_mb by more than its summary";
    const json j = test::read_mcap(script, f.string());
    ASSERT_TRUE(j["ok"].get<bool>()) << f << ": " << j.dump().substr(0, 400);
    EXPECT_TRUE(j["problems"].empty()) << f << j["problems"].dump();
    EXPECT_EQ(j["channels"].size(), 6u) << "every file declares every channel (no GPS here)";
    scans += j["counts"].value("/rob1/lidar/points", 0u);
  }
  EXPECT_GE(scans, ours.size());  // each kept file holds scans
}

TEST(RecorderStage, APathThatCannotTakeFilesStopsTheRobotAtStartNamingIt) {
  TempDir dir;
  const fs::path not_a_dir = dir.path / "plain-file";
  { std::ofstream(not_a_dir) << "x"; }
  auto run = run_role({"recorder.path=" + (not_a_dir / "rec").string()}, 0.1);
  ASSERT_FALSE(run.ok());
  EXPECT_NE(run.error().message.find("recorder.path"), std::string::npos) << run.error().message;
  EXPECT_NE(run.error().message.find((not_a_dir / "rec").string()), std::string::npos) << run.error().message;

  auto caps = run_role({"recorder.path=" + dir.path.string(), "recorder.max_file_mb=64", "recorder.max_total_mb=32"}, 0.1);
  ASSERT_FALSE(caps.ok());
  EXPECT_NE(caps.error().message.find("recorder.max_total_mb"), std::string::npos) << caps.error().message;
}

TEST(RecorderStage, OffWithoutAPathTapsNothingAndWritesNothing) {
  auto run = run_role({}, 1.0);
  ASSERT_TRUE(run.ok()) << run.error().message;
  const RecorderStage* rec = find_stage<RecorderStage>(run.value().robot.get());
  ASSERT_NE(rec, nullptr);
  EXPECT_FALSE(rec->enabled());
  EXPECT_EQ(run.value().counters.odometry.read, 0u);
}

}  // namespace
}  // namespace ag
