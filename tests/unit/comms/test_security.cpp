// Security: forged, altered, replayed, truncated, random and malformed datagrams are dropped, counted by
// reason, and never change the store.
#include <gtest/gtest.h>

#include <random>

#include "airground/comms/bytes.hpp"
#include "airground/comms/link_hub.hpp"
#include "team_rig.hpp"

namespace ag::comms {
namespace {

// Captures what a node sends (and passes it on to `inner`, if any), so a test can replay it later.
class Tap final : public DatagramLink {
 public:
  explicit Tap(DatagramLink* inner = nullptr) : inner_(inner) {}
  SendStatus send(TimeNs now, const LinkAddress& to, std::span<const std::uint8_t> b) noexcept override {
    sent.emplace_back(b.begin(), b.end());
    return inner_ ? inner_->send(now, to, b) : SendStatus::kSent;
  }
  std::size_t receive(TimeNs now, LinkAddress& from, std::span<std::uint8_t> buf, bool& t) noexcept override {
    return inner_ ? inner_->receive(now, from, buf, t) : 0;
  }
  [[nodiscard]] std::size_t mtu() const noexcept override { return 1200; }
  std::vector<std::vector<std::uint8_t>> sent;

 private:
  DatagramLink* inner_;
};

struct Victim {
  RecordStore store{test::Team::kTestLimits};
  GossipNode node;
  explicit Victim(RobotId self = 1) : node(params(self), test::test_key(), store, 1, nullptr) {}
  static GossipParams params(RobotId self) {
    GossipParams p;
    p.self = self;
    return p;
  }
  std::uint64_t drops(DropReason r) const { return node.stats().drop(r); }
  void feed(const std::vector<std::uint8_t>& d) { node.receive(kNsPerS, LinkAddress{9, false}, d); }
};

std::vector<std::uint8_t> seal(const TeamKey& key, DatagramHeader h, const std::vector<std::uint8_t>& body) {
  DatagramCodec c(key);
  std::vector<std::uint8_t> out(body.size() + kSealOverhead);
  out.resize(c.seal(h, body, out));
  return out;
}

// One whole record (pose of robot 0) as a records body.
std::vector<std::uint8_t> record_body(RobotId origin, std::uint64_t seq, std::uint32_t total, std::uint32_t offset,
                                      std::uint16_t len) {
  std::vector<std::uint8_t> b(GossipNode::kFragmentHeaderBytes + len, 0xAB);
  ByteWriter w(b);
  w.u8(origin);
  w.u32(make_topic(TopicKind::kPose, 0));
  w.u64(seq);
  w.u8(5);
  w.i64(1000);
  w.u32(total);
  w.u32(offset);
  w.u16(len);
  return b;
}

DatagramHeader hdr(std::uint64_t counter, std::uint32_t epoch = 1, RobotId sender = 0, RobotId dest = kNoRobot) {
  DatagramHeader h;
  h.type = MsgType::kRecords;
  h.sender = sender;
  h.dest = dest;
  h.epoch = epoch;
  h.counter = counter;
  return h;
}

TEST(Security, AnAuthenticRecordIsStoredOnce) {
  Victim v;
  const auto d = seal(test::test_key(), hdr(1), record_body(0, 10, 48, 0, 48));
  v.feed(d);
  EXPECT_EQ(v.store.size(), 1U);
  EXPECT_EQ(v.node.stats().total_drops(), 0U);
  v.feed(d);
  EXPECT_EQ(v.drops(DropReason::kReplayed), 1U) << "the same datagram again";
  EXPECT_EQ(v.store.size(), 1U);
}

TEST(Security, ForgedAlteredAndTruncatedDatagramsAreDropped) {
  Victim v;
  const auto good = seal(test::test_key(), hdr(5), record_body(0, 10, 48, 0, 48));
  v.feed(seal(test::test_key(1), hdr(1), record_body(0, 10, 48, 0, 48)));  // another team's key
  for (std::size_t i = 0; i < good.size(); ++i) {  // every single-bit flip, header (AD) and body alike
    if (i < 4) continue;                             // magic/version/type flips have their own reasons
    auto bad = good;
    bad[i] ^= 0x10;
    v.feed(bad);
  }
  for (std::ptrdiff_t cut : {1, 5, 16}) v.feed(std::vector<std::uint8_t>(good.begin(), good.end() - cut));
  v.feed(std::vector<std::uint8_t>(good.begin(), good.begin() + 20));
  EXPECT_EQ(v.store.size(), 0U) << "nothing forged reached the store";
  // Header bytes 4 (sender) and 5 (dest) have their own checks for some values; the rest fail the tag.
  const std::uint64_t forged = v.drops(DropReason::kForged);
  EXPECT_GE(forged, 1U + (good.size() - 4) - 2 + 3);
  EXPECT_EQ(v.drops(DropReason::kTooShort), 1U);
  EXPECT_EQ(v.drops(DropReason::kReplayed), 0U) << "forgeries never reach the replay window";
  v.feed(good);
  EXPECT_EQ(v.store.size(), 1U) << "the authentic one still passes after all that";
  std::printf("[security] forged %llu, not_for_us %llu, bad_sender %llu, own_echo %llu, too_short %llu\n",
              static_cast<unsigned long long>(forged), static_cast<unsigned long long>(v.drops(DropReason::kNotForUs)),
              static_cast<unsigned long long>(v.drops(DropReason::kBadSender)),
              static_cast<unsigned long long>(v.drops(DropReason::kOwnEcho)),
              static_cast<unsigned long long>(v.drops(DropReason::kTooShort)));
}

TEST(Security, ReplayWindowAcceptsReorderingAndRefusesRepeatsOldAndPreviousEpochs) {
  Victim v;
  const TeamKey k = test::test_key();
  auto d = [&](std::uint64_t counter, std::uint32_t epoch, std::uint64_t seq) {
    return seal(k, hdr(counter, epoch), record_body(0, seq, 48, 0, 48));
  };
  v.feed(d(100, 2, 1));
  v.feed(d(98, 2, 2));   // reordered, inside the window: accepted
  v.feed(d(98, 2, 3));   // repeat
  v.feed(d(30, 2, 4));   // older than the 64-datagram window
  v.feed(d(500, 1, 5));  // previous boot epoch
  EXPECT_EQ(v.drops(DropReason::kReplayed), 3U);
  EXPECT_EQ(v.store.meta(v.store.find(RecordKey{0, make_topic(TopicKind::kPose, 0)})).seq, 2U);
  v.feed(d(0, 3, 6));  // the sender restarted: a new epoch starts a new window
  EXPECT_EQ(v.drops(DropReason::kReplayed), 3U);
  EXPECT_EQ(v.store.meta(v.store.find(RecordKey{0, make_topic(TopicKind::kPose, 0)})).seq, 6U);
}

TEST(Security, RecordedDigestsAndHaveListsReplayedLaterAreDropped) {
  test::Team team(2, 0.0, 3);
  team.node(0).publish(make_topic(TopicKind::kPose, 0), 5, 1, test::bytes_of("p0"));
  Tap tap(&team.hub().endpoint(0));  // everything robot 0 sends is recorded on its way to robot 1
  for (int k = 0; k < 40; ++k) {
    const TimeNs now = 2 * kNsPerS + k * 100 * kNsPerMs;
    team.node(0).tick(now, tap);
    team.node(1).tick(now, team.hub().endpoint(1));
  }
  ASSERT_TRUE(team.converged());
  ASSERT_GE(tap.sent.size(), 3U) << "digests and the record";
  const auto before = team.node(1).stats().drop(DropReason::kReplayed);
  for (const auto& d : tap.sent) team.node(1).receive(team.now(), LinkAddress{0, false}, d);
  EXPECT_EQ(team.node(1).stats().drop(DropReason::kReplayed), before + tap.sent.size());
}

TEST(Security, RandomDatagramsAreDroppedAndCounted) {
  Victim v;
  std::mt19937_64 rng(42);
  std::uniform_int_distribution<std::size_t> len(0, 1500);
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    std::vector<std::uint8_t> d(len(rng));
    for (auto& b : d) b = static_cast<std::uint8_t>(rng());
    if (i % 2 == 0 && d.size() >= 4) {  // half of them look like ours up to the tag
      d[0] = 0x41;
      d[1] = 0x47;
      d[2] = 1;
      d[3] = static_cast<std::uint8_t>(1 + i % 3);
      if (d.size() >= 6) {
        d[4] = static_cast<std::uint8_t>(2 + i % 200);  // a team member's id
        d[5] = 255;                                     // to everyone
      }
    }
    v.feed(d);
  }
  EXPECT_EQ(v.node.stats().total_drops(), static_cast<std::uint64_t>(n));
  EXPECT_EQ(v.store.size(), 0U);
  EXPECT_GT(v.drops(DropReason::kForged), 8000U);
  EXPECT_GT(v.drops(DropReason::kBadMagic), 8000U);
}

TEST(Security, AuthenticButMalformedBodiesAreDroppedWithoutTouchingTheStore) {
  Victim v;
  const TeamKey k = test::test_key();
  std::uint64_t c = 1;
  auto feed = [&](MsgType t, std::vector<std::uint8_t> body) {
    DatagramHeader h = hdr(c++);
    h.type = t;
    v.feed(seal(k, h, body));
  };
  feed(MsgType::kRecords, record_body(0, 1, 48, 0, 40));           // neither whole nor 64-aligned
  feed(MsgType::kRecords, record_body(0, 1, 48, 32, 16));          // offset not on a block
  feed(MsgType::kRecords, record_body(0, 1, 48, 64, 64));          // beyond the record
  feed(MsgType::kRecords, record_body(255, 1, 48, 0, 48));         // origin "nobody"
  auto short_frag = record_body(0, 1, 48, 0, 48);
  short_frag.resize(short_frag.size() - 1);
  feed(MsgType::kRecords, short_frag);                             // length says more than there is
  feed(MsgType::kDigest, {0, 254, 3, 1, 2});                       // 3 entries announced, none there
  feed(MsgType::kDigest, {9, 3, 0});                               // lo > hi
  feed(MsgType::kHave, {0, 0, 0, 0, 0, 0, 0, 0, 0, 5, 0});         // 5 entries announced, none there
  std::vector<std::uint8_t> unsorted(11 + 24, 0);
  ByteWriter w(unsorted);
  w.u8(0);
  w.u32(0);
  w.u32(0xFFFFFFFF);
  w.u16(2);
  w.u32(7);
  w.u64(1);
  w.u32(3);  // topics must increase
  w.u64(1);
  feed(MsgType::kHave, unsorted);
  EXPECT_EQ(v.drops(DropReason::kMalformed), 9U);
  EXPECT_EQ(v.store.size(), 0U);
  feed(MsgType::kRecords, record_body(0, 1, 70'000, 0, 64));      // a record above the store's limit
  EXPECT_EQ(v.drops(DropReason::kRecordTooLarge), 1U);
}

TEST(Security, OwnEchoesAndOtherRobotsUnicastsAreSetAside) {
  Victim v(1);
  v.feed(seal(test::test_key(), hdr(1, 1, 1), record_body(1, 1, 48, 0, 48)));     // "us", but we never sent it
  v.feed(seal(test::test_key(), hdr(2, 1, 0, 7), record_body(0, 1, 48, 0, 48)));  // to robot 7
  EXPECT_EQ(v.drops(DropReason::kIdClash), 1U) << "an authentic datagram with our id that is not our echo";
  EXPECT_EQ(v.drops(DropReason::kOwnEcho), 0U);
  EXPECT_EQ(v.drops(DropReason::kNotForUs), 1U);
  EXPECT_EQ(v.store.size(), 0U);
}

TEST(Security, TwoRobotsWithTheSameIdAreToldApartFromAnEcho) {
  LinkHub hub(3, 0.0, 1);
  RecordStore s0(test::Team::kTestLimits), s1(test::Team::kTestLimits), s2(test::Team::kTestLimits);
  GossipParams p;
  p.self = 4;
  GossipNode a(p, test::test_key(), s0, 7, nullptr), b(p, test::test_key(), s1, 9, nullptr);  // both robot 4
  p.self = 5;
  GossipNode c(p, test::test_key(), s2, 1, nullptr);
  a.publish(make_topic(TopicKind::kPose, 0), 5, 1, test::bytes_of("a"));
  // Robot a also hears its own broadcasts (as on a UDP broadcast link): those are echoes, not clashes.
  Tap echo(&hub.endpoint(0));
  for (int k = 0; k < 30; ++k) {
    const TimeNs now = kNsPerS + k * 100 * kNsPerMs;
    a.tick(now, echo);
    for (const auto& d : echo.sent) a.receive(now, LinkAddress{0, false}, d);
    echo.sent.clear();
    b.tick(now, hub.endpoint(1));
    c.tick(now, hub.endpoint(2));
  }
  EXPECT_GT(a.stats().drop(DropReason::kOwnEcho), 0U);
  EXPECT_GT(a.stats().drop(DropReason::kIdClash) + b.stats().drop(DropReason::kIdClash), 0U);
  EXPECT_EQ(c.stats().drop(DropReason::kIdClash), 0U);
}

TEST(Security, TeamKeyParsingNamesTheProblem) {
  EXPECT_TRUE(TeamKey::from_hex(std::string(64, 'a'), "k").ok());
  const auto short_key = TeamKey::from_hex("abcd", "key.hex");
  ASSERT_FALSE(short_key.ok());
  EXPECT_NE(short_key.error().message.find("key.hex"), std::string::npos);
  EXPECT_NE(short_key.error().message.find("64 hex digits"), std::string::npos);
  const auto bad = TeamKey::from_hex(std::string(63, 'a') + "g", "k");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("position 63"), std::string::npos);
  EXPECT_FALSE(TeamKey::load_file("/nonexistent/team.key").ok());
}

}  // namespace
}  // namespace ag::comms
