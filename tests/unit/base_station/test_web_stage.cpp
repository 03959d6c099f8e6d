// The web stage inside the real base role: a played mission arrives over the inproc link; the model,
// /api/state, the WebSocket (hello, state, binary tiles) and the mission log all show it; malformed
// records are counted and named; the operator's arm goes out over the radio.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "base_rig.hpp"
#include "http_client.hpp"

namespace ag::base_station::test {
namespace {

std::string slurp(const std::string& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Plays the mission for `seconds` of simulated time in 50 ms steps.
void play(MissionPlayer& pl, BaseRig& rig, TimeNs& now, double seconds, bool poses = true) {
  const TimeNs end = now + static_cast<TimeNs>(seconds * 1e9);
  for (; now < end; now += 50 * kNsPerMs) {
    if (poses && (now / (50 * kNsPerMs)) % 4 == 0)
      for (int r = 1; r <= 2; ++r) {
        const Pose2 p = MissionPlayer::robot_pose(r, static_cast<double>(now) * 1e-9);
        pl.pose(r, p.x, p.y, p.yaw, now);
      }
    pl.tick(now);
    rig.step(now);
  }
}

TEST(WebStage, TheMissionReachesTheModelTheApiTheWebSocketAndTheLog) {
  TempDir dir;
  MissionPlayer pl;
  auto rig = BaseRig::make(dir);
  ASSERT_NE(rig, nullptr);
  TimeNs now = kNsPerS;
  for (std::int32_t tx = 0; tx < 3; ++tx)
    for (std::int32_t ty = 0; ty < 2; ++ty) pl.tile(tx, ty, 1, now);
  pl.publish_mission_records(now);
  play(pl, *rig, now, 3.0);

  const MissionModel& m = rig->web->model();
  EXPECT_EQ(m.counters.tiles_in, 6U);
  ASSERT_NE(m.find_robot(1), nullptr);
  ASSERT_NE(m.find_robot(2), nullptr);
  EXPECT_TRUE(m.find_robot(1)->has_pose);
  EXPECT_GE(m.find_robot(2)->trail_count, 5U) << "robot 2 drives 6 m/s: its trail grows";
  ASSERT_TRUE(m.find_robot(1)->has_claim);
  EXPECT_EQ(m.find_robot(1)->claim.region_id, 11u);
  ASSERT_TRUE(m.find_robot(2)->has_visited);
  EXPECT_EQ(m.find_robot(2)->visited.entries[0].region_id, 12u);
  EXPECT_EQ(m.failure_count, 1U);
  EXPECT_EQ(m.object_count, 1U);
  int regions = 0;
  m.for_each_region([&](const mission::RegionRecord&) { ++regions; });
  EXPECT_EQ(regions, 3);
  EXPECT_EQ(m.counters.decode_errors, 0U);
  EXPECT_TRUE(m.has_comms);

  // /api/state over HTTP.
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  Client api(rig->web->port());
  api.send(get_request("/api/state"));
  ASSERT_TRUE(api.read_to_close());
  EXPECT_EQ(api.buf.find("HTTP/1.1 200 OK"), 0U);
  EXPECT_NE(api.buf.find("Content-Type: application/json"), std::string::npos);
  for (const char* s : {"\"id\":1,", "\"id\":2,", "\"region\":11", "\"id\":12,", "\"reason\":\"no_route\"", "\"state\":\"going\"",
                        "\"tiles_held\":6", "\"peers\":[{"})
    EXPECT_NE(api.buf.find(s), std::string::npos) << s << " in " << api.buf.substr(0, 3000);
  Client page(rig->web->port());
  page.send(get_request("/"));
  ASSERT_TRUE(page.read_to_close());
  EXPECT_NE(page.buf.find("<canvas id=\"map\""), std::string::npos) << "the embedded page";
  Client js(rig->web->port());
  js.send(get_request("/app.js"));
  ASSERT_TRUE(js.read_to_close());
  EXPECT_NE(js.buf.find("text/javascript"), std::string::npos);
  EXPECT_NE(js.buf.find("window.agStats"), std::string::npos);

  // WebSocket: hello with the class colours of config/classes.yaml, the state, the six tiles.
  Client ws(rig->web->port());
  ws.send(ws_upgrade());
  std::thread stepper([&] {
    TimeNs t = now;
    play(pl, *rig, t, 0.5, false);
  });
  const bool got = ws.read_until([](const std::string& b) {
    int bin = 0;
    for (const auto& f : ws_frames(b)) bin += f.opcode == 2 ? 1 : 0;
    return bin >= 6;
  }, 3.0);
  stepper.join();
  ASSERT_TRUE(got) << ws_frames(ws.buf).size() << " frames";
  const auto frames = ws_frames(ws.buf);
  ASSERT_GE(frames.size(), 8U);
  EXPECT_EQ(frames[0].opcode, 1);
  EXPECT_NE(frames[0].payload.find("\"type\":\"hello\""), std::string::npos);
  EXPECT_NE(frames[0].payload.find("{\"id\":6,\"name\":\"water\",\"color\":[40,110,210]}"), std::string::npos) << frames[0].payload;
  EXPECT_NE(frames[1].payload.find("\"type\":\"state\""), std::string::npos);
  for (const auto& f : frames) {
    if (f.opcode != 2) continue;
    ASSERT_EQ(f.payload.size(), 24U + 3U * kTileCellCount);
    const auto* p = reinterpret_cast<const std::uint8_t*>(f.payload.data());
    EXPECT_EQ(p[0], 1);
    EXPECT_EQ(p[2] | (p[3] << 8), 64);
    const std::int32_t tx = static_cast<std::int32_t>(p[4] | (p[5] << 8) | (p[6] << 16) | (static_cast<std::uint32_t>(p[7]) << 24));
    const std::int32_t ty = static_cast<std::int32_t>(p[8] | (p[9] << 8) | (p[10] << 16) | (static_cast<std::uint32_t>(p[11]) << 24));
    EXPECT_EQ(p[16], 1) << "version 1";
    // cell (row 21, col 17) of the class bytes; elevation 100 m + 0.01 (r + c) in decimetres
    EXPECT_EQ(p[24 + 21 * 64 + 17], player_class(tx, ty, 21, 17));
    const std::size_t e = 24 + kTileCellCount + 2 * (21 * 64 + 17);
    EXPECT_EQ(static_cast<std::int16_t>(p[e] | (p[e + 1] << 8)), 1004);
  }

  // The mission log: one JSON line per record, with time, origin, kind and the decoded fields.
  rig->role->stop_all();
  const std::string log = slurp(dir.file("mission.jsonl"));
  EXPECT_NE(log.find("\"origin\":1,\"kind\":\"claim\""), std::string::npos) << log.substr(0, 2000);
  EXPECT_NE(log.find("\"state\":\"going\",\"priority\":1,\"region\":11"), std::string::npos);
  EXPECT_NE(log.find("\"origin\":2,\"kind\":\"failure\""), std::string::npos);
  EXPECT_NE(log.find("\"reason\":\"no_route\",\"attempts\":2"), std::string::npos);
  EXPECT_NE(log.find("\"kind\":\"regions\""), std::string::npos);
  EXPECT_NE(log.find("\"kind\":\"map_tile\""), std::string::npos);
  EXPECT_NE(log.find("\"origin\":2,\"kind\":\"pose\""), std::string::npos);
  std::size_t lines = 0;
  std::istringstream in(log);
  for (std::string l; std::getline(in, l); ++lines) {
    ASSERT_FALSE(l.empty());
    EXPECT_EQ(l.front(), '{');
    EXPECT_EQ(l.back(), '}');
    EXPECT_NE(l.find("\"t\":"), std::string::npos);
  }
  EXPECT_GE(lines, 6U + 5U + 10U);
}

TEST(WebStage, MalformedRecordsAreCountedNamedAndLogged) {
  TempDir dir;
  MissionPlayer pl;
  auto rig = BaseRig::make(dir);
  ASSERT_NE(rig, nullptr);
  TimeNs now = kNsPerS;
  const std::uint8_t short_claim[5] = {1, 1, 0, 0, 7};
  pl.record(1, comms::make_topic(comms::TopicKind::kClaims, 0), short_claim, now);
  std::uint8_t bad_regions[8] = {2, 0, 1, 0, 1, 0, 0, 0};  // format 2
  pl.record(0, comms::make_topic(comms::TopicKind::kRegions, 0), bad_regions, now);
  play(pl, *rig, now, 1.5, false);
  const MissionModel& m = rig->web->model();
  EXPECT_EQ(m.counters.decode_errors, 2U);
  ASSERT_NE(m.find_robot(1), nullptr);
  EXPECT_FALSE(m.find_robot(1)->has_claim);
  rig->role->stop_all();
  const std::string log = slurp(dir.file("mission.jsonl"));
  EXPECT_NE(log.find("\"kind\":\"claim\",\"topic\":\"0x05000000\""), std::string::npos) << log;
  EXPECT_NE(log.find("\"error\":\"truncated\""), std::string::npos) << log;
  EXPECT_NE(log.find("\"error\":\"unknown format byte\""), std::string::npos) << log;
}

// The operator's arm (the page's button, or any HTTP tool): POST /api/arm?robot=N reaches robot N's store
// over the radio as its command record; bad requests are refused and say why.
TEST(WebStage, AnArmPostedToTheBaseStationReachesTheRobotOverTheRadio) {
  TempDir dir;
  MissionPlayer pl;
  auto rig = BaseRig::make(dir);
  ASSERT_NE(rig, nullptr);
  TimeNs now = kNsPerS;
  play(pl, *rig, now, 1.0);
  auto post = [&](const std::string& target, const std::string& method = "POST") {
    Client c(rig->web->port());
    c.send(method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 0\r\nConnection: close\r\n\r\n");
    EXPECT_TRUE(c.read_to_close());
    return c.buf;
  };
  const std::string ok = post("/api/arm?robot=1");
  EXPECT_EQ(ok.find("HTTP/1.1 202 Accepted"), 0U) << ok;
  EXPECT_NE(ok.find("\"command\": \"arm\""), std::string::npos) << ok;
  EXPECT_EQ(post("/api/arm").find("HTTP/1.1 400"), 0U) << "no robot";
  EXPECT_EQ(post("/api/arm?robot=x1").find("HTTP/1.1 400"), 0U);
  EXPECT_EQ(post("/api/arm?robot=300").find("HTTP/1.1 400"), 0U);
  EXPECT_EQ(post("/api/disarm?robot=200").find("HTTP/1.1 400"), 0U) << "the base station itself";
  EXPECT_EQ(post("/api/arm?robot=1", "GET").find("HTTP/1.1 405"), 0U) << "a GET never arms";
  EXPECT_EQ(post("/api/launch?robot=1").find("HTTP/1.1 404"), 0U);
  play(pl, *rig, now, 3.0);
  const comms::RecordStore::Slot s = pl.node(1).store().find(comms::RecordKey{200, comms::command_topic(1)});
  ASSERT_NE(s, comms::RecordStore::kNoSlot) << "the command reached robot 1 over the radio";
  comms::OperatorCommand c{};
  std::uint32_t request = 0;
  ASSERT_TRUE(comms::decode_command(pl.node(1).store().payload(s), c, request));
  EXPECT_EQ(c, comms::OperatorCommand::kArm);
  EXPECT_EQ(request, 1U);
  EXPECT_EQ(rig->web->model().counters.commands_sent, 1U);
}

TEST(WebStage, AnUnwritableLogPathFailsInitNamingThePath) {
  TempDir dir;
  MissionPlayer pl;
  static const std::vector<ParamSection> schema = role_schema(base_role());
  Config cfg = Config::defaults(schema);
  ASSERT_TRUE(cfg.set("comms.transport=none").ok());
  ASSERT_TRUE(cfg.set("web.port=0").ok());
  ASSERT_TRUE(cfg.set("web.log_path=" + dir.file("no/such/dir/mission.jsonl")).ok());
  SimClock clock{0};
  auto r = RoleInstance::create(base_role(), cfg, clock, "base");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("no/such/dir/mission.jsonl"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace ag::base_station::test
