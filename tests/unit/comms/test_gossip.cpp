// The gossip protocol over the in-process hub: convergence of 11 robots on a random changing contact
// graph with 30 % loss, a data mule, restart from the journal, priorities and budgets.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>

#include "team_rig.hpp"

namespace ag::comms {
namespace {
using test::Team;

std::vector<std::uint8_t> blob(std::mt19937_64& rng, std::size_t n) {
  std::vector<std::uint8_t> v(n);
  for (auto& b : v) b = static_cast<std::uint8_t>(rng());
  return v;
}

// Every member publishes a pose, a status and a claim; member 0 (the quadrotor) also map tiles.
void publish_round(Team& team, std::mt19937_64& rng, int round) {
  for (int i = 0; i < team.size(); ++i) {
    if (!team.alive(i)) continue;
    GossipNode& n = team.node(i);
    const TimeNs t = team.now();
    n.publish(make_topic(TopicKind::kPose, 0), default_priority(TopicKind::kPose), t, blob(rng, 48));
    if (round % 3 == 0) n.publish(make_topic(TopicKind::kStatus, 0), default_priority(TopicKind::kStatus), t, blob(rng, 24));
    if (round % 4 == i % 4) n.publish(make_topic(TopicKind::kClaims, 0), default_priority(TopicKind::kClaims), t, blob(rng, 40));
    if (i == 0)
      for (int k = 0; k < 4; ++k)
        n.publish(tile_topic(round % 8, k), default_priority(TopicKind::kMapTile), t, blob(rng, 600 + 700 * static_cast<std::size_t>(k)));
  }
}

TEST(Gossip, TwoRobotsExchangeEverythingBothWays) {
  Team team(2, 0.0, 1);
  team.node(0).publish(make_topic(TopicKind::kPose, 0), 5, 1, test::bytes_of("pose of robot 0"));
  team.node(1).publish(make_topic(TopicKind::kFailures, 3), 7, 2, test::bytes_of("robot 1 failed goal 3"));
  std::mt19937_64 rng(3);
  team.node(0).publish(tile_topic(0, 0), 2, 3, blob(rng, 5000));  // several fragments
  const TimeNs t = team.run_until_converged(10 * kNsPerS);
  ASSERT_GE(t, 0) << "did not converge";
  EXPECT_EQ(team.store(1).size(), 3U);
  const auto s = team.store(1).find(RecordKey{0, tile_topic(0, 0)});
  ASSERT_NE(s, RecordStore::kNoSlot);
  EXPECT_EQ(team.store(1).payload(s).size(), 5000U);
  EXPECT_EQ(team.node(1).stats().total_drops(), 0U);
  EXPECT_EQ(team.node(0).peer_stats(1).records_in, 1U);
  EXPECT_EQ(team.node(1).peer_stats(0).records_in, 2U);
  EXPECT_GE(team.node(0).peer_stats(1).records_out, 2U);
}

// 11 robots, a contact graph redrawn every second (each pair in contact with probability 0.2, so the
// graph is usually split), 30 % of datagrams lost. 30 s of updates, then the bound after the last one.
TEST(Gossip, ElevenRobotsRandomChangingContactsThirtyPercentLossConverge) {
  for (std::uint64_t seed : {1ULL, 2ULL, 3ULL}) {
    Team team(11, 0.30, seed);
    std::mt19937_64 rng(seed);
    std::bernoulli_distribution contact(0.2);
    auto redraw = [&] {
      for (int a = 0; a < 11; ++a)
        for (int b = a + 1; b < 11; ++b) team.hub().set_contact(a, b, contact(rng));
    };
    for (int round = 0; round < 30; ++round) {
      redraw();
      publish_round(team, rng, round);
      for (int k = 0; k < 10; ++k) team.step(100 * kNsPerMs);
    }
    const std::uint64_t bytes_before = team.bytes_out();
    int rounds = 0;
    while (!team.converged() && rounds < 60) {
      redraw();
      for (int k = 0; k < 10; ++k) team.step(100 * kNsPerMs);
      ++rounds;
    }
    ASSERT_TRUE(team.converged()) << "seed " << seed << ": not converged 60 rounds after the last update";
    EXPECT_LE(rounds, 30) << "seed " << seed;
    const std::size_t records = team.store(0).size();
    EXPECT_EQ(records, 11U * 3U + 32U) << "pose, status, claims of each robot and 32 tiles";
    std::uint64_t drops = 0, dup = 0;
    for (int i = 0; i < 11; ++i) {
      drops += team.node(i).stats().total_drops();
      dup += team.node(i).stats().duplicates_in;
    }
    EXPECT_EQ(drops, 0U) << "nothing on a team-only hub is refused";
    std::printf("[convergence] seed %llu: 11 robots, 30%% loss, random contacts p=0.2: identical stores (%zu records) "
                "%d rounds (1 s each) after the last update; bytes on the wire %llu during updates, %llu after; "
                "datagrams lost %llu of %llu; duplicate records received %llu\n",
                static_cast<unsigned long long>(seed), records, rounds, static_cast<unsigned long long>(bytes_before),
                static_cast<unsigned long long>(team.bytes_out() - bytes_before),
                static_cast<unsigned long long>(team.hub().stats().lost), static_cast<unsigned long long>(team.hub().stats().sent),
                static_cast<unsigned long long>(dup));
  }
}

// A and C are never in range of each other; B spends 5 s with A, then 5 s with C, and so on.
TEST(Gossip, DataMuleCarriesRecordsBetweenRobotsThatNeverMeet) {
  Team team(3, 0.1, 7);
  const int A = 0, B = 1, C = 2;
  team.hub().set_all_contacts(false);
  team.node(A).publish(make_topic(TopicKind::kRegions, 0), 4, 1, test::bytes_of("regions found by A"));
  team.node(C).publish(make_topic(TopicKind::kClaims, 0), 6, 1, test::bytes_of("C claims goal 5"));
  std::mt19937_64 rng(1);
  team.node(A).publish(tile_topic(1, 1), 2, 1, blob(rng, 9000));
  bool a_has_c = false, c_has_a = false;
  int legs = 0;
  for (; legs < 8 && !(a_has_c && c_has_a); ++legs) {
    const bool at_a = legs % 2 == 0;
    team.hub().set_contact(A, B, at_a);
    team.hub().set_contact(B, C, !at_a);
    for (int k = 0; k < 50; ++k) {
      team.step(100 * kNsPerMs);
      ASSERT_FALSE(team.hub().contact(A, C));
    }
    a_has_c = team.store(A).find(RecordKey{C, make_topic(TopicKind::kClaims, 0)}) != RecordStore::kNoSlot;
    c_has_a = team.store(C).find(RecordKey{A, tile_topic(1, 1)}) != RecordStore::kNoSlot &&
              team.store(C).find(RecordKey{A, make_topic(TopicKind::kRegions, 0)}) != RecordStore::kNoSlot;
  }
  EXPECT_TRUE(a_has_c) << "C's claim reached A through B";
  EXPECT_TRUE(c_has_a) << "A's regions and tile reached C through B";
  EXPECT_EQ(team.node(A).peer_stats(C).datagrams_in, 0U);
  EXPECT_EQ(team.node(C).peer_stats(A).datagrams_in, 0U);
  std::printf("[data mule] A<->C through B in %d legs of 5 s\n", legs);
  EXPECT_TRUE(team.converged());
}

TEST(Gossip, MostImportantAndNewestTravelFirstOnAThinLink) {
  GossipParams p;
  p.budget_bytes_per_s = 3000;  // ~2.5 datagrams a second
  Team team(2, 0.0, 5, p);
  std::mt19937_64 rng(2);
  team.hub().set_all_contacts(false);
  for (int k = 0; k < 20; ++k) team.node(0).publish(tile_topic(k, 0), 2, 100 + k, blob(rng, 1000));
  team.node(0).publish(make_topic(TopicKind::kTrajectory, 0), 1, 500, blob(rng, 100));
  team.node(0).publish(make_topic(TopicKind::kFailures, 1), 7, 50, test::bytes_of("failed goal 1"));
  team.node(0).publish(make_topic(TopicKind::kPose, 0), 5, 60, blob(rng, 48));
  team.hub().set_all_contacts(true);
  // Order of arrival at robot 1.
  std::vector<Topic> order;
  for (int k = 0; k < 400 && order.size() < 23; ++k) {
    team.step(100 * kNsPerMs);
    RecordStore::Slot s;
    while (team.node(1).pending_change(s)) {
      order.push_back(team.store(1).meta(s).key.topic);
      team.node(1).pop_change();
    }
  }
  ASSERT_EQ(order.size(), 23U);
  EXPECT_EQ(order[0], make_topic(TopicKind::kFailures, 1));
  EXPECT_EQ(order[1], make_topic(TopicKind::kPose, 0));
  EXPECT_EQ(order[2], tile_topic(19, 0)) << "newest tile first";
  EXPECT_EQ(order[21], tile_topic(0, 0));
  EXPECT_EQ(order[22], make_topic(TopicKind::kTrajectory, 0));
}

TEST(Gossip, BudgetCapsTheBytesAPeerLinkCarries) {
  GossipParams p;
  p.budget_bytes_per_s = 20'000;
  p.broadcast_budget_bytes_per_s = 2'000;
  Team team(2, 0.0, 9, p);
  std::mt19937_64 rng(4);
  for (int k = 0; k < 100; ++k) team.node(0).publish(tile_topic(k % 16, k / 16), 2, k, blob(rng, 3000));
  for (int k = 0; k < 50; ++k) team.step(100 * kNsPerMs);  // 5 s
  const double sent = static_cast<double>(team.node(0).peer_stats(1).bytes_out);
  const double allowed = 20'000 * 5.0 + 20'000 * 0.25 + 2 * 1228;
  std::printf("[budget] 5 s at 20000 B/s: %.0f B sent to the peer (cap %.0f with the burst)\n", sent, allowed);
  EXPECT_LE(sent, allowed);
  EXPECT_GE(sent, 0.8 * 20'000 * 5.0) << "the budget is used, not wasted";
  EXPECT_FALSE(team.converged()) << "300 kB cannot pass in 5 s at 20 kB/s";
  EXPECT_GE(team.run_until_converged(60 * kNsPerS), 0);
}

// A robot killed mid-exchange (a big tile half received, queues full) restarts: its own records come
// back from its journal, the rest from its peers; nothing is lost, nothing duplicated.
TEST(Gossip, RestartMidExchangeRecoversFromDiskAndPeers) {
  test::TempDir dir;
  GossipParams slow;
  slow.budget_bytes_per_s = 40'000;  // a 30 kB tile takes most of a second
  Team team(4, 0.2, 11, slow, Team::kTestLimits, dir.path.string());
  std::mt19937_64 rng(8);
  std::map<std::pair<int, Topic>, std::vector<std::uint8_t>> truth;  // latest payload per key
  auto pub = [&](int who, Topic t, std::size_t n) {
    auto b = blob(rng, n);
    ASSERT_EQ(team.node(who).publish(t, default_priority(topic_kind(t)), team.now(), b) == PutResult::kFull, false);
    truth[{who, t}] = b;
  };
  for (int r = 0; r < 5; ++r) {
    for (int i = 0; i < 4; ++i) pub(i, make_topic(TopicKind::kPose, 0), 48);
    pub(2, make_topic(TopicKind::kClaims, static_cast<std::uint32_t>(r)), 30);
    for (int k = 0; k < 10; ++k) team.step(100 * kNsPerMs);
  }
  pub(0, tile_topic(3, 3), 30'000);  // ~27 fragments
  pub(1, tile_topic(4, 4), 30'000);
  // Step until the tiles are on their way to robot 2 (its peers' queues to it hold them), then once more
  // so that some of their fragments have arrived: it dies in the middle of that exchange.
  for (int k = 0; k < 40 && team.node(0).queued_to(2) + team.node(1).queued_to(2) == 0; ++k) team.step(100 * kNsPerMs);
  team.step(100 * kNsPerMs);
  ASSERT_GT(team.node(0).queued_to(2) + team.node(1).queued_to(2) + team.node(3).queued_to(2), 0U)
      << "killed while records to it were still queued";
  const bool tiles_complete_at_kill = team.store(2).find(RecordKey{0, tile_topic(3, 3)}) != RecordStore::kNoSlot &&
                                      team.store(2).find(RecordKey{1, tile_topic(4, 4)}) != RecordStore::kNoSlot;
  EXPECT_FALSE(tiles_complete_at_kill) << "killed before both big tiles had arrived";
  const std::uint64_t own_max_seq = team.store(2).summary(2).max_seq;
  const std::size_t before = team.store(2).size();
  team.kill(2);
  // A torn last entry, as a power cut in the middle of a write leaves.
  {
    std::ofstream f(dir.file("robot2.agj"), std::ios::app | std::ios::binary);
    const std::uint8_t torn[] = {0x41, 0x47, 0x4A, 0x31, 200, 0, 0, 0, 1, 2, 3};
    f.write(reinterpret_cast<const char*>(torn), sizeof torn);
  }
  for (int i = 0; i < 4; ++i)
    if (i != 2) pub(i, make_topic(TopicKind::kStatus, 0), 20);  // the others go on while it is down
  for (int k = 0; k < 30; ++k) team.step(100 * kNsPerMs);

  team.start(2);
  const JournalReport& rep = team.member(2).report;
  std::printf("[restart] journal: %zu entries, %zu records, %zu bad region(s), %zu bad bytes\n%s", rep.entries,
              rep.records_loaded, rep.bad_regions, rep.bad_bytes, rep.problems.c_str());
  EXPECT_EQ(rep.bad_regions, 1U);
  EXPECT_EQ(rep.bad_bytes, 11U);
  EXPECT_NE(rep.problems.find("torn tail"), std::string::npos);
  EXPECT_EQ(team.store(2).size(), before) << "everything it had stored came back from disk";
  EXPECT_EQ(team.store(2).summary(2).max_seq, own_max_seq) << "its own records came back from disk";
  for (std::uint32_t r = 0; r < 5; ++r)
    EXPECT_NE(team.store(2).find(RecordKey{2, make_topic(TopicKind::kClaims, r)}), RecordStore::kNoSlot);
  EXPECT_GT(team.node(2).next_seq(), own_max_seq) << "no seq is reused after a restart";
  pub(2, make_topic(TopicKind::kPose, 0), 48);
  ASSERT_GE(team.run_until_converged(60 * kNsPerS), 0) << "the restarted robot rejoined";
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(team.store(i).size(), truth.size()) << "robot " << i << ": every key once";
    for (const auto& [k, payload] : truth) {
      const auto s = team.store(i).find(RecordKey{static_cast<RobotId>(k.first), k.second});
      ASSERT_NE(s, RecordStore::kNoSlot) << "robot " << i << " lacks a record of " << k.first;
      const auto p = team.store(i).payload(s);
      ASSERT_TRUE(std::equal(p.begin(), p.end(), payload.begin(), payload.end())) << "robot " << i << ": latest payload";
    }
  }
  // The rewritten journal holds each key once: reopening it loads exactly the store.
  team.kill(2);
  RecordStore again(Team::kTestLimits);
  JournalReport rep2;
  auto j = Journal::open(dir.file("robot2.agj"), again, 1, rep2);
  ASSERT_TRUE(j.ok());
  EXPECT_EQ(rep2.bad_regions, 0U);
  EXPECT_EQ(again.size(), truth.size());
  EXPECT_EQ(rep2.previous_epoch, 2U);
  EXPECT_EQ(j.value()->epoch(), 3U);
}

}  // namespace
}  // namespace ag::comms
