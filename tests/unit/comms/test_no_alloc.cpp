// The comms real-time path never allocates once built: GossipNode receive/tick/publish (digests,
// have-lists, fragments, reassembly, compaction, journal appends) and the stage's step with tiles,
// poses and generic records flowing both ways (operator new counted by tests/common/counting_new.hpp).
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "airground/comms/link_hub.hpp"
#include "map_fixture.hpp"
#include "stage_rig.hpp"
#include "team_rig.hpp"

#include "../../common/counting_new.hpp"

namespace ag::comms {
namespace {
using test_alloc::AllocationWindow;

TEST(NoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(NoAllocation, GossipNodesExchangingRecordsTilesAndRepairsAfterLoss) {
  test::TempDir dir;
  // A small arena so that compaction runs inside the window; 20 % loss so repairs (have-lists, resends,
  // partial reassemblies) run too.
  test::Team team(3, 0.2, 4, GossipParams{}, StoreLimits{256, 200'000, 65536}, dir.path.string());
  std::mt19937_64 rng(1);
  std::vector<std::vector<std::uint8_t>> blobs;
  for (int k = 0; k < 64; ++k) {
    blobs.emplace_back(static_cast<std::size_t>(40 + (k % 8) * 1500));
    for (auto& b : blobs.back()) b = static_cast<std::uint8_t>(rng());
  }
  for (int k = 0; k < 30; ++k) team.step(100 * kNsPerMs);  // warm up: peers known
  std::uint64_t records_in = 0;
  {
    AllocationWindow window;
    for (int round = 0; round < 40; ++round) {
      for (int i = 0; i < 3; ++i)
        team.node(i).publish(make_topic(TopicKind::kApp, static_cast<std::uint32_t>(round % 10)), 3, team.now(),
                             blobs[static_cast<std::size_t>((round * 3 + i) % 64)]);
      if (round % 10 == 5) team.hub().set_contact(0, 2, false);
      if (round % 10 == 8) team.hub().set_contact(0, 2, true);
      for (int k = 0; k < 5; ++k) team.step(100 * kNsPerMs);
    }
    for (int k = 0; k < 100 && !team.converged(); ++k) team.step(100 * kNsPerMs);
    EXPECT_EQ(window.allocations(), 0U) << "allocations in publish/receive/tick";
  }
  for (int i = 0; i < 3; ++i) records_in += team.node(i).stats().records_in;
  EXPECT_TRUE(team.converged());
  EXPECT_GT(records_in, 100U);
  EXPECT_GT(team.store(0).compactions(), 0U) << "the arena compacted inside the window";
  EXPECT_GT(team.node(0).stats().haves_out, 0U);
}

TEST(NoAllocation, TheStageStepWithTilesPosesAndRecordsBothWays) {
  test::TempDir dir;
  const std::string key = test::write_key_file(dir.file("team.key"));
  LinkHub hub(2, 0.1, 9);
  register_inproc_link("uav", &hub.endpoint(0));
  register_inproc_link("ugv1", &hub.endpoint(1));
  auto uav = test::CommsRig::make("uav", {"robot.id=0", "comms.transport=inproc", "comms.key_file=" + key, "comms.send_map_tiles=true",
                                          "comms.journal=" + dir.file("u.agj"), "comms.digest_period_s=0.2", "comms.store_mb=4"});
  ASSERT_TRUE(uav.ok()) << uav.error().message;
  auto ugv = test::CommsRig::make("ugv1", {"robot.id=1", "comms.transport=inproc", "comms.key_file=" + key, "comms.send_pose=true",
                                           "comms.deliver_map_tiles=true", "probe.read_tiles=true", "comms.journal=" + dir.file("g.agj"),
                                           "comms.digest_period_s=0.2", "comms.store_mb=4"});
  ASSERT_TRUE(ugv.ok()) << ugv.error().message;
  auto& u = *uav.value();
  auto& g = *ugv.value();
  std::vector<std::unique_ptr<MapTileMsg>> tiles;
  for (int k = 0; k < 24; ++k) {
    tiles.push_back(std::make_unique<MapTileMsg>());
    test::make_tile(*tiles.back(), k % 6, k / 6, 200.0, 1 + static_cast<std::uint64_t>(k / 12));
  }
  auto pose = std::make_unique<LocalizationMsg>();
  auto claim = std::make_unique<GossipPublishMsg>();
  claim->topic = make_topic(TopicKind::kClaims, 0);
  claim->size = 64;
  TimeNs now = kNsPerS;
  auto step_both = [&] {
    u.step(now);
    g.step(now);
    for (MapTileMsg* t = g.probe->tiles.front(); t != nullptr; t = g.probe->tiles.front()) g.probe->tiles.pop();
    for (GossipRecordMsg* r = u.probe->records.front(); r != nullptr; r = u.probe->records.front()) u.probe->records.pop();
    now += 50 * kNsPerMs;
  };
  for (int k = 0; k < 20; ++k) step_both();  // warm up
  {
    AllocationWindow window;
    for (int k = 0; k < 24; ++k) {
      (void)u.tiles_w.push(*tiles[static_cast<std::size_t>(k)]);
      pose->stamp = now;
      pose->status = LocalizationStatus::kTracking;
      pose->pose = Pose2{static_cast<double>(k), 1.0, 0.1};
      g.pose_w.publish(*pose);
      claim->payload[0] = static_cast<std::uint8_t>(k);
      (void)g.out_w.push(*claim);
      for (int s = 0; s < 8; ++s) step_both();
    }
    for (int s = 0; s < 100; ++s) step_both();
    EXPECT_EQ(window.allocations(), 0U) << "allocations in CommsStage::step";
  }
  EXPECT_EQ(g.stage->stats().tiles_in, 24U);
  EXPECT_GE(u.stage->team().count, 1U);
  register_inproc_link("uav", nullptr);
  register_inproc_link("ugv1", nullptr);
}

}  // namespace
}  // namespace ag::comms
