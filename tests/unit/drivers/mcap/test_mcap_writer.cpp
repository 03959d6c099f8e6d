// The MCAP writer against the official readers: files with Foxglove JSON channels, several zstd chunks
// and metadata are read back by @mcap/core (indexed and stream readers, CRCs validated), and their
// schemas, channels, counts and contents compared with what was written; truncated and corrupted files
// are refused.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "airground/drivers/recording/mcap/foxglove_json.hpp"
#include "airground/drivers/recording/mcap/mcap_writer.hpp"
#include "mcap_read.hpp"

namespace ag {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string source_dir() {
  const char* e = std::getenv("AG_SOURCE_DIR");
  return e ? e : AG_TEST_SOURCE_DIR;
}

struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() / ("ag_mcap_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
  [[nodiscard]] std::string file(const std::string& n) const { return (path / n).string(); }
};

std::string reader() {
  std::string why;
  std::string s = test::mcap_reader_script(source_dir(), &why);
  EXPECT_FALSE(s.empty()) << why;
  return s;
}

std::vector<std::uint8_t> read_bytes(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}
void write_bytes(const std::string& p, const std::vector<std::uint8_t>& b) {
  std::ofstream f(p, std::ios::binary);
  f.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

std::vector<std::uint8_t> unbase64(const std::string& s) {
  auto v = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    return c == '+' ? 62 : c == '/' ? 63 : -1;
  };
  std::vector<std::uint8_t> out;
  std::uint32_t acc = 0;
  int bits = 0;
  for (char c : s) {
    const int d = v(c);
    if (d < 0) break;
    acc = (acc << 6) | static_cast<std::uint32_t>(d);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<std::uint8_t>(acc >> bits));
    }
  }
  return out;
}

// The points of scan k: 3 floats each, values that identify scan and point.
std::vector<std::uint8_t> cloud_bytes(int k, int n) {
  std::vector<float> xyz;
  for (int i = 0; i < n; ++i) {
    xyz.push_back(static_cast<float>(k) + 0.5f);
    xyz.push_back(static_cast<float>(i) * 0.25f);
    xyz.push_back(-1.0f * static_cast<float>(i));
  }
  std::vector<std::uint8_t> b(xyz.size() * 4);
  std::memcpy(b.data(), xyz.data(), b.size());
  return b;
}

// A recording like the simulator's: poses at 50 Hz, transforms, point clouds at 10 Hz, a grid, a log
// channel, a schemaless counters channel; small chunks so there are many.
struct Written {
  std::uint64_t poses{0}, tfs{0}, clouds{0}, grids{0}, logs{0}, counters{0};
  mcap::WriterStats stats;
};
Written write_sample(const std::string& path, const mcap::WriterOptions& opt, int seconds = 20) {
  Written w;
  mcap::McapWriter m;
  EXPECT_TRUE(m.open(path, opt));
  auto sch = [&](const char* n) { return m.add_schema(n, foxglove::kSchemaEncoding, foxglove::schema(n)); };
  const std::uint16_t s_pose = sch("foxglove.PoseInFrame"), s_tf = sch("foxglove.FrameTransforms"), s_pc = sch("foxglove.PointCloud"),
                      s_grid = sch("foxglove.Grid"), s_log = sch("foxglove.Log");
  const std::uint16_t c_pose = m.add_channel(s_pose, "/uav/pose", "json", {{"robot", "uav"}});
  const std::uint16_t c_tf = m.add_channel(s_tf, "/tf", "json");
  const std::uint16_t c_pc = m.add_channel(s_pc, "/ugv1/lidar", "json");
  const std::uint16_t c_grid = m.add_channel(s_grid, "/map/class", "json");
  const std::uint16_t c_log = m.add_channel(s_log, "/log", "json");
  const std::uint16_t c_cnt = m.add_channel(0, "/counters", "json");
  EXPECT_TRUE(m.add_metadata("run", {{"seed", "1"}, {"world", "default"}}));
  for (int k = 0; k < seconds * 50; ++k) {
    const std::uint64_t t = static_cast<std::uint64_t>(k) * 20'000'000u;
    const double x = 0.1 * k;
    EXPECT_TRUE(m.write(c_pose, t, foxglove::pose_in_frame(t, "map", {{x, -2.0 * x, 40}, foxglove::quat_from_rpy(0, 0, 0.5)})));
    ++w.poses;
    if (k % 5 == 0) {
      EXPECT_TRUE(m.write(c_tf, t, foxglove::frame_transforms(t, {{"map", "uav", {x, 0, 40}, {}}, {"uav", "uav/camera", {0, 0, -0.1}, foxglove::quat_from_rpy(3.14159, 0, 0)}})));
      ++w.tfs;
      const std::vector<std::uint8_t> pts = cloud_bytes(k / 5, 64);
      EXPECT_TRUE(m.write(c_pc, t, foxglove::point_cloud(t, "ugv1/lidar", {}, 12,
                                                         {{"x", 0, foxglove::NumericType::kFloat32}, {"y", 4, foxglove::NumericType::kFloat32},
                                                          {"z", 8, foxglove::NumericType::kFloat32}}, pts)));
      ++w.clouds;
    }
    if (k % 250 == 0) {
      std::vector<std::uint8_t> cells(32 * 16);
      for (std::size_t i = 0; i < cells.size(); ++i) cells[i] = static_cast<std::uint8_t>((i + static_cast<std::size_t>(k)) % 7);
      EXPECT_TRUE(m.write(c_grid, t, foxglove::grid(t, "map", {{-8, -4, 0}, {}}, 32, 0.5, 0.5, 32, 1, {{"class", 0, foxglove::NumericType::kUint8}}, cells)));
      ++w.grids;
      EXPECT_TRUE(m.write(c_log, t, foxglove::log(t, foxglove::LogLevel::kInfo, "sim", "tick \"" + std::to_string(k) + "\"\n")));
      ++w.logs;
      EXPECT_TRUE(m.write(c_cnt, t, "{\"stage\":\"status\",\"runs\":" + std::to_string(k) + "}"));
      ++w.counters;
    }
  }
  EXPECT_TRUE(m.close());
  w.stats = m.stats();
  return w;
}

mcap::WriterOptions small_chunks() {
  mcap::WriterOptions o;
  o.chunk_size_bytes = 16 * 1024;
  return o;
}

TEST(Mcap, Crc32AndBase64MatchTheirStandards) {
  const std::string check = "123456789";
  EXPECT_EQ(mcap::crc32({reinterpret_cast<const std::uint8_t*>(check.data()), check.size()}), 0xCBF43926u);
  // running value: crc(a + b) from crc(a)
  const std::uint32_t a = mcap::crc32({reinterpret_cast<const std::uint8_t*>(check.data()), 4});
  EXPECT_EQ(mcap::crc32({reinterpret_cast<const std::uint8_t*>(check.data()) + 4, 5}, a), 0xCBF43926u);
  auto b64 = [](std::string_view s) { return mcap::base64({reinterpret_cast<const std::uint8_t*>(s.data()), s.size()}); };
  EXPECT_EQ(b64(""), "");  // RFC 4648 section 10
  EXPECT_EQ(b64("f"), "Zg==");
  EXPECT_EQ(b64("fo"), "Zm8=");
  EXPECT_EQ(b64("foo"), "Zm9v");
  EXPECT_EQ(b64("foob"), "Zm9vYg==");
  EXPECT_EQ(b64("foobar"), "Zm9vYmFy");
  const std::vector<std::uint8_t> hi{0xFB, 0xFF, 0xBF};
  EXPECT_EQ(mcap::base64(hi), "+/+/");
}

TEST(Mcap, TheOfficialReaderSeesEveryChannelSchemaAndMessageWritten) {
  const std::string script = reader();
  ASSERT_FALSE(script.empty());
  TempDir dir;
  const std::string path = dir.file("a.mcap");
  const Written w = write_sample(path, small_chunks());
  ASSERT_GT(w.stats.chunks, 3u) << "the sample should span several chunks";
  const json j = test::read_mcap(script, path);
  ASSERT_TRUE(j.value("ok", false)) << j.dump();
  EXPECT_EQ(j["header"]["library"], "airground-mcap");
  EXPECT_EQ(j["size"].get<std::uint64_t>(), w.stats.bytes);
  EXPECT_EQ(j["size"].get<std::uint64_t>(), fs::file_size(path));

  // schemas: Foxglove's names, jsonschema, our text byte for byte
  ASSERT_EQ(j["schemas"].size(), 5u);
  for (const json& s : j["schemas"]) {
    EXPECT_EQ(s["encoding"], "jsonschema");
    EXPECT_EQ(s["data"].get<std::string>(), foxglove::schema(s["name"].get<std::string>())) << s["name"];
    const json parsed = json::parse(s["data"].get<std::string>());
    EXPECT_EQ(parsed["title"], s["name"]);
  }
  // channels with their schema and metadata
  std::map<std::string, std::string> schema_of;
  for (const json& c : j["channels"]) schema_of[c["topic"]] = c["schema_name"];
  EXPECT_EQ(schema_of, (std::map<std::string, std::string>{{"/uav/pose", "foxglove.PoseInFrame"}, {"/tf", "foxglove.FrameTransforms"},
                                                           {"/ugv1/lidar", "foxglove.PointCloud"}, {"/map/class", "foxglove.Grid"},
                                                           {"/log", "foxglove.Log"}, {"/counters", ""}}));
  for (const json& c : j["channels"]) {
    EXPECT_EQ(c["message_encoding"], "json");
    if (c["topic"] == "/uav/pose") {
      EXPECT_EQ(c["metadata"], (json{{"robot", "uav"}}));
    }
  }
  // counts: the statistics record, the indexes and the stream all agree with what was written
  const json want = {{"/uav/pose", w.poses}, {"/tf", w.tfs}, {"/ugv1/lidar", w.clouds}, {"/map/class", w.grids}, {"/log", w.logs}, {"/counters", w.counters}};
  EXPECT_EQ(j["statistics"]["channel_message_counts"], want);
  EXPECT_EQ(j["counts"], want);
  EXPECT_EQ(j["stream_counts"], want);
  EXPECT_EQ(j["statistics"]["message_count"].get<std::uint64_t>(), w.stats.messages);
  EXPECT_EQ(j["statistics"]["chunk_count"].get<std::uint64_t>(), w.stats.chunks);
  EXPECT_EQ(j["statistics"]["schema_count"], 5);
  EXPECT_EQ(j["statistics"]["channel_count"], 6);
  EXPECT_EQ(j["statistics"]["metadata_count"], 1);
  EXPECT_EQ(j["statistics"]["message_start_time"], 0);
  EXPECT_EQ(j["statistics"]["message_end_time"].get<std::uint64_t>(), (w.poses - 1) * 20'000'000u);
  EXPECT_EQ(j["chunk_indexes"].get<std::uint64_t>(), w.stats.chunks);
  EXPECT_EQ(j["chunk_compression"], json::array({"zstd"}));
  EXPECT_EQ(j["records"]["Chunk"].get<std::uint64_t>(), w.stats.chunks);
  EXPECT_GE(j["records"]["MessageIndex"].get<std::uint64_t>(), w.stats.chunks);
  EXPECT_EQ(j["records"]["Footer"], 1);
  EXPECT_EQ(j["records"]["DataEnd"], 1);
  // summary offsets for Schema (3), Channel (4), ChunkIndex (8), Statistics (11), MetadataIndex (13)
  EXPECT_EQ(j["summary_offsets"], json::array({3, 4, 8, 11, 13}));
  EXPECT_TRUE(j["data_section_crc_ok"].get<bool>());
  EXPECT_EQ(j["metadata"], json::parse(R"([{"name":"run","values":{"seed":"1","world":"default"}}])"));
  // sequences from 1 per channel, log times in order, every JSON message has its schema's fields
  EXPECT_TRUE(j["problems"].empty()) << j["problems"].dump(1);
}

TEST(Mcap, MessageContentsComeBackAsWritten) {
  const std::string script = reader();
  ASSERT_FALSE(script.empty());
  TempDir dir;
  const std::string path = dir.file("b.mcap");
  write_sample(path, small_chunks(), 3);
  const json j = test::read_mcap(script, path, {"--dump", "/uav/pose", "--dump", "/ugv1/lidar", "--dump", "/map/class", "--dump", "/log", "--dump", "/tf", "--max", "3"});
  ASSERT_TRUE(j.value("ok", false)) << j.dump();
  const json& pose = j["dumps"]["/uav/pose"][2];
  EXPECT_EQ(pose["log_time"], 40'000'000);
  EXPECT_EQ(pose["sequence"], 3);
  EXPECT_EQ(pose["data"]["timestamp"], (json{{"sec", 0}, {"nsec", 40'000'000}}));
  EXPECT_EQ(pose["data"]["frame_id"], "map");
  EXPECT_DOUBLE_EQ(pose["data"]["pose"]["position"]["x"].get<double>(), 0.2);
  EXPECT_DOUBLE_EQ(pose["data"]["pose"]["position"]["y"].get<double>(), -0.4);
  EXPECT_DOUBLE_EQ(pose["data"]["pose"]["position"]["z"].get<double>(), 40);
  EXPECT_NEAR(pose["data"]["pose"]["orientation"]["z"].get<double>(), std::sin(0.25), 1e-15);
  EXPECT_NEAR(pose["data"]["pose"]["orientation"]["w"].get<double>(), std::cos(0.25), 1e-15);

  const json& cloud = j["dumps"]["/ugv1/lidar"][1]["data"];
  EXPECT_EQ(cloud["point_stride"], 12);
  EXPECT_EQ(cloud["fields"][2], (json{{"name", "z"}, {"offset", 8}, {"type", 7}}));
  EXPECT_EQ(unbase64(cloud["data"].get<std::string>()), cloud_bytes(1, 64));

  const json& grid = j["dumps"]["/map/class"][0]["data"];
  EXPECT_EQ(grid["column_count"], 32);
  EXPECT_EQ(grid["cell_size"], (json{{"x", 0.5}, {"y", 0.5}}));
  const std::vector<std::uint8_t> cells = unbase64(grid["data"].get<std::string>());
  ASSERT_EQ(cells.size(), 512u);
  EXPECT_EQ(cells[100], 100 % 7);

  EXPECT_EQ(j["dumps"]["/log"][0]["data"]["message"], "tick \"0\"\n");
  EXPECT_EQ(j["dumps"]["/log"][0]["data"]["level"], 2);
  const json& tf = j["dumps"]["/tf"][1]["data"]["transforms"];
  ASSERT_EQ(tf.size(), 2u);
  EXPECT_EQ(tf[1]["parent_frame_id"], "uav");
  EXPECT_EQ(tf[1]["child_frame_id"], "uav/camera");
  EXPECT_DOUBLE_EQ(tf[0]["translation"]["x"].get<double>(), 0.5);
}

TEST(Mcap, UncompressedChunksAndOneBigChunkReadToo) {
  const std::string script = reader();
  ASSERT_FALSE(script.empty());
  TempDir dir;
  mcap::WriterOptions raw;
  raw.zstd_level = 0;
  const Written a = write_sample(dir.file("raw.mcap"), raw, 4);
  const json j = test::read_mcap(script, dir.file("raw.mcap"));
  ASSERT_TRUE(j.value("ok", false)) << j.dump();
  EXPECT_EQ(j["chunk_compression"], json::array({""}));
  EXPECT_EQ(j["statistics"]["message_count"].get<std::uint64_t>(), a.stats.messages);
  EXPECT_EQ(a.stats.chunks, 1u);
  // zstd makes the (repetitive) JSON several times smaller
  const Written z = write_sample(dir.file("z.mcap"), {}, 4);
  EXPECT_LT(z.stats.bytes * 3, a.stats.bytes);
}

TEST(Mcap, TheSameMessagesGiveTheSameBytes) {
  TempDir dir;
  write_sample(dir.file("1.mcap"), small_chunks(), 5);
  write_sample(dir.file("2.mcap"), small_chunks(), 5);
  EXPECT_EQ(read_bytes(dir.file("1.mcap")), read_bytes(dir.file("2.mcap")));
}

TEST(Mcap, TruncatedFilesAreReportedAsSuch) {
  const std::string script = reader();
  ASSERT_FALSE(script.empty());
  TempDir dir;
  write_sample(dir.file("full.mcap"), small_chunks(), 5);
  const std::vector<std::uint8_t> full = read_bytes(dir.file("full.mcap"));
  // a recording cut off by a crash: no summary, footer or closing magic; and one cut inside the footer
  for (const std::size_t keep : {full.size() / 2, full.size() - 10}) {
    write_bytes(dir.file("cut.mcap"), std::vector<std::uint8_t>(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(keep)));
    const json j = test::read_mcap(script, dir.file("cut.mcap"));
    EXPECT_FALSE(j.value("ok", true)) << "kept " << keep << " of " << full.size() << " bytes: " << j.dump().substr(0, 300);
    EXPECT_NE(j.value("exit_status", 0), 0);
    EXPECT_FALSE(j.value("error", std::string()).empty());
  }
}

TEST(Mcap, CorruptedFilesAreReportedAsSuch) {
  const std::string script = reader();
  ASSERT_FALSE(script.empty());
  TempDir dir;
  write_sample(dir.file("good.mcap"), small_chunks(), 5);
  const std::vector<std::uint8_t> good = read_bytes(dir.file("good.mcap"));
  ASSERT_TRUE(test::read_mcap(script, dir.file("good.mcap")).value("ok", false));
  // one byte flipped: inside a chunk's compressed records (a third in), in the summary (near the end,
  // before the footer), in the data section's first channel record (covered only by the data CRC)
  std::size_t channel_topic = 0;
  for (std::size_t i = 0; i + 9 < good.size(); ++i)
    if (std::memcmp(good.data() + i, "/uav/pose", 9) == 0) {
      channel_topic = i;
      break;
    }
  ASSERT_GT(channel_topic, 0u);
  for (const std::size_t at : {good.size() / 3, good.size() - 60, channel_topic + 3}) {
    std::vector<std::uint8_t> bad = good;
    bad[at] ^= 0x20;
    write_bytes(dir.file("bad.mcap"), bad);
    const json j = test::read_mcap(script, dir.file("bad.mcap"));
    EXPECT_FALSE(j.value("ok", true)) << "byte " << at << " of " << good.size() << " flipped: " << j.dump().substr(0, 300);
    EXPECT_FALSE(j.value("error", std::string()).empty());
  }
}

TEST(Mcap, MisuseIsAnErrorThatNamesTheFile) {
  mcap::McapWriter m;
  const Status s = m.open("/nonexistent-dir/x.mcap");
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("/nonexistent-dir/x.mcap"), std::string::npos);
  TempDir dir;
  ASSERT_TRUE(m.open(dir.file("m.mcap")));
  const Status w = m.write(3, 0, "{}");
  ASSERT_FALSE(w);
  EXPECT_NE(w.error().message.find("channel 3"), std::string::npos);
  EXPECT_EQ(m.add_channel(7, "/x", "json"), 0xFFFF) << "schema 7 does not exist";
  EXPECT_TRUE(m.close());
  EXPECT_FALSE(m.close());
}

TEST(Foxglove, EverySchemaIsJsonWithItsNameAsTitle) {
  for (const std::string_view name : foxglove::kSchemaNames) {
    const std::string& s = foxglove::schema(name);
    ASSERT_FALSE(s.empty()) << name;
    const json j = json::parse(s, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << name << ": " << s;
    EXPECT_EQ(j["title"], std::string(name));
    EXPECT_EQ(j["type"], "object");
    EXPECT_TRUE(j["properties"].contains(name == "foxglove.FrameTransforms" ? "transforms" : name == "foxglove.SceneUpdate" ? "entities" : "timestamp")) << name;
  }
  EXPECT_TRUE(foxglove::schema("foxglove.Nothing").empty());
  // binary fields are base64 strings, as Foxglove's JSON encoding has them
  EXPECT_EQ(json::parse(foxglove::schema("foxglove.CompressedImage"))["properties"]["data"]["contentEncoding"], "base64");
  EXPECT_EQ(foxglove::json_number(0.1), "0.1");
  EXPECT_EQ(foxglove::json_number(std::nan("")), "null");
  EXPECT_EQ(foxglove::json_string("a\"b\\\n\x01"), "\"a\\\"b\\\\\\n\\u0001\"");
  const json scene = json::parse(foxglove::scene_update(1'500'000'000, {{"r1", "map", {{{{0, 0, 0}, {1, 2, 0}}, {1, 0, 0, 1}, 0.3, false}}, {{{5, 5, 0}, 2, {}}}, {{{5, 5, 3}, "R1", {}, 14}}}}));
  EXPECT_EQ(scene["entities"][0]["timestamp"], (json{{"sec", 1}, {"nsec", 500'000'000}}));
  EXPECT_EQ(scene["entities"][0]["lines"][0]["points"][1], (json{{"x", 1}, {"y", 2}, {"z", 0}}));
  EXPECT_EQ(scene["entities"][0]["spheres"][0]["size"]["x"], 2);
  EXPECT_EQ(scene["entities"][0]["texts"][0]["text"], "R1");
}

}  // namespace
}  // namespace ag
