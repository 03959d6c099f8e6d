// recording.mcap of a team run, read back by the official MCAP readers (@mcap/core on node): every
// channel with Foxglove's schema, the counts recording.json reports, frames in the tree, and the same
// seed giving the same file.
#include <gtest/gtest.h>

#include <filesystem>
#include <set>
#include <fstream>
#include <sstream>

#include "../../mcap_reader/mcap_read.hpp"
#include "airground/sim/runner.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string source_dir() {
  const char* e = std::getenv("AG_SOURCE_DIR");
  return e ? e : AG_SOURCE_DIR;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

RunOptions small_run(const std::string& dir) {
  RunOptions o;
  o.out_dir = (fs::path(::testing::TempDir()) / dir).string();
  o.seed = 3;
  o.ugvs = 2;
  o.duration_s = 12;
  o.camera_scale = 0.25;
  o.camera_hz = 2;
  o.lidar_columns = 512;
  o.threads = 2;
  o.progress = false;
  return o;
}

TEST(TeamRecording, TheOfficialReaderSeesEveryChannelAndTheCountsTheRunReports) {
  std::string why;
  const std::string script = test::mcap_reader_script(source_dir(), &why);
  ASSERT_FALSE(script.empty()) << why;
  RunOptions o = small_run("rec_a");
  auto r = run_team(o);
  ASSERT_TRUE(r) << r.error().message;
  const fs::path file = fs::path(o.out_dir) / "recording.mcap";
  ASSERT_TRUE(fs::exists(file));
  const json j = test::read_mcap(script, file.string(),
                                 {"--dump", "/tf", "--dump", "/ugv1/lidar/points", "--dump", "/uav/camera/image", "--dump", "/radio", "--dump",
                                  "/ugv1/path", "--dump", "/mission/events", "--dump", "/scheduler", "--max", "3", "--expect",
                                  (fs::path(o.out_dir) / "recording.json").string()});
  ASSERT_TRUE(j.value("ok", false)) << j.dump().substr(0, 500);
  EXPECT_TRUE(j["problems"].empty()) << j["problems"].dump(1);  // with --expect: every count as recording.json says
  EXPECT_TRUE(j["data_section_crc_ok"].get<bool>());

  std::map<std::string, std::string> schema_of;
  for (const json& c : j["channels"]) schema_of[c.value("topic", std::string())] = c.value("schema_name", std::string());
  const std::map<std::string, std::string> want = {
      {"/tf", "foxglove.FrameTransforms"},          {"/uav/truth", "foxglove.PoseInFrame"},
      {"/uav/gps", "foxglove.LocationFix"},         {"/uav/camera/image", "foxglove.CompressedImage"},
      {"/uav/map_tiles", "foxglove.Grid"},          {"/ugv1/truth", "foxglove.PoseInFrame"},
      {"/ugv1/pose", "foxglove.PoseInFrame"},       {"/ugv1/odometry", "foxglove.PoseInFrame"},
      {"/ugv1/lidar/points", "foxglove.PointCloud"}, {"/ugv2/truth", "foxglove.PoseInFrame"},
      {"/ugv2/pose", "foxglove.PoseInFrame"},       {"/ugv2/odometry", "foxglove.PoseInFrame"},
      {"/ugv2/lidar/points", "foxglove.PointCloud"}, {"/ugv1/path", "foxglove.SceneUpdate"},
      {"/ugv2/path", "foxglove.SceneUpdate"},       {"/mission/regions", "foxglove.SceneUpdate"},
      {"/mission/events", "foxglove.Log"},          {"/radio", "airground.RadioTraffic"},
      {"/scheduler", "airground.SchedulerCounters"}};
  EXPECT_EQ(schema_of, want);
  // one encoding: every schema JSON Schema, every channel JSON
  for (const json& sc : j["schemas"]) EXPECT_EQ(sc["encoding"], "jsonschema") << sc["name"];
  for (const json& c : j["channels"]) EXPECT_EQ(c["message_encoding"], "json") << c["topic"];
  EXPECT_TRUE(j["schemaless"].empty()) << j["schemaless"].dump();

  // the counts the run reports (recording.json, RunSummary) are what the reader counts
  const json rep = json::parse(slurp(fs::path(o.out_dir) / "recording.json"));
  EXPECT_EQ(rep["channel_messages"], j["statistics"]["channel_message_counts"]);
  EXPECT_EQ(j["counts"], j["stream_counts"]);
  for (const auto& it : rep["channel_messages"].items()) EXPECT_EQ(j["counts"].value(it.key(), -1), it.value().get<int>()) << it.key();
  EXPECT_EQ(rep["messages"].get<std::uint64_t>(), r.value().recording_messages);
  EXPECT_EQ(j["statistics"]["message_count"].get<std::uint64_t>(), r.value().recording_messages);
  EXPECT_EQ(j["size"].get<std::uint64_t>(), r.value().recording_bytes);
  // 10 Hz poses over 0..12 s (121); camera every 5th frame of 25; scans every 20th of 121; radio every second
  EXPECT_EQ(j["counts"]["/uav/truth"], 121);
  EXPECT_EQ(j["counts"]["/ugv2/truth"], 121);
  EXPECT_EQ(j["counts"]["/tf"], 363);
  EXPECT_EQ(j["counts"]["/uav/camera/image"], 5);
  EXPECT_EQ(j["counts"]["/ugv1/lidar/points"], 7);
  EXPECT_EQ(j["counts"]["/radio"], 13);
  EXPECT_EQ(j["counts"]["/scheduler"], 2);
  // the simulator's routes (each robot's first leg at least), each robot's first mission state
  EXPECT_GE(j["counts"].value("/ugv1/path", 0), 1);
  EXPECT_GE(j["counts"].value("/mission/events", 0), 2);

  // radio traffic and scheduler counters under their own schemas: totals, per robot, per stage
  const json& radio = j["dumps"]["/radio"].back()["data"];
  EXPECT_GT(radio["link"]["sent"].get<std::uint64_t>(), 0u);
  std::set<std::string> robots;
  for (const json& rb : radio["robots"]) robots.insert(rb["robot"].get<std::string>());
  EXPECT_EQ(robots, (std::set<std::string>{"uav", "ugv1", "ugv2", "base"}));
  const json& sched = j["dumps"]["/scheduler"].back()["data"];  // at 10 s (the first, at 0 s, counts no run yet)
  ASSERT_FALSE(sched["stages"].empty());
  EXPECT_GT(sched["stages"][0]["runs"].get<std::uint64_t>(), 0u);
  bool drawn = false;  // a route with points, drawn in the map frame
  for (const json& m : j["dumps"]["/ugv1/path"])
    for (const json& e : m["data"]["entities"])
      if (e["frame_id"] == "map" && e["id"] == "ugv1/path" && !e["lines"].empty() && e["lines"][0]["points"].size() >= 2) drawn = true;
  EXPECT_TRUE(drawn) << j["dumps"]["/ugv1/path"].dump().substr(0, 400);
  EXPECT_EQ(j["dumps"]["/mission/events"][0]["data"]["name"], "ugv1");

  // the frame tree: map -> uav -> uav/camera, map -> ugvN -> ugvN/lidar
  std::set<std::pair<std::string, std::string>> edges;
  for (const json& m : j["dumps"]["/tf"])
    for (const json& tf : m["data"]["transforms"]) edges.emplace(tf.value("parent_frame_id", std::string()), tf.value("child_frame_id", std::string()));
  EXPECT_TRUE(edges.count({"map", "uav"}) && edges.count({"uav", "uav/camera"}) && edges.count({"map", "ugv2"}) && edges.count({"ugv2", "ugv2/lidar"})) << edges.size() << " edges";
  const json& cloud = j["dumps"]["/ugv1/lidar/points"][0]["data"];
  EXPECT_EQ(cloud["frame_id"], "ugv1/lidar");
  EXPECT_EQ(cloud["point_stride"], 16);
  EXPECT_GT(cloud["data"].get<std::string>().size(), 1000u);
  const json& img = j["dumps"]["/uav/camera/image"][0]["data"];
  EXPECT_EQ(img["format"], "jpeg");
  EXPECT_EQ(img["data"].get<std::string>().substr(0, 4), "/9j/") << "base64 of a JPEG's FF D8 FF";
}

TEST(TeamRecording, TheSameSeedGivesTheSameFileWithoutTheSchedulerChannel) {
  RunOptions a = small_run("rec_same_a");
  RunOptions b = small_run("rec_same_b");
  a.duration_s = b.duration_s = 6;
  a.record_scheduler_period_s = b.record_scheduler_period_s = 0;
  b.threads = 1;
  ASSERT_TRUE(run_team(a));
  ASSERT_TRUE(run_team(b));
  const std::string fa = slurp(fs::path(a.out_dir) / "recording.mcap"), fb = slurp(fs::path(b.out_dir) / "recording.mcap");
  EXPECT_GT(fa.size(), 10000u);
  EXPECT_TRUE(fa == fb) << "sizes " << fa.size() << " and " << fb.size();
}

std::vector<char> read_all(const fs::path& p) {
  const std::string s = slurp(p);
  return {s.begin(), s.end()};
}
void write_all(const fs::path& p, const std::vector<char>& b) {
  std::ofstream(p, std::ios::binary).write(b.data(), static_cast<std::streamsize>(b.size()));
}

TEST(TeamRecording, ACorruptedOrTruncatedRecordingIsReportedAsSuch) {
  std::string why;
  const std::string script = test::mcap_reader_script(source_dir(), &why);
  ASSERT_FALSE(script.empty()) << why;
  RunOptions o = small_run("rec_damaged");
  o.duration_s = 3;
  ASSERT_TRUE(run_team(o));
  const fs::path file = fs::path(o.out_dir) / "recording.mcap", bad = fs::path(o.out_dir) / "bad.mcap";
  const json good = test::read_mcap(script, file.string());
  ASSERT_TRUE(good.value("ok", false)) << good.dump().substr(0, 300);
  ASSERT_FALSE(good["chunks"].empty());
  const json& chunk = good["chunks"][0];
  const auto at = chunk["offset"].get<std::size_t>(), len = chunk["length"].get<std::size_t>();
  const std::vector<char> bytes = read_all(file);
  // a byte flipped in the chunk's compressed records, then in its CRC field (opcode 1 + length 8 + start
  // time 8 + end time 8 + uncompressed size 8 = byte 33): the chunk's CRC no longer matches
  for (const std::size_t k : {at + len / 2, at + len - 200, at + 33}) {
    std::vector<char> b = bytes;
    b[k] = static_cast<char>(b[k] ^ 0x20);
    write_all(bad, b);
    const json j = test::read_mcap(script, bad.string());
    EXPECT_FALSE(j.value("ok", true)) << "byte " << k;
    EXPECT_NE(j.value("exit_status", 0), 0);
    EXPECT_EQ(j.value("damage", std::string()), "corrupted") << j.dump();
    const std::string e = j.value("error", std::string());
    EXPECT_TRUE(e.find("CRC") != std::string::npos || e.find("decompression") != std::string::npos) << "byte " << k << ": " << e;
    if (k == at + 33) {
      EXPECT_NE(e.find("Incorrect chunk CRC"), std::string::npos) << e;
    }
  }
  // cut short (a crash): inside the data, and inside the footer
  for (const std::size_t keep : {bytes.size() / 2, bytes.size() - 5}) {
    write_all(bad, std::vector<char>(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(keep)));
    const json j = test::read_mcap(script, bad.string());
    EXPECT_FALSE(j.value("ok", true)) << "kept " << keep;
    EXPECT_EQ(j.value("damage", std::string()), "truncated") << j.dump();
  }
  // and a count the writer did not report is a problem the reader names
  json rep = json::parse(slurp(fs::path(o.out_dir) / "recording.json"));
  rep["channel_messages"]["/tf"] = rep["channel_messages"]["/tf"].get<int>() + 1;
  std::ofstream(fs::path(o.out_dir) / "wrong.json") << rep.dump();
  const json j = test::read_mcap(script, file.string(), {"--expect", (fs::path(o.out_dir) / "wrong.json").string()});
  ASSERT_EQ(j["problems"].size(), 1u) << j["problems"].dump();
  EXPECT_NE(j["problems"][0].get<std::string>().find("/tf"), std::string::npos);
}

TEST(TeamRecording, RecordNoneWritesNoRecording) {
  RunOptions o = small_run("rec_none");
  o.duration_s = 2;
  o.record = RecordLevel::kNone;
  fs::remove_all(o.out_dir);
  ASSERT_TRUE(run_team(o));
  EXPECT_FALSE(fs::exists(fs::path(o.out_dir) / "recording.mcap"));
}

}  // namespace
}  // namespace ag::sim
