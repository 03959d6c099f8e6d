// The comms stage's row of the ground robot's table, held to its budget while a quadrotor (a gossip node
// on the other end of an in-process link with 20 % loss) sends it a full 500 m map, a changed tile every
// second and poses, and while the stage decodes and delivers the tiles and answers with its own pose.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdio>
#include <fstream>
#include <memory>

#include "airground/comms/gossip_node.hpp"
#include "airground/comms/link_hub.hpp"
#include "airground/comms/stage.hpp"
#include "airground/comms/tile_codec.hpp"
#include "budget_harness.hpp"
#include "roles.hpp"

namespace ag {
namespace {
using namespace comms;

TEST(CommsBudget, GroundRobotStageReceivingAFullMapStaysWithinItsBudget) {
  const StageSpec* row = nullptr;
  for (const StageSpec& s : ugv_role().stages)
    if (s.name == "comms") row = &s;
  ASSERT_NE(row, nullptr) << "the ugv table has a comms row";
  static std::vector<StageSpec> stages;
  stages = {*row};
  static const RoleDescription role{"ugvcomms", "the ugv's comms row", stages, {}};

  const std::string key_path = ::testing::TempDir() + "comms_budget.key";
  std::ofstream(key_path) << "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff\n";
  ::chmod(key_path.c_str(), 0600);
  TeamKey key;
  for (std::size_t i = 0; i < 16; ++i) key.bytes[i] = key.bytes[i + 16] = static_cast<std::uint8_t>(i * 0x11);

  LinkHub hub(2, 0.2, 5);
  register_inproc_link("ugvcomms", &hub.endpoint(1));
  RecordStore store(StoreLimits{1024, 8u << 20, TileCodec::max_payload_bytes()});
  GossipParams gp;
  gp.self = 0;
  gp.budget_bytes_per_s = 400'000;  // a fast link: the receiver's work per step is what is measured
  GossipNode uav(gp, key, store, 1, nullptr);
  TileCodec codec;
  auto tile = std::make_unique<MapTileMsg>();
  std::vector<std::uint8_t> buf(TileCodec::max_payload_bytes());
  auto publish_tile = [&](int tx, int ty, std::uint64_t version, TimeNs t) {
    tile->tx = tx;
    tile->ty = ty;
    tile->version = version;
    tile->stamp = t;
    for (std::size_t i = 0; i < kTileCellCount; ++i) {
      tile->cls[i] = static_cast<std::uint8_t>(((i / 64) / 8 + (i % 64) / 8 + static_cast<std::size_t>(tx + ty) + version) % 5);
      tile->elevation[i] = static_cast<float>(0.01 * static_cast<double>((i * 7 + static_cast<std::size_t>(ty)) % 300));
    }
    const std::size_t n = codec.encode(*tile, buf);
    (void)uav.publish(tile_topic(tx, ty), 2, t, std::span<const std::uint8_t>(buf.data(), n));
  };
  std::uint64_t version = 1;
  timing::BudgetCase c;
  c.role = &role;
  c.duration = 30 * kNsPerS;
  c.overrides = {"robot.id=1", "comms.transport=inproc", "comms.key_file=" + key_path, "comms.deliver_map_tiles=true",
                 "comms.epoch_from_clock=false", "comms.budget_bytes_per_s=400000"};
  c.before_tick = [&](TimeNs t, RoleInstance&) {
    if (t == kNsPerS)
      for (int ty = 0; ty < 16; ++ty)
        for (int tx = 0; tx < 16; ++tx) publish_tile(tx, ty, version, t);
    if (t > 2 * kNsPerS && t % kNsPerS == 0) publish_tile(static_cast<int>(t / kNsPerS) % 16, 3, ++version, t);
    uav.tick(t, hub.endpoint(0));
  };
  // The stage's own map_tiles ring has no reader here: deliveries count as pushes all the same.
  auto rep = timing::run_budget_case(c);
  register_inproc_link("ugvcomms", nullptr);
  ASSERT_TRUE(rep.ok()) << rep.error().message;
  std::fputs(timing::format_table(rep.value()).c_str(), stdout);
  const auto* s = rep.value().find("comms");
  ASSERT_NE(s, nullptr);
  EXPECT_GT(s->runs, 500U);
  EXPECT_TRUE(s->within()) << "comms p99 " << to_us(s->p99) << " us > scaled budget " << to_us(s->scaled) << " us";
  EXPECT_GE(uav.peer_stats(1).records_out, 256U) << "the map went through during the run";
}

}  // namespace
}  // namespace ag
