// The mission records as the base station reads them (the mission codec's decode_detailed) against byte
// layouts written out by hand from the records table, and every kind of malformed payload.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "airground/base_station/model.hpp"
#include "airground/base_station/records.hpp"

namespace ag::base_station {
namespace {

using mission::ClaimRecord;
using mission::ClaimState;
using mission::DecodeError;
using mission::FailureReason;
using mission::FailureRecord;
using mission::kClaimBytes;
using mission::kRegionBatchHeader;
using mission::kRegionEntryBytes;
using mission::ObjectRecord;
using mission::RegionBatch;
using mission::RegionRecord;
using mission::VisitedRecord;

void put32(std::vector<std::uint8_t>& v, std::uint32_t x) {
  for (int i = 0; i < 4; ++i) v.push_back(static_cast<std::uint8_t>(x >> (8 * i)));
}
void putf(std::vector<std::uint8_t>& v, float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  put32(v, u);
}

TEST(Records, ClaimLayoutByHand) {
  std::vector<std::uint8_t> b = {1, 1, 3, 0};  // format, state going, priority 3, reserved
  put32(b, 0x01020304);
  putf(b, 12.5f);
  putf(b, -7.25f);
  putf(b, 0.75f);
  ASSERT_EQ(b.size(), kClaimBytes);
  ClaimRecord c;
  ASSERT_EQ(decode_detailed(b, c), DecodeError::kOk);
  EXPECT_EQ(c.state, ClaimState::kGoing);
  EXPECT_EQ(c.priority, 3);
  EXPECT_EQ(c.region_id, 0x01020304u);
  EXPECT_FLOAT_EQ(c.goal_x, 12.5f);
  EXPECT_FLOAT_EQ(c.goal_y, -7.25f);
  EXPECT_FLOAT_EQ(c.pose_sigma_m, 0.75f);
  std::uint8_t enc[64];
  ASSERT_EQ(encode(c, enc), kClaimBytes);
  EXPECT_EQ(std::vector<std::uint8_t>(enc, enc + kClaimBytes), b);
  // malformed
  EXPECT_EQ(decode_detailed(std::span<const std::uint8_t>(b.data(), 19), c), DecodeError::kTruncated);
  auto longer = b;
  longer.push_back(0);
  EXPECT_EQ(decode_detailed(longer, c), DecodeError::kTrailing);
  auto fmt = b;
  fmt[0] = 2;
  EXPECT_EQ(decode_detailed(fmt, c), DecodeError::kFormat);
  auto state = b;
  state[1] = 9;
  EXPECT_EQ(decode_detailed(state, c), DecodeError::kValue);
  auto nan = b;
  const float q = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(nan.data() + 8, &q, 4);
  EXPECT_EQ(decode_detailed(nan, c), DecodeError::kNotFinite);
  EXPECT_EQ(decode_detailed({}, c), DecodeError::kTruncated);
}

TEST(Records, RegionsLayoutByHandAndLimits) {
  std::vector<std::uint8_t> b = {1, 2, 3, 0};  // format, count 2, batches 3
  put32(b, 77);                                // version
  for (std::uint32_t id : {5u, 9u}) {
    put32(b, id);
    putf(b, 1.0f * static_cast<float>(id));
    putf(b, 2.0f);
    putf(b, 3.0f);
    putf(b, 4.0f);
    b.push_back(40);
    b.push_back(1);  // cells 296 (0x128)
    b.push_back(1);  // flags: goal valid
    b.push_back(0);
  }
  ASSERT_EQ(b.size(), kRegionBatchHeader + 2 * kRegionEntryBytes);
  RegionBatch r;
  ASSERT_EQ(decode_detailed(b, r), DecodeError::kOk);
  EXPECT_EQ(r.count, 2);
  EXPECT_EQ(r.batches, 3);
  EXPECT_EQ(r.regions_version, 77u);
  EXPECT_EQ(r.regions[1].id, 9u);
  EXPECT_FLOAT_EQ(r.regions[1].cx, 9.0f);
  EXPECT_EQ(r.regions[1].cells, 296);
  EXPECT_TRUE(r.regions[1].goal_valid);
  std::uint8_t enc[1024];
  ASSERT_EQ(encode(r, enc), b.size());
  EXPECT_EQ(std::vector<std::uint8_t>(enc, enc + b.size()), b);
  auto many = b;
  many[1] = 41;
  EXPECT_EQ(decode_detailed(many, r), DecodeError::kCount);
  auto shortb = b;
  shortb.pop_back();
  EXPECT_EQ(decode_detailed(shortb, r), DecodeError::kTruncated);
  auto nob = b;
  nob[2] = 0;
  EXPECT_EQ(decode_detailed(nob, r), DecodeError::kValue) << "zero batches";
}

TEST(Records, VisitedFailureObjectRoundTripAndSizes) {
  VisitedRecord v;
  v.count = 2;
  v.entries[0] = {3, 1.5f, 2.5f};
  v.entries[1] = {4, -1.0f, 8.0f};
  std::uint8_t b[1024];
  const std::size_t nv = encode(v, b);
  ASSERT_EQ(nv, 4U + 2 * 12U);
  EXPECT_EQ(b[2], 2);  // count u16 at offset 2
  VisitedRecord v2;
  ASSERT_EQ(decode_detailed({b, nv}, v2), DecodeError::kOk);
  EXPECT_EQ(v2.entries[1].region_id, 4u);
  EXPECT_FLOAT_EQ(v2.entries[1].y, 8.0f);
  b[2] = 81;
  EXPECT_EQ(decode_detailed({b, 4 + 81 * 12}, v2), DecodeError::kCount);

  const std::size_t nf = encode(FailureRecord{FailureReason::kNoProgress, 300, 17, 4.0f, 5.0f}, b);
  ASSERT_EQ(nf, 16U);
  EXPECT_EQ(b[2] | (b[3] << 8), 300);  // attempts
  FailureRecord f;
  ASSERT_EQ(decode_detailed({b, nf}, f), DecodeError::kOk);
  EXPECT_EQ(f.region_id, 17u);
  EXPECT_EQ(f.reason, FailureReason::kNoProgress);
  EXPECT_STREQ(to_string(f.reason), "no_progress");

  const std::size_t no = encode(ObjectRecord{5, 12, 99, 1.0f, 2.0f, 0.5f, 0.1f, 0.4f}, b);
  ASSERT_EQ(no, 28U);
  ObjectRecord o;
  ASSERT_EQ(decode_detailed({b, no}, o), DecodeError::kOk);
  EXPECT_EQ(o.object_id, 99u);
  EXPECT_EQ(o.detections, 12);
  EXPECT_FLOAT_EQ(o.cyy, 0.4f);
}

TEST(Records, TopicsMapToKinds) {
  using comms::TopicKind;
  EXPECT_EQ(record_kind(comms::make_topic(TopicKind::kRegions, 3)), RecordKind::kRegions);
  EXPECT_EQ(record_kind(comms::make_topic(TopicKind::kClaims, 0)), RecordKind::kClaim);
  EXPECT_EQ(record_kind(comms::make_topic(TopicKind::kClaims, 1)), RecordKind::kVisited);
  EXPECT_EQ(record_kind(comms::make_topic(TopicKind::kClaims, 2)), RecordKind::kOther);
  EXPECT_EQ(record_kind(comms::make_topic(TopicKind::kFailures, 13)), RecordKind::kFailure);
  EXPECT_EQ(record_kind(comms::make_topic(TopicKind::kApp, mission::kObjectIndexBase | 4)), RecordKind::kObject);
  EXPECT_EQ(record_kind(comms::make_topic(TopicKind::kApp, 4)), RecordKind::kOther);
}

comms::GossipRecordMsg rec(comms::RobotId origin, comms::Topic t, const std::uint8_t* b, std::size_t n) {
  comms::GossipRecordMsg r;
  r.key = {origin, t};
  r.size = static_cast<std::uint32_t>(n);
  std::memcpy(r.payload.data(), b, n);
  return r;
}

TEST(MissionModel, RegionVersionsBatchesClaimsAndBadRecordsKeepTheModel) {
  auto m = std::make_unique<MissionModel>();
  std::uint8_t b[1024];
  DecodeError e{};
  RegionBatch r;
  r.count = 2;
  r.batches = 2;
  r.regions_version = 5;
  r.regions[0] = {1, 0, 0, 0, 0, 10, true};
  r.regions[1] = {2, 0, 0, 0, 0, 10, true};
  std::size_t n = encode(r, b);
  m->apply_record(rec(0, comms::make_topic(comms::TopicKind::kRegions, 0), b, n), 1, e);
  r.regions[0].id = 3;
  r.count = 1;
  n = encode(r, b);
  m->apply_record(rec(0, comms::make_topic(comms::TopicKind::kRegions, 1), b, n), 2, e);
  int shown = 0;
  m->for_each_region([&](const RegionRecord&) { ++shown; });
  EXPECT_EQ(shown, 3);
  // A new version with one batch: batch 1 of the old one is no longer shown.
  r.regions_version = 6;
  r.batches = 1;
  r.count = 1;
  r.regions[0].id = 7;
  n = encode(r, b);
  m->apply_record(rec(0, comms::make_topic(comms::TopicKind::kRegions, 0), b, n), 3, e);
  std::vector<std::uint32_t> ids;
  m->for_each_region([&](const RegionRecord& x) { ids.push_back(x.id); });
  EXPECT_EQ(ids, std::vector<std::uint32_t>{7});
  // An older version arriving late is refused.
  r.regions_version = 5;
  r.regions[0].id = 8;
  n = encode(r, b);
  m->apply_record(rec(0, comms::make_topic(comms::TopicKind::kRegions, 0), b, n), 4, e);
  ids.clear();
  m->for_each_region([&](const RegionRecord& x) { ids.push_back(x.id); });
  EXPECT_EQ(ids, std::vector<std::uint32_t>{7});
  EXPECT_EQ(m->counters.stale_regions, 1U);
  // A truncated regions batch neither clears nor changes what is shown.
  m->apply_record(rec(0, comms::make_topic(comms::TopicKind::kRegions, 0), b, 5), 5, e);
  EXPECT_EQ(e, DecodeError::kTruncated);
  ids.clear();
  m->for_each_region([&](const RegionRecord& x) { ids.push_back(x.id); });
  EXPECT_EQ(ids, std::vector<std::uint32_t>{7});
  // Claims per robot; a bad claim leaves the good one and is counted with its origin.
  n = encode(ClaimRecord{ClaimState::kGoing, 2, 7, 1.0f, 2.0f, 0.3f}, b);
  m->apply_record(rec(4, comms::make_topic(comms::TopicKind::kClaims, 0), b, n), 6, e);
  b[0] = 9;
  m->apply_record(rec(4, comms::make_topic(comms::TopicKind::kClaims, 0), b, n), 7, e);
  EXPECT_EQ(e, DecodeError::kFormat);
  const RobotView* v = m->find_robot(4);
  ASSERT_NE(v, nullptr);
  ASSERT_TRUE(v->has_claim);
  EXPECT_EQ(v->claim.region_id, 7u);
  EXPECT_EQ(m->counters.decode_errors, 2U);
  EXPECT_EQ(m->counters.last_error_origin, 4);
  // Failures are keyed by (robot, region): a repeat replaces, another robot adds.
  n = encode(FailureRecord{FailureReason::kNoRoute, 1, 7, 0, 0}, b);
  m->apply_record(rec(4, comms::make_topic(comms::TopicKind::kFailures, 7), b, n), 8, e);
  n = encode(FailureRecord{FailureReason::kNoRoute, 2, 7, 0, 0}, b);
  m->apply_record(rec(4, comms::make_topic(comms::TopicKind::kFailures, 7), b, n), 9, e);
  m->apply_record(rec(5, comms::make_topic(comms::TopicKind::kFailures, 7), b, n), 9, e);
  EXPECT_EQ(m->failure_count, 2U);
  EXPECT_EQ(m->failures[0].f.attempts, 2);
}

// What the robots encode (the mission codec, on the mission's topics) is what the model holds.
TEST(MissionModel, HoldsTheRecordsTheRobotsEncode) {
  auto m = std::make_unique<MissionModel>();
  std::uint8_t b[1024];
  DecodeError e{};
  RegionBatch r;
  r.count = 2;
  r.batches = 1;
  r.regions_version = 3;
  r.regions[0] = {4, 1.5f, 2.5f, 3.5f, 4.5f, 12, true};
  r.regions[1] = {6, -1.5f, 8.0f, 0.0f, 0.0f, 300, false};
  std::size_t n = encode(r, b);
  EXPECT_EQ(m->apply_record(rec(0, mission::regions_topic(0), b, n), 1, e), RecordKind::kRegions);
  EXPECT_EQ(e, DecodeError::kOk);
  std::vector<RegionRecord> shown;
  m->for_each_region([&](const RegionRecord& x) { shown.push_back(x); });
  EXPECT_EQ(shown, (std::vector<RegionRecord>{r.regions[0], r.regions[1]}));
  EXPECT_EQ(m->regions_version, 3U);

  const ClaimRecord c{ClaimState::kReturning, 3, 4, 3.5f, 4.5f, 0.25f};
  n = encode(c, b);
  EXPECT_EQ(m->apply_record(rec(1, mission::kClaimTopic, b, n), 2, e), RecordKind::kClaim);
  VisitedRecord v;
  v.count = 2;
  v.entries[0] = {4, 3.25f, 4.75f};
  v.entries[1] = {9, -3.0f, 0.5f};
  n = encode(v, b);
  EXPECT_EQ(m->apply_record(rec(1, mission::kVisitedTopic, b, n), 3, e), RecordKind::kVisited);
  const FailureRecord f{FailureReason::kBlocked, 5, 6, -1.5f, 8.0f};
  n = encode(f, b);
  EXPECT_EQ(m->apply_record(rec(2, mission::failure_topic(6), b, n), 4, e), RecordKind::kFailure);
  const ObjectRecord o{5, 7, 9, 10.0f, 11.0f, 0.1f, -0.02f, 0.2f};
  n = encode(o, b);
  EXPECT_EQ(m->apply_record(rec(2, mission::object_topic(9), b, n), 5, e), RecordKind::kObject);
  EXPECT_EQ(m->counters.decode_errors, 0U);

  const RobotView* r1 = m->find_robot(1);
  ASSERT_NE(r1, nullptr);
  ASSERT_TRUE(r1->has_claim);
  EXPECT_EQ(r1->claim, c);
  ASSERT_TRUE(r1->has_visited);
  ASSERT_EQ(r1->visited.count, 2U);
  EXPECT_EQ(r1->visited.entries[0], v.entries[0]);
  EXPECT_EQ(r1->visited.entries[1], v.entries[1]);
  ASSERT_EQ(m->failure_count, 1U);
  EXPECT_EQ(m->failures[0].origin, 2);
  EXPECT_EQ(m->failures[0].f, f);
  ASSERT_EQ(m->object_count, 1U);
  EXPECT_EQ(m->objects[0].o, o);
}

TEST(MissionModel, TrailsGrowWithMovementNotWithRepeats) {
  auto m = std::make_unique<MissionModel>();
  comms::TeamPosesMsg t;
  t.count = 1;
  t.robots[0].robot = 2;
  for (int k = 0; k < 10; ++k) {
    t.robots[0].stamp = (k + 1) * kNsPerS;
    t.robots[0].pose = Pose2{k < 5 ? 1.0 * k : 4.0, 0.0, 0.0};  // moves 1 m a step, then stands
    m->apply_poses(t, k);
  }
  const RobotView* r = m->find_robot(2);
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->trail_count, 5U);
  EXPECT_FALSE(m->apply_poses(t, 20)) << "the same stamp again changes nothing";
  t.robots[0].stamp = 100 * kNsPerS;
  t.robots[0].pose.x = std::nan("");
  m->apply_poses(t, 21);
  EXPECT_FLOAT_EQ(m->find_robot(2)->x, 4.0f) << "a non-finite pose is refused";
  EXPECT_EQ(m->counters.decode_errors, 1U);
}

}  // namespace
}  // namespace ag::base_station
