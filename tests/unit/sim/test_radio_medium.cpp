// Tests of the shared radio medium: saturating senders in one neighbourhood share its airtime, groups out of
// carrier-sense range do not slow each other, hidden terminals collide where exposed ones only defer.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <vector>

#include "airground/sim/radio.hpp"

namespace ag::sim {
namespace {

constexpr std::size_t kFrameBytes = 1000;
constexpr double kRunS = 5.0;

struct Node {
  double x{0}, y{0};
  bool sends{false};
  double period_s{0.0005};  // offers a frame this often (0.5 ms: far beyond the medium, the queue stays full)
};

struct Outcome {
  std::vector<double> got;  // [B/s] payload `listener` received from each node over the run
  std::unique_ptr<RadioModel> radio;
};

Outcome run(const RadioConfig& cfg, const std::vector<Node>& nodes, int listener, std::uint64_t seed) {
  Outcome r{{}, std::make_unique<RadioModel>(cfg, seed, static_cast<int>(nodes.size()))};
  RadioModel& radio = *r.radio;
  for (std::size_t i = 0; i < nodes.size(); ++i) radio.set_position(static_cast<int>(i), nodes[i].x, nodes[i].y);
  const std::vector<std::uint8_t> frame(kFrameBytes, 0x5A);
  std::vector<double> got(nodes.size(), 0.0), next(nodes.size(), 0.0);
  std::vector<Delivery> out;
  for (TimeNs t = 0; t <= from_seconds(kRunS); t += 100 * 1000) {  // 0.1 ms steps
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      if (!nodes[i].sends || to_seconds(t) < next[i]) continue;
      next[i] += nodes[i].period_s;
      radio.send(t, static_cast<int>(i), RadioModel::kBroadcast, frame);
    }
    out.clear();
    radio.deliver(t, out);
    for (const Delivery& d : out)
      if (d.to == listener) got[static_cast<std::size_t>(d.from)] += static_cast<double>(d.bytes.size()) / kRunS;
  }
  r.got = std::move(got);
  return r;
}

double sum(const std::vector<double>& v) {
  double s = 0;
  for (const double x : v) s += x;
  return s;
}

RadioConfig medium() {
  RadioConfig c;  // the defaults: 6 Mbit/s, DCF timing, path loss with shadowing
  c.range_m = 100;
  c.queue_limit_bytes = 8 * 1064;
  c.loss_probability = 0;
  return c;
}

// N senders on a 5 m circle around a listener at the origin.
std::vector<Node> cluster(int n, double cx, double cy) {
  std::vector<Node> v;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * 3.141592653589793 * i / n;
    v.push_back(Node{cx + 5.0 * std::cos(a), cy + 5.0 * std::sin(a), true});
  }
  v.push_back(Node{cx, cy, false});
  return v;
}

TEST(RadioMedium, SaturatingSendersInOneNeighbourhoodShareTheAirtime) {
  const RadioConfig c = medium();
  // The most the air can carry: back-to-back frames, each after a DIFS and no backoff at all.
  const double ceiling = kFrameBytes / (difs_s(c) + frame_airtime_s(c, kFrameBytes, false));
  double solo = 0;
  for (const int n : {1, 2, 5, 10}) {
    const auto nodes = cluster(n, 0, 0);
    const std::vector<double> got = run(c, nodes, n, 17).got;
    const double total = sum(got);
    std::printf("[radio medium] %2d saturating senders, one neighbourhood: %.0f kB/s received in all (ceiling %.0f kB/s)\n", n,
                total / 1e3, ceiling / 1e3);
    EXPECT_LE(total, ceiling) << n << " senders: the sum stays within one medium's airtime";
    if (n == 1) {
      solo = total;
      EXPECT_GT(total, 0.9 * ceiling) << "one sender uses the air but for DIFS and its backoff";
      continue;
    }
    EXPECT_LT(total, 1.02 * solo) << "more senders do not add capacity (the per-link model gave " << n << "x)";
    EXPECT_GT(total, 0.3 * ceiling) << "collisions of equal backoffs cost airtime, not all of it";
    for (int i = 0; i < n; ++i) {
      const double share = got[static_cast<std::size_t>(i)] / total;
      EXPECT_GT(share, 0.5 / n) << "sender " << i << " of " << n;
      EXPECT_LT(share, 1.5 / n) << "sender " << i << " of " << n;
    }
  }
}

TEST(RadioMedium, GroupsOutOfCarrierSenseRangeDoNotSlowEachOther) {
  const RadioConfig c = medium();
  ASSERT_LT(carrier_sense_range_m(c), 1000.0);
  // Group A: senders 0..4 and listener 5 at the origin; group B: 6..10 and listener 11.
  auto layout = [](double bx, bool b_sends) {
    std::vector<Node> v = cluster(5, 0, 0);
    std::vector<Node> b = cluster(5, bx, 0);
    for (auto& n : b) n.sends = n.sends && b_sends;
    v.insert(v.end(), b.begin(), b.end());
    return v;
  };
  auto from_a = [](const std::vector<double>& got) {
    double s = 0;
    for (int i = 0; i < 5; ++i) s += got[static_cast<std::size_t>(i)];
    return s;
  };
  const double alone = from_a(run(c, layout(10000, false), 5, 23).got);
  const double apart = from_a(run(c, layout(10000, true), 5, 23).got);
  const double b_apart = sum(run(c, layout(10000, true), 11, 23).got);
  const double together = from_a(run(c, layout(20, true), 5, 23).got);
  std::printf("[radio medium] group A alone %.0f kB/s; with group B 10 km away %.0f kB/s (B: %.0f kB/s); B 20 m away: %.0f kB/s\n",
              alone / 1e3, apart / 1e3, b_apart / 1e3, together / 1e3);
  EXPECT_NEAR(apart / alone, 1.0, 0.1);
  EXPECT_NEAR(b_apart / alone, 1.0, 0.1);
  EXPECT_LT(together, 0.65 * alone) << "within carrier-sense range the two groups share one medium";
}

RadioConfig hard_edge() {
  RadioConfig c;
  c.range_m = 100;
  c.shadowing_sigma_db = 0;        // a frame within 100 m is received unless it collides
  c.carrier_sense_range_m = 120;
  c.loss_probability = 0;
  return c;
}

TEST(RadioMedium, HiddenTerminalsCollideWhereExposedOnesOnlyDefer) {
  const RadioConfig c = hard_edge();
  // Hidden: 0 and 2 are 180 m apart (beyond carrier sense), both 90 m from 1; each fills ~30 % of the air.
  std::vector<Node> hidden{{0, 0, true, 0.005}, {90, 0, false}, {180, 0, true, 0.0047}};
  const Outcome rh = run(c, hidden, 1, 31);
  const LinkStats& h = rh.radio->stats(0, 1);
  const double hidden_loss = static_cast<double>(h.dropped_collision) / static_cast<double>(h.sent);
  std::printf("[radio medium] hidden terminals: %.0f %% of 0 -> 1 collided at 1 (%llu of %llu)\n", 100 * hidden_loss,
              static_cast<unsigned long long>(h.dropped_collision), static_cast<unsigned long long>(h.sent));
  EXPECT_GT(hidden_loss, 0.2);
  EXPECT_GE(rh.radio->medium(0).transmissions + 1, h.sent) << "neither hears the other: every frame goes on the air";

  // Exposed: 1 and 2 hear each other (80 m) and defer; their receivers 0 and 3 are beyond the other's reach.
  std::vector<Node> exposed{{0, 0, false}, {80, 0, true, 0.005}, {160, 0, true, 0.005}, {240, 0, false}};
  const Outcome re = run(c, exposed, 0, 31);
  EXPECT_EQ(re.radio->stats(1, 0).dropped_collision, 0u);
  EXPECT_EQ(re.radio->stats(2, 3).dropped_collision, 0u);
  EXPECT_GE(re.radio->stats(1, 0).delivered + 1, re.radio->medium(1).transmissions) << "every frame 1 put on the air reached 0";
  EXPECT_GT(re.radio->medium(1).transmissions, 900u) << "5 s at one frame per 5 ms";
  EXPECT_GT(re.radio->stats(1, 2).dropped_collision + re.radio->stats(2, 1).dropped_collision, 0u)
      << "only between the two senders, when their backoffs end in the same slot";
}

TEST(RadioMedium, CaptureLetsTheNearSenderThrough) {
  const RadioConfig c = hard_edge();
  // 0 is 30 m from the listener 1, the interferer 2 is 95 m from it and 125 m from 0 (hidden from each other):
  // at 1, 0's frames are 30 log10(95 / 30) = 15 dB above 2's, beyond the 10 dB capture threshold.
  std::vector<Node> nodes{{-30, 0, true, 0.005}, {0, 0, false}, {95, 0, true, 0.005}};
  const Outcome r = run(c, nodes, 1, 37);
  EXPECT_EQ(r.radio->stats(0, 1).dropped_collision, 0u);
  EXPECT_GT(r.radio->stats(2, 1).dropped_collision, 0u) << "the far one is the one lost";
}

}  // namespace
}  // namespace ag::sim
