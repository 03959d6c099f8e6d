// The mission's gossip record formats: byte layout, round trips, and every kind of malformed payload.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "airground/comms/messages.hpp"
#include "airground/mission/records.hpp"

namespace ag::mission {
namespace {

using Buf = std::array<std::uint8_t, comms::kGossipPayloadMax>;

TEST(Records, RegionBatchLayoutAndRoundTrip) {
  RegionBatch b;
  b.count = 2;
  b.batches = 3;
  b.regions_version = 0x01020304;
  b.regions[0] = RegionRecord{7, 1.5f, -2.0f, 3.0f, 4.0f, 36, true};
  b.regions[1] = RegionRecord{0xAABBCCDD, 10.f, 20.f, 30.f, 40.f, 500, false};
  Buf buf{};
  const std::size_t n = encode(b, buf);
  ASSERT_EQ(n, 8U + 2 * 24U);
  // header: format 1, count 2, batches 3 (LE u16), version (LE u32)
  EXPECT_EQ(buf[0], 1);
  EXPECT_EQ(buf[1], 2);
  EXPECT_EQ(buf[2], 3);
  EXPECT_EQ(buf[3], 0);
  EXPECT_EQ(buf[4], 0x04);
  EXPECT_EQ(buf[7], 0x01);
  // entry 0: id 7, cx = 1.5f little-endian, flags bit0 at byte 8 + 22
  EXPECT_EQ(buf[8], 7);
  float cx = 0;
  std::memcpy(&cx, &buf[12], 4);
  EXPECT_EQ(cx, 1.5f);
  EXPECT_EQ(buf[8 + 20], 36);
  EXPECT_EQ(buf[8 + 22], 1);
  EXPECT_EQ(buf[8 + 24 + 22], 0);
  RegionBatch d;
  ASSERT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), d), DecodeError::kOk);
  EXPECT_EQ(d.count, 2);
  EXPECT_EQ(d.batches, 3);
  EXPECT_EQ(d.regions_version, 0x01020304U);
  EXPECT_EQ(d.regions[0], b.regions[0]);
  EXPECT_EQ(d.regions[1], b.regions[1]);
  // 40 regions fit the gossip payload; 41 do not encode
  b.count = 40;
  EXPECT_EQ(encode(b, buf), 8U + 40 * 24U);
  b.count = 41;
  EXPECT_EQ(encode(b, buf), 0U);
}

TEST(Records, EveryTruncationAndExtensionIsAnError) {
  RegionBatch b;
  b.count = 3;
  b.batches = 1;
  ClaimRecord c{ClaimState::kGoing, 2, 9, 1.f, 2.f, 0.5f};
  VisitedRecord v;
  v.count = 2;
  v.entries[0] = VisitedEntry{3, 1.f, 1.f};
  FailureRecord f{FailureReason::kNoProgress, 2, 5, 1.f, 2.f};
  ObjectRecord o{5, 3, 11, 1.f, 2.f, 0.2f, 0.01f, 0.3f};
  Buf eb{};
  auto check = [&](auto rec, const char* what) {
    const std::size_t n = encode(rec, eb);
    ASSERT_GT(n, 0U) << what;
    for (std::size_t k = 0; k < n; ++k) {
      decltype(rec) out;
      EXPECT_NE(decode(std::span<const std::uint8_t>(eb.data(), k), out), DecodeError::kOk) << what << " truncated to " << k;
    }
    decltype(rec) out;
    EXPECT_EQ(decode(std::span<const std::uint8_t>(eb.data(), n), out), DecodeError::kOk) << what;
    EXPECT_EQ(decode(std::span<const std::uint8_t>(eb.data(), n + 1), out), DecodeError::kTrailing) << what;
    eb[0] = 2;
    EXPECT_EQ(decode(std::span<const std::uint8_t>(eb.data(), n), out), DecodeError::kFormat) << what;
  };
  check(b, "regions");
  check(c, "claim");
  check(v, "visited");
  check(f, "failure");
  check(o, "object");
}

TEST(Records, OutOfRangeValuesAreRejected) {
  Buf buf{};
  // claim state 6
  ClaimRecord c{ClaimState::kGoing, 1, 1, 0, 0, 0};
  std::size_t n = encode(c, buf);
  buf[1] = 6;
  ClaimRecord co;
  EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), co), DecodeError::kValue);
  // NaN goal
  c.goal_x = std::numeric_limits<float>::quiet_NaN();
  n = encode(c, buf);
  EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), co), DecodeError::kValue);
  // failure reason 0 and 5
  FailureRecord f{FailureReason::kNoRoute, 1, 1, 0, 0};
  n = encode(f, buf);
  FailureRecord fo;
  for (std::uint8_t r : {std::uint8_t{0}, std::uint8_t{5}}) {
    buf[1] = r;
    EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), fo), DecodeError::kValue);
  }
  // region count 41 in the header
  RegionBatch b;
  b.count = 1;
  b.batches = 1;
  n = encode(b, buf);
  buf[1] = 41;
  RegionBatch bo;
  EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), bo), DecodeError::kCount);
  // zero batches
  buf[1] = 1;
  buf[2] = 0;
  EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), bo), DecodeError::kValue);
  // visited count 81
  VisitedRecord v;
  n = encode(v, buf);
  buf[2] = 81;
  VisitedRecord vo;
  EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), vo), DecodeError::kCount);
  // an object with a negative variance
  ObjectRecord o{5, 1, 1, 0, 0, -1.f, 0, 1.f};
  n = encode(o, buf);
  ObjectRecord oo;
  EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), oo), DecodeError::kValue);
}

TEST(Records, RandomBytesNeverCrashAndAFailedDecodeLeavesTheOutputAlone) {
  std::mt19937 rng(3);
  Buf buf{};
  std::size_t ok = 0;
  for (int it = 0; it < 20000; ++it) {
    const std::size_t n = rng() % 1025;
    for (std::size_t i = 0; i < n; ++i) buf[i] = static_cast<std::uint8_t>(rng());
    if (it % 2 == 0 && n > 0) buf[0] = 1;
    const std::span<const std::uint8_t> in(buf.data(), n);
    RegionBatch b;
    b.regions_version = 77;
    if (decode(in, b) == DecodeError::kOk) {
      ++ok;
    } else {
      EXPECT_EQ(b.regions_version, 77U);
    }
    ClaimRecord c;
    c.region_id = 5;
    if (decode(in, c) == DecodeError::kOk) {
      ++ok;
    } else {
      EXPECT_EQ(c.region_id, 5U);
    }
    VisitedRecord v;
    (void)decode(in, v);
    FailureRecord f;
    (void)decode(in, f);
    ObjectRecord o;
    (void)decode(in, o);
  }
  SUCCEED() << ok << " random payloads happened to decode";
}

// decode_detailed() (the base station's) is decode() (the robots') but for naming a non-finite float.
TEST(Records, DetailedDecodeDiffersOnlyInNamingANonFiniteFloat) {
  Buf buf{};
  ClaimRecord c{ClaimState::kGoing, 1, 1, std::numeric_limits<float>::infinity(), 0, 0};
  std::size_t n = encode(c, buf);
  ClaimRecord co;
  EXPECT_EQ(decode(std::span<const std::uint8_t>(buf.data(), n), co), DecodeError::kValue);
  EXPECT_EQ(decode_detailed(std::span<const std::uint8_t>(buf.data(), n), co), DecodeError::kNotFinite);
  EXPECT_STREQ(to_string(DecodeError::kNotFinite), "non-finite number");
  std::mt19937 rng(5);
  const auto same = [](DecodeError coarse, DecodeError detailed) {
    return coarse == (detailed == DecodeError::kNotFinite ? DecodeError::kValue : detailed);
  };
  for (int it = 0; it < 20000; ++it) {
    for (std::size_t i = 0; i < 1024; ++i) buf[i] = static_cast<std::uint8_t>(rng());
    buf[0] = kRecordFormat;
    const auto k = static_cast<std::uint8_t>(rng() % 4);
    switch (it % 6) {  // mostly the exact sizes, so that the values get checked
      case 0: n = kClaimBytes; break;
      case 1: n = kFailureBytes; break;
      case 2: n = kObjectBytes; break;
      case 3:
        buf[1] = k;
        n = kRegionBatchHeader + kRegionEntryBytes * k;
        break;
      case 4:
        buf[2] = k;
        buf[3] = 0;
        n = kVisitedHeader + kVisitedEntryBytes * k;
        break;
      default: n = rng() % 1025;
    }
    const std::span<const std::uint8_t> in(buf.data(), n);
    RegionBatch b1, b2;
    EXPECT_TRUE(same(decode(in, b1), decode_detailed(in, b2)));
    EXPECT_EQ(b1.regions_version, b2.regions_version);
    ClaimRecord c1, c2;
    EXPECT_TRUE(same(decode(in, c1), decode_detailed(in, c2)));
    EXPECT_EQ(c1, c2);
    VisitedRecord v1, v2;
    EXPECT_TRUE(same(decode(in, v1), decode_detailed(in, v2)));
    EXPECT_EQ(v1.count, v2.count);
    FailureRecord f1, f2;
    EXPECT_TRUE(same(decode(in, f1), decode_detailed(in, f2)));
    EXPECT_EQ(f1, f2);
    ObjectRecord o1, o2;
    EXPECT_TRUE(same(decode(in, o1), decode_detailed(in, o2)));
    EXPECT_EQ(o1, o2);
  }
}

TEST(Records, Topics) {
  EXPECT_EQ(comms::topic_kind(regions_topic(2)), comms::TopicKind::kRegions);
  EXPECT_EQ(comms::topic_index(regions_topic(2)), 2U);
  EXPECT_EQ(comms::topic_index(kClaimTopic), 0U);
  EXPECT_EQ(comms::topic_index(kVisitedTopic), 1U);
  EXPECT_EQ(comms::topic_kind(kVisitedTopic), comms::TopicKind::kClaims);
  EXPECT_EQ(comms::topic_index(failure_topic(0x12345678)), 0x345678U);
  EXPECT_EQ(comms::topic_index(object_topic(3)), 0x100003U);
  EXPECT_TRUE(is_object_topic(object_topic(3)));
  EXPECT_FALSE(is_object_topic(comms::make_topic(comms::TopicKind::kApp, 3)));
}

}  // namespace
}  // namespace ag::mission
