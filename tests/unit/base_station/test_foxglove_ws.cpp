// The base's live Foxglove connection, in the real base role with a played mission: Foxglove's own
// client (@foxglove/ws-protocol's FoxgloveClient on node, tests/foxglove_ws_client/check_live.mjs)
// subscribes to every advertised channel, receives each, unsubscribes and gets nothing more, and has
// its malformed messages refused by name while the connection, the page and the stage go on; raw
// sockets check the subprotocol negotiation and that a client that does not read loses messages, not
// the base.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "base_rig.hpp"
#include "http_client.hpp"

namespace ag::base_station::test {
namespace {

// Plays the mission in real time (50 ms steps) on its own thread until stopped: poses every 200 ms.
class LivePlayer {
 public:
  LivePlayer(MissionPlayer& pl, BaseRig& rig, TimeNs now) : now_(now) {
    thread_ = std::thread([this, &pl, &rig] {
      while (!stop_.load()) {
        if ((now_ / (50 * kNsPerMs)) % 4 == 0)
          for (int r = 1; r <= 2; ++r) {
            const Pose2 p = MissionPlayer::robot_pose(r, static_cast<double>(now_) * 1e-9);
            pl.pose(r, p.x, p.y, p.yaw, now_);
          }
        pl.tick(now_);
        rig.step(now_);
        now_ += 50 * kNsPerMs;
        ++steps_;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    });
  }
  ~LivePlayer() { stop(); }
  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  [[nodiscard]] std::uint64_t steps() const { return steps_.load(); }

 private:
  TimeNs now_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> steps_{0};
  std::thread thread_;
};

nlohmann::json fox_counters(const WebStage& web) { return nlohmann::json::parse("{" + web.foxglove_counters_json() + "}"); }

std::unique_ptr<BaseRig> mission_rig(const TempDir& dir, MissionPlayer& pl, TimeNs& now, std::vector<std::string> extra = {}) {
  auto rig = BaseRig::make(dir, std::move(extra));
  if (rig == nullptr) return nullptr;
  for (std::int32_t tx = 0; tx < 3; ++tx)
    for (std::int32_t ty = 0; ty < 2; ++ty) pl.tile(tx, ty, 1, now);
  pl.publish_mission_records(now);
  for (const TimeNs end = now + 2 * kNsPerS; now < end; now += 50 * kNsPerMs) {
    for (int r = 1; r <= 2; ++r) {
      const Pose2 p = MissionPlayer::robot_pose(r, static_cast<double>(now) * 1e-9);
      pl.pose(r, p.x, p.y, p.yaw, now);
    }
    pl.tick(now);
    rig->step(now);
  }
  // The server thread advertises each robot's pose channel on its next tick after the model has it.
  for (int i = 0; i < 200 && fox_counters(*rig->web)["channels"] != 11; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(fox_counters(*rig->web)["channels"], 11) << "9 fixed channels and robot1's and robot2's poses";
  return rig;
}

nlohmann::json run_node(const std::string& cmd) {
  std::FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) return {{"ok", false}, {"error", "popen failed"}};
  std::string out;
  std::array<char, 65536> buf{};
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), p)) > 0;) out.append(buf.data(), n);
  const int rc = ::pclose(p);
  nlohmann::json j = nlohmann::json::parse(out, nullptr, false);
  if (j.is_discarded()) return {{"ok", false}, {"error", "the client printed no JSON (exit " + std::to_string(rc) + "): " + out}};
  return j;
}

// A masked client text frame of any length (http_client.hpp's helper is for short payloads).
std::vector<std::uint8_t> text_frame(const std::string& payload) {
  std::vector<std::uint8_t> f{0x81};
  if (payload.size() < 126) {
    f.push_back(static_cast<std::uint8_t>(0x80u | payload.size()));
  } else {
    f.push_back(0x80u | 126u);
    f.push_back(static_cast<std::uint8_t>(payload.size() >> 8));
    f.push_back(static_cast<std::uint8_t>(payload.size()));
  }
  const std::uint8_t mask[4] = {0x11, 0x22, 0x33, 0x44};
  f.insert(f.end(), mask, mask + 4);
  for (std::size_t i = 0; i < payload.size(); ++i) f.push_back(static_cast<std::uint8_t>(static_cast<std::uint8_t>(payload[i]) ^ mask[i % 4]));
  return f;
}

std::string fox_upgrade(const std::string& path, const std::string& protocols) {
  return "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
         "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: " + protocols + "\r\n\r\n";
}

TEST(FoxgloveWs, TheOfficialClientSubscribesReceivesEveryChannelUnsubscribesAndIsRefusedByName) {
  const std::string dir = std::string(AG_TEST_SOURCE_DIR) + "/tests/foxglove_ws_client";
  ASSERT_EQ(std::system("node --version >/dev/null 2>&1"), 0) << "node is not installed (tools/install-deps.sh installs it)";
  ASSERT_TRUE(std::filesystem::exists(dir + "/node_modules/@foxglove/ws-protocol/package.json") &&
              std::filesystem::exists(dir + "/node_modules/ws/package.json"))
      << "@foxglove/ws-protocol and ws are not installed in " << dir << "/node_modules: run tools/install-foxglove-ws-client.sh";
  TempDir tmp;
  MissionPlayer pl;
  TimeNs now = kNsPerS;
  auto rig = mission_rig(tmp, pl, now);
  ASSERT_NE(rig, nullptr);
  const std::uint64_t poses0 = rig->web->model().counters.poses_in;
  LivePlayer live(pl, *rig, now);
  const std::string url = "ws://127.0.0.1:" + std::to_string(rig->web->port());
  const nlohmann::json r = run_node("node " + dir + "/check_live.mjs " + url + " --min-channels 11 --timeout 6");
  ASSERT_TRUE(r.contains("ok") && r["ok"] == true) << r.dump().substr(0, 3000);
  EXPECT_EQ(r["protocol"], "foxglove.websocket.v1");
  EXPECT_EQ(r["server_info"]["name"], "airground-base");
  EXPECT_TRUE(r["errors"].empty()) << r["errors"].dump();

  // Every channel: JSON with a JSON schema; the topics and schemas the base station knows.
  const std::map<std::string, std::string> expected = {
      {"/tf", "foxglove.FrameTransforms"}, {"/map_tiles", "foxglove.Grid"}, {"/regions", "foxglove.SceneUpdate"},
      {"/claims", "foxglove.SceneUpdate"}, {"/visits", "foxglove.SceneUpdate"}, {"/failures", "foxglove.SceneUpdate"},
      {"/objects", "foxglove.SceneUpdate"}, {"/comms", "airground.CommsStats"}, {"/base/counters", "airground.BaseCounters"},
      {"/robot1/pose", "foxglove.PoseInFrame"}, {"/robot2/pose", "foxglove.PoseInFrame"}};
  std::map<std::string, std::string> seen;
  for (const auto& c : r["channels"]) {
    seen[c["topic"]] = c["schemaName"];
    EXPECT_EQ(c["encoding"], "json") << c.dump();
    EXPECT_EQ(c["schemaEncoding"], "jsonschema") << c.dump();
    EXPECT_EQ(c["schema_parses"], true) << c.dump();
  }
  EXPECT_EQ(seen, expected);

  // Messages of each, as their schemas say.
  const auto& topics = r["topics"];
  const auto wall_s = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  for (const auto& [topic, schema] : expected) {
    ASSERT_TRUE(topics.contains(topic)) << topic << " delivered nothing: " << topics.dump().substr(0, 2000);
    const auto& t = topics[topic];
    EXPECT_GE(t["count"].get<int>(), 1) << topic;
    EXPECT_EQ(t["json_ok"], true) << topic;
    EXPECT_NEAR(std::stod(t["timestamp_ns"].get<std::string>()) * 1e-9, wall_s, 60.0) << topic << ": the base's wall clock";
  }
  EXPECT_EQ(topics["/map_tiles"]["count"], 6) << "the six tiles held, each once";
  EXPECT_EQ(topics["/map_tiles"]["data_bytes"], 64 * 64 * 8) << "elevation f32, class, r, g, b per cell";
  auto frames = topics["/tf"]["child_frames"].get<std::vector<std::string>>();
  std::sort(frames.begin(), frames.end());
  EXPECT_EQ(frames, (std::vector<std::string>{"robot1", "robot2"})) << "map -> each robot heard";
  EXPECT_EQ(topics["/robot1/pose"]["frame_id"], "map");
  EXPECT_EQ(topics["/regions"]["entity_ids"], (nlohmann::json{"regions"}));
  EXPECT_EQ(topics["/claims"]["entity_ids"], (nlohmann::json{"claim/robot1"}));
  EXPECT_EQ(topics["/visits"]["entity_ids"], (nlohmann::json{"visits/robot2"}));
  EXPECT_EQ(topics["/failures"]["entity_ids"], (nlohmann::json{"failures"}));
  EXPECT_EQ(topics["/objects"]["entity_ids"], (nlohmann::json{"objects"}));
  EXPECT_NE(std::find(topics["/comms"]["keys"].begin(), topics["/comms"]["keys"].end(), "peers"), topics["/comms"]["keys"].end());
  EXPECT_GE(topics["/base/counters"]["last"]["foxglove"]["subscriptions"].get<int>(), 11);

  // Unsubscribed: nothing more (the robots keep moving, the counters keep ticking).
  EXPECT_TRUE(r["after_unsubscribe"].empty()) << r["after_unsubscribe"].dump();

  // Each malformed message: one status, level error, naming the fault.
  const std::map<std::string, std::string> refusals = {
      {"not_json", "not JSON"}, {"not_object", "JSON object with a string 'op'"}, {"unknown_op", "unknown op 'fly'"},
      {"needs_capability", "capability 'parameters'"}, {"unknown_channel", "channel 99999 is not advertised"},
      {"bad_subscription_entry", "unsigned 32-bit"}, {"subscription_id_in_use", "subscription id 901 is already in use"},
      {"unknown_unsubscribe", "no subscription 12345"}, {"binary_garbage", "binary message refused (opcode 0xde"}};
  ASSERT_EQ(r["refusals"].size(), refusals.size()) << r["refusals"].dump();
  for (const auto& x : r["refusals"]) {
    const std::string name = x["name"];
    EXPECT_EQ(x["statuses"], 1) << name;
    EXPECT_EQ(x["level"], 2) << name;
    ASSERT_TRUE(x["message"].is_string()) << name << ": no status";
    EXPECT_NE(x["message"].get<std::string>().find(refusals.at(name)), std::string::npos) << name << ": " << x["message"];
  }
  ASSERT_FALSE(r["resubscribed"].is_null()) << "a subscription after the refusals still delivers";
  EXPECT_GE(r["resubscribed"]["count"].get<int>(), 1);

  // Counted by the base; the page, its feed and the stage go on.
  const nlohmann::json fc = fox_counters(*rig->web);
  EXPECT_EQ(fc["client_errors"], refusals.size()) << fc.dump();
  EXPECT_EQ(fc["clients_opened"], 1);
  EXPECT_GE(fc["subscriptions"].get<int>(), 13);
  EXPECT_GE(fc["unsubscriptions"].get<int>(), 12);
  EXPECT_EQ(rig->web->server_counters()->ws_bad_frames.load(), 0U);
  // /api/state is the state the stage last rendered (at its rate): the count shows there within a few
  // renders, not at once (on a loaded machine it read 7 of 9 right after the refusals).
  std::string state;
  for (int attempt = 0; attempt < 100; ++attempt) {
    Client api(rig->web->port());
    api.send(get_request("/api/state"));
    ASSERT_TRUE(api.read_to_close());
    EXPECT_EQ(api.buf.find("HTTP/1.1 200 OK"), 0U);
    state = api.buf;
    if (state.find("\"client_errors\":9") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_NE(state.find("\"client_errors\":9"), std::string::npos) << state.substr(state.size() > 1500 ? state.size() - 1500 : 0);
  Client page(rig->web->port());
  page.send(ws_upgrade());
  ASSERT_TRUE(page.read_contains("\"type\":\"state\"")) << "the page's own feed";
  EXPECT_EQ(page.buf.find("Sec-WebSocket-Protocol"), std::string::npos);
  EXPECT_GT(live.steps(), 20U);
  live.stop();
  EXPECT_GT(rig->web->model().counters.poses_in, poses0 + 10) << "the stage kept taking poses throughout";
}

TEST(FoxgloveWs, TheSubprotocolIsNegotiatedAtAnyPathAndThePageKeepsItsOwn) {
  TempDir tmp;
  MissionPlayer pl;
  TimeNs now = kNsPerS;
  auto rig = mission_rig(tmp, pl, now);
  ASSERT_NE(rig, nullptr);
  const int port = rig->web->port();
  // Foxglove's client at /: 101 with the subprotocol, serverInfo, then the advertise of 11 channels.
  Client fox(port);
  fox.send(fox_upgrade("/", "foxglove.websocket.v1"));
  ASSERT_TRUE(fox.read_until([](const std::string& b) { return ws_frames(b).size() >= 2; }));
  EXPECT_EQ(fox.buf.find("HTTP/1.1 101 Switching Protocols"), 0U);
  EXPECT_NE(fox.buf.find("\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n"), std::string::npos);
  const auto frames = ws_frames(fox.buf);
  const auto info = nlohmann::json::parse(frames[0].payload);
  EXPECT_EQ(info["op"], "serverInfo");
  EXPECT_TRUE(info["capabilities"].empty());
  const auto adv = nlohmann::json::parse(frames[1].payload);
  EXPECT_EQ(adv["op"], "advertise");
  EXPECT_EQ(adv["channels"].size(), 11U);
  // Among several offered, ours is picked; the page's /ws with it is Foxglove too.
  Client both(port);
  both.send(fox_upgrade("/ws", "other.v2, foxglove.websocket.v1"));
  ASSERT_TRUE(both.read_contains("serverInfo"));
  EXPECT_NE(both.buf.find("Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n"), std::string::npos);
  // A subprotocol we do not speak at /: no upgrade, the page.
  Client other(port);
  other.send(fox_upgrade("/", "other.v2"));
  ASSERT_TRUE(other.read_contains("</html>"));
  EXPECT_EQ(other.buf.find("HTTP/1.1 200 OK"), 0U);
  // The page's own feed: no subprotocol, hello first.
  Client page(port);
  page.send(ws_upgrade());
  ASSERT_TRUE(page.read_contains("\"type\":\"hello\""));
  EXPECT_EQ(page.buf.find("Sec-WebSocket-Protocol"), std::string::npos);
  // With web.foxglove=false the Foxglove client gets the page, not an upgrade.
  TempDir tmp2;
  auto off = BaseRig::make(tmp2, {"web.foxglove=false"});
  ASSERT_NE(off, nullptr);
  Client refused(off->web->port());
  refused.send(fox_upgrade("/", "foxglove.websocket.v1"));
  ASSERT_TRUE(refused.read_contains("</html>"));
  EXPECT_EQ(refused.buf.find("HTTP/1.1 200 OK"), 0U);
}

TEST(FoxgloveWs, AClientThatDoesNotReadLosesMessagesNotTheBase) {
  TempDir tmp;
  MissionPlayer pl;
  TimeNs now = kNsPerS;
  auto rig = mission_rig(tmp, pl, now, {"web.client_buffer_kb=64", "web.slow_client_s=1.5", "web.push_hz=20"});
  ASSERT_NE(rig, nullptr);
  Client slow(rig->web->port(), 4096);
  slow.send(fox_upgrade("/", "foxglove.websocket.v1"));
  ASSERT_TRUE(slow.read_contains("\"op\":\"advertise\""));
  std::string sub = R"({"op":"subscribe","subscriptions":[)";
  for (std::uint32_t c = 1; c <= 9; ++c) sub += std::string(c > 1 ? "," : "") + R"({"id":)" + std::to_string(c) + R"(,"channelId":)" + std::to_string(c) + "}";
  sub += R"(,{"id":10,"channelId":101},{"id":11,"channelId":102}]})";
  slow.send(text_frame(sub));
  // It stops reading; a second client reads everything.
  Client reader(rig->web->port());
  reader.send(fox_upgrade("/", "foxglove.websocket.v1"));
  ASSERT_TRUE(reader.read_contains("\"op\":\"advertise\""));
  reader.send(text_frame(R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":101}]})"));
  for (std::int32_t k = 0; k < 30; ++k) pl.tile(10 + k, 5, 1, now);
  LivePlayer live(pl, *rig, now);
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  const std::size_t before = reader.buf.size();
  ASSERT_TRUE(reader.read_until([&](const std::string& b) { return b.size() > before + 200; }, 2.0)) << "the reading client still gets poses";
  const std::uint64_t steps = live.steps();
  live.stop();
  const nlohmann::json fc = fox_counters(*rig->web);
  EXPECT_GT(fc["dropped_slow"].get<int>(), 0) << fc.dump();
  EXPECT_GE(rig->web->server_counters()->slow_dropped.load(), 1U) << "the server drops a client that has not drained for slow_client_s";
  EXPECT_GE(steps, 40U) << "the stage stepped on";
  EXPECT_GE(rig->web->model().counters.tiles_in, 12U) << "tiles kept arriving";
}

}  // namespace
}  // namespace ag::base_station::test
