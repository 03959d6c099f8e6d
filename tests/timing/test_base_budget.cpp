// The base station's table (status, comms, web) held to its budgets while a played mission arrives over
// an in-process link: a 16 x 16-tile map at once, two robots' poses at 5 Hz, regions, a claim, visited
// and failed goals; the web stage decodes them, copies its model to the server thread and hands tiles
// and log entries over every step, with the server (on its own thread) writing the mission log.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "budget_harness.hpp"
#include "mission_player.hpp"
#include "roles.hpp"

namespace ag {
namespace {

TEST(BaseBudget, WebAndCommsRowsWithALiveMissionStayWithinTheirBudgets) {
  base_station::test::TempDir dir;
  base_station::test::MissionPlayer pl;
  timing::BudgetCase c;
  c.role = &base_role();
  c.duration = 30 * kNsPerS;
  c.overrides = {"robot.id=200", "comms.transport=inproc", "comms.key_file=" + base_station::test::write_key(dir.file("team.key")),
                 "comms.deliver_map_tiles=true", "comms.epoch_from_clock=false", "comms.budget_bytes_per_s=400000",
                 "web.port=0", "web.bind=127.0.0.1", "web.log_path=" + dir.file("mission.jsonl")};
  c.before_tick = [&](TimeNs t, RoleInstance&) {
    if (t == kNsPerS) {
      for (int ty = 0; ty < 16; ++ty)
        for (int tx = 0; tx < 16; ++tx) pl.tile(tx, ty, 1, t);
      pl.publish_mission_records(t);
    }
    if (t % (200 * kNsPerMs) == 0)
      for (int r = 1; r <= 2; ++r) {
        const Pose2 p = base_station::test::MissionPlayer::robot_pose(r, static_cast<double>(t) * 1e-9);
        pl.pose(r, p.x, p.y, p.yaw, t);
      }
    pl.tick(t);
  };
  auto rep = timing::run_budget_case(c);
  ASSERT_TRUE(rep.ok()) << rep.error().message;
  std::fputs(timing::format_table(rep.value()).c_str(), stdout);
  for (const char* name : {"web", "comms"}) {
    const auto* s = rep.value().find(name);
    ASSERT_NE(s, nullptr) << name;
    EXPECT_GT(s->runs, 250U) << name;
    EXPECT_TRUE(s->within()) << name << " p99 " << to_us(s->p99) << " us > scaled budget " << to_us(s->scaled) << " us";
  }
  std::ifstream f(dir.file("mission.jsonl"));
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string log = ss.str();
  std::size_t tiles = 0;
  for (std::size_t p = log.find("\"kind\":\"map_tile\""); p != std::string::npos; p = log.find("\"kind\":\"map_tile\"", p + 1)) ++tiles;
  std::printf("mission log: %zu B, %zu map tiles\n", log.size(), tiles);
  EXPECT_GT(tiles, 0U) << "tiles reached the web stage's server during the run";
}

}  // namespace
}  // namespace ag
