// The gossip over the simulator's radio model (shared medium, path loss, loss, latency): a data
// mule that drives between two robots out of each other's range, and a team of 11 robots moving
// about a 600 m square with 30 % loss.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "airground/sim/radio_link.hpp"
#include "team_rig.hpp"

namespace ag::comms {
namespace {

struct RadioTeam {
  sim::RadioNet net;
  std::vector<std::unique_ptr<RecordStore>> stores;
  std::vector<std::unique_ptr<GossipNode>> nodes;
  TimeNs now{kNsPerS};
  RadioTeam(const sim::RadioConfig& cfg, int n, std::uint64_t seed) : net(cfg, seed, n) {
    for (int i = 0; i < n; ++i) {
      stores.push_back(std::make_unique<RecordStore>(test::Team::kTestLimits));
      GossipParams p;
      p.self = static_cast<RobotId>(i);
      p.seed = seed + static_cast<std::uint64_t>(i);
      nodes.push_back(std::make_unique<GossipNode>(p, test::test_key(), *stores.back(), 1, nullptr));
    }
  }
  void step(TimeNs dt) {
    now += dt;
    net.pump(now);
    for (std::size_t i = 0; i < nodes.size(); ++i) nodes[i]->tick(now, net.endpoint(static_cast<int>(i)));
  }
  bool converged() const {
    for (const auto& s : stores)
      if (s->size() != stores[0]->size() || s->content_hash() != stores[0]->content_hash()) return false;
    return true;
  }
};

TEST(RadioLink, DataMuleDrivesBetweenRobotsOutOfRange) {
  sim::RadioConfig cfg;
  cfg.range_m = 100;
  cfg.shadowing_sigma_db = 0;  // a hard edge: with shadowing, 1 frame in ~800 still crosses 400 m
  cfg.loss_probability = 0.1;
  RadioTeam t(cfg, 3, 4);
  t.net.radio().set_position(0, 0, 0);
  t.net.radio().set_position(2, 400, 0);
  std::mt19937_64 rng(3);
  std::vector<std::uint8_t> tile(6000);
  for (auto& b : tile) b = static_cast<std::uint8_t>(rng());
  t.nodes[0]->publish(tile_topic(0, 0), 2, 1, tile);
  t.nodes[0]->publish(make_topic(TopicKind::kRegions, 0), 4, 1, test::bytes_of("regions seen by robot 0"));
  t.nodes[2]->publish(make_topic(TopicKind::kFailures, 9), 7, 1, test::bytes_of("robot 2 failed goal 9"));
  // Robot 1 drives 0 -> 400 -> 0 m at 5 m/s along x.
  double seconds = 0;
  for (int k = 0; k < 3200 && !t.converged(); ++k) {
    const double tt = k * 0.05;
    const double x = 400.0 * (1.0 - std::fabs(std::fmod(tt / 80.0, 2.0) - 1.0));
    t.net.radio().set_position(1, x, 0);
    ASSERT_FALSE(t.net.radio().in_range(0, 2));
    t.step(50 * kNsPerMs);
    seconds = tt;
  }
  ASSERT_TRUE(t.converged()) << "the mule carried everything both ways";
  EXPECT_EQ(t.nodes[0]->peer_stats(2).datagrams_in, 0U);
  EXPECT_EQ(t.nodes[2]->peer_stats(0).datagrams_in, 0U);
  std::printf("[radio mule] robots 0 and 2 400 m apart (range 100 m), robot 1 shuttling at 5 m/s: stores identical after %.0f s\n", seconds);
}

TEST(RadioLink, ElevenMovingRobotsThirtyPercentLossConverge) {
  sim::RadioConfig cfg;
  cfg.range_m = 150;
  cfg.loss_probability = 0.3;
  cfg.overhead_bytes = 28;
  RadioTeam t(cfg, 11, 8);
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(0, 600);
  std::vector<std::pair<double, double>> pos(11), goal(11);
  for (auto& p : pos) p = {u(rng), u(rng)};
  for (auto& g : goal) g = {u(rng), u(rng)};
  auto move = [&] {  // each drives at 5 m/s to a random goal, then picks another
    for (int i = 0; i < 11; ++i) {
      auto& p = pos[static_cast<std::size_t>(i)];
      auto& g = goal[static_cast<std::size_t>(i)];
      const double dx = g.first - p.first, dy = g.second - p.second, d = std::hypot(dx, dy);
      if (d < 1.0) g = {u(rng), u(rng)};
      else p = {p.first + dx / d * 0.25, p.second + dy / d * 0.25};
      t.net.radio().set_position(i, p.first, p.second);
    }
  };
  std::vector<std::uint8_t> blob(2000);
  for (int k = 0; k < 600; ++k) {  // 30 s of updates
    if (k % 20 == 0)
      for (int i = 0; i < 11; ++i) {
        for (auto& b : blob) b = static_cast<std::uint8_t>(rng());
        t.nodes[static_cast<std::size_t>(i)]->publish(make_topic(TopicKind::kPose, 0), 5, t.now, std::span(blob).first(48));
        if (i == 0) t.nodes[0]->publish(tile_topic(k / 20, 0), 2, t.now, blob);
      }
    move();
    t.step(50 * kNsPerMs);
  }
  int ticks = 0;
  while (!t.converged() && ticks < 20 * 240) {
    move();
    t.step(50 * kNsPerMs);
    ++ticks;
  }
  ASSERT_TRUE(t.converged()) << "within 4 minutes of driving after the last update";
  const sim::LinkStats tot = t.net.radio().total();
  std::printf("[radio team] 11 robots in 600 m x 600 m, range 150 m, 30%% loss: identical stores %.1f s (%d digest rounds) after "
              "the last update; radio: %llu datagrams, %llu B offered, %llu lost, %llu out of range\n",
              ticks * 0.05, ticks / 20, static_cast<unsigned long long>(tot.sent), static_cast<unsigned long long>(tot.bytes_sent),
              static_cast<unsigned long long>(tot.dropped_loss), static_cast<unsigned long long>(tot.dropped_range));
}

}  // namespace
}  // namespace ag::comms
