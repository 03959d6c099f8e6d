// recording.mcap of the evaluations (eval vo: its own flight loop; eval mapping: the team runner with
// recording.mcap only), read back by the official MCAP readers (@mcap/core, @mcap/support on node) and
// compared with what recording.json reports; --record none writes none.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>

#include "../../mcap_reader/mcap_read.hpp"
#include "airground/sim/eval_mapping.hpp"
#include "airground/sim/eval_vo.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string source_dir() {
  const char* e = std::getenv("AG_SOURCE_DIR");
  return e ? e : AG_SOURCE_DIR;
}

// Reads DIR/recording.mcap back; expects it whole, with the counts of DIR/recording.json.
json read_back(const std::string& script, const fs::path& dir) {
  const json j = test::read_mcap(script, (dir / "recording.mcap").string(), {"--expect", (dir / "recording.json").string(), "--dump", "/tf", "--max", "1"});
  EXPECT_TRUE(j.value("ok", false)) << j.dump().substr(0, 400);
  EXPECT_TRUE(j.value("problems", json::array()).empty()) << j["problems"].dump(1);
  EXPECT_TRUE(j.value("schemaless", json::array()).empty()) << j["schemaless"].dump();
  return j;
}

std::map<std::string, std::string> schemas_of(const json& j) {
  std::map<std::string, std::string> m;
  for (const json& c : j["channels"]) m[c.value("topic", std::string())] = c.value("schema_name", std::string());
  return m;
}

TEST(EvalRecording, EvalVoRecordsTheTrueFlightAndTheCameraFrames) {
  std::string why;
  const std::string script = test::mcap_reader_script(source_dir(), &why);
  ASSERT_FALSE(script.empty()) << why;
  EvalVoOptions o;
  o.out_dir = (fs::path(::testing::TempDir()) / "eval_vo_rec").string();
  o.max_duration_s = 6;
  o.quiet = true;
  auto m = eval_vo(o);
  ASSERT_TRUE(m) << m.error().message;
  const json j = read_back(script, o.out_dir);
  const auto schema = schemas_of(j);
  EXPECT_EQ(schema.at("/tf"), "foxglove.FrameTransforms");
  EXPECT_EQ(schema.at("/uav/truth"), "foxglove.PoseInFrame");
  EXPECT_EQ(schema.at("/uav/camera/image"), "foxglove.CompressedImage");
  EXPECT_EQ(schema.count("/scheduler"), 0u) << "eval vo has no stages of a robot";
  EXPECT_EQ(schema.count("/mission/regions"), 0u);
  // 10 Hz truth over 6 s (the first at 0.02 s), every 5th of the 5 Hz frames
  EXPECT_NEAR(j["counts"].value("/uav/truth", 0), 60, 1);
  EXPECT_EQ(j["counts"].value("/uav/camera/image", 0), static_cast<int>((m.value().frames + 4) / 5));
  EXPECT_EQ(j["counts"].value("/tf", 0), j["counts"].value("/uav/truth", -1));

  o.record = false;
  o.out_dir += "_none";
  ASSERT_TRUE(eval_vo(o));
  EXPECT_TRUE(fs::exists(fs::path(o.out_dir) / "metrics.json"));
  EXPECT_FALSE(fs::exists(fs::path(o.out_dir) / "recording.mcap"));
}

TEST(EvalRecording, EvalMappingWritesTheRecordingAndNoCsvStreams) {
  std::string why;
  const std::string script = test::mcap_reader_script(source_dir(), &why);
  ASSERT_FALSE(script.empty()) << why;
  EvalMappingOptions o;
  o.out_dir = (fs::path(::testing::TempDir()) / "eval_mapping_rec").string();
  fs::remove_all(o.out_dir);
  o.max_duration_s = 12;
  o.oracles = {"labels"};  // no ErfNet: the recording, not the labels, is under test
  o.quiet = true;
  auto m = eval_mapping(o);
  ASSERT_TRUE(m) << m.error().message;
  const json j = read_back(script, o.out_dir);
  const auto schema = schemas_of(j);
  EXPECT_EQ(schema.at("/uav/map_tiles"), "foxglove.Grid");
  EXPECT_EQ(schema.at("/uav/gps"), "foxglove.LocationFix");
  EXPECT_EQ(schema.at("/mission/regions"), "foxglove.SceneUpdate");
  EXPECT_EQ(schema.at("/scheduler"), "airground.SchedulerCounters");
  EXPECT_EQ(j["counts"].value("/uav/truth", 0), 121);
  EXPECT_GE(j["counts"].value("/uav/camera/image", 0), 10);
  EXPECT_GE(j["counts"].value("/scheduler", 0), 1);
  // recording.mcap only: no CSV streams, no PNG frames (RecordLevel::kMcap)
  EXPECT_FALSE(fs::exists(fs::path(o.out_dir) / "truth_uav.csv"));
  const fs::path frames = fs::path(o.out_dir) / "camera";
  EXPECT_TRUE(!fs::exists(frames) || fs::is_empty(frames));
}

}  // namespace
}  // namespace ag::sim
