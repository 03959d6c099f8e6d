// The record store: latest per (origin, topic), digest summaries, arena compaction, fixed limits.
#include <gtest/gtest.h>

#include <vector>

#include "airground/comms/record_store.hpp"

namespace ag::comms {
namespace {

RecordMeta meta(RobotId o, Topic t, std::uint64_t seq, std::uint8_t prio = 3) {
  RecordMeta m;
  m.key = RecordKey{o, t};
  m.seq = seq;
  m.priority = prio;
  m.stamp = static_cast<TimeNs>(seq) * 10;
  return m;
}
std::vector<std::uint8_t> payload(std::size_t n, std::uint8_t v) { return std::vector<std::uint8_t>(n, v); }

TEST(RecordStore, KeepsOnlyTheLatestSeqPerKey) {
  RecordStore s(StoreLimits{16, 4096, 512});
  const Topic pose = make_topic(TopicKind::kPose, 0);
  EXPECT_EQ(s.put(meta(1, pose, 5), payload(10, 5)), PutResult::kNew);
  EXPECT_EQ(s.put(meta(1, pose, 4), payload(10, 4)), PutResult::kStale);
  EXPECT_EQ(s.put(meta(1, pose, 5), payload(10, 9)), PutResult::kStale) << "a duplicate changes nothing";
  EXPECT_EQ(s.put(meta(1, pose, 7), payload(3, 7)), PutResult::kReplaced);
  ASSERT_EQ(s.size(), 1U);
  const auto slot = s.find(RecordKey{1, pose});
  EXPECT_EQ(s.meta(slot).seq, 7U);
  ASSERT_EQ(s.payload(slot).size(), 3U);
  EXPECT_EQ(s.payload(slot)[0], 7);
  EXPECT_EQ(s.find(RecordKey{2, pose}), RecordStore::kNoSlot);
}

TEST(RecordStore, SummaryHashDependsOnVersionsNotOnArrivalOrder) {
  RecordStore a(StoreLimits{64, 1 << 16, 512}), b(StoreLimits{64, 1 << 16, 512});
  for (std::uint32_t t = 0; t < 20; ++t) a.put(meta(3, make_topic(TopicKind::kMapTile, t), 100 + t), payload(20, 1));
  for (std::uint32_t t = 20; t-- > 0;) b.put(meta(3, make_topic(TopicKind::kMapTile, t), 100 + t), payload(20, 1));
  EXPECT_EQ(a.summary(3), b.summary(3));
  EXPECT_EQ(a.content_hash(), b.content_hash());
  b.put(meta(3, make_topic(TopicKind::kMapTile, 4), 500), payload(20, 1));
  EXPECT_NE(a.summary(3).hash, b.summary(3).hash);
  EXPECT_EQ(b.summary(3).count, 20U);
  EXPECT_EQ(b.summary(3).max_seq, 500U);
  EXPECT_EQ(a.summary(4).count, 0U);
}

TEST(RecordStore, CompactsTheArenaInsteadOfRunningOut) {
  RecordStore s(StoreLimits{8, 1000, 400});
  // 4 keys of 200 B = 800 B live; rewriting them 50 times would need 40 kB without compaction.
  for (std::uint64_t round = 1; round <= 50; ++round)
    for (std::uint32_t t = 0; t < 4; ++t)
      ASSERT_NE(s.put(meta(1, make_topic(TopicKind::kApp, t), round * 10 + t), payload(200, static_cast<std::uint8_t>(round))),
                PutResult::kFull) << "round " << round;
  EXPECT_GT(s.compactions(), 10U);
  for (std::uint32_t t = 0; t < 4; ++t) {
    const auto p = s.payload(s.find(RecordKey{1, make_topic(TopicKind::kApp, t)}));
    ASSERT_EQ(p.size(), 200U);
    for (auto v : p) ASSERT_EQ(v, 50) << "compaction kept the latest payload";
  }
  EXPECT_EQ(s.payload_bytes(), 800U);
}

TEST(RecordStore, RefusesBeyondItsLimitsAndKeepsWhatItHas) {
  RecordStore s(StoreLimits{2, 300, 200});
  EXPECT_EQ(s.put(meta(1, 1, 1), payload(201, 0)), PutResult::kTooLarge);
  EXPECT_EQ(s.put(meta(1, make_topic(TopicKind::kApp, 1), 1), payload(150, 1)), PutResult::kNew);
  EXPECT_EQ(s.put(meta(1, make_topic(TopicKind::kApp, 2), 2), payload(150, 2)), PutResult::kNew);
  EXPECT_EQ(s.put(meta(1, make_topic(TopicKind::kApp, 3), 3), payload(1, 3)), PutResult::kFull) << "no key slot left";
  // 150 + 150 live; replacing one with 200 B needs 350 > 300: refused, and the old version survives.
  EXPECT_EQ(s.put(meta(1, make_topic(TopicKind::kApp, 1), 4), payload(200, 4)), PutResult::kFull);
  const auto slot = s.find(RecordKey{1, make_topic(TopicKind::kApp, 1)});
  EXPECT_EQ(s.meta(slot).seq, 1U);
  EXPECT_EQ(s.payload(slot).size(), 150U);
  EXPECT_EQ(s.payload(slot)[149], 1);
}

TEST(Topics, TileIndicesRoundTrip) {
  for (int tx : {-2048, -9, 0, 7, 2047})
    for (int ty : {-2048, -1, 0, 15, 2047}) {
      const Topic t = tile_topic(tx, ty);
      EXPECT_EQ(topic_kind(t), TopicKind::kMapTile);
      EXPECT_EQ(tile_topic_tx(t), tx);
      EXPECT_EQ(tile_topic_ty(t), ty);
    }
  EXPECT_NE(tile_topic(1, 2), tile_topic(2, 1));
}

}  // namespace
}  // namespace ag::comms
