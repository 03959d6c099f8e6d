// Tests of the radio model: range, loss, latency, bandwidth and queue limits, broadcast, determinism, config.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "airground/sim/radio.hpp"

namespace ag::sim {
namespace {

RadioConfig ideal() {
  RadioConfig c;
  c.range_m = 100.0;
  c.loss_probability = 0.0;
  c.latency_s = 0.0;
  c.jitter_s = 0.0;
  c.bandwidth_bytes_per_s = 0.0;  // unlimited
  return c;
}

const std::vector<std::uint8_t> kPayload(100, 0xAB);

TEST(RadioModel, OutOfRangeIsNeverDelivered) {
  RadioModel radio(ideal(), 1, 2);
  radio.set_position(0, 0, 0);
  radio.set_position(1, 100.5, 0);
  for (int i = 0; i < 100; ++i) EXPECT_EQ(radio.send(i * kNsPerMs, 0, 1, kPayload), 0u);
  std::vector<Delivery> out;
  EXPECT_EQ(radio.deliver(10 * kNsPerS, out), 0u);
  EXPECT_TRUE(out.empty());
  EXPECT_EQ(radio.stats(0, 1).sent, 100u);
  EXPECT_EQ(radio.stats(0, 1).dropped_range, 100u);
  EXPECT_EQ(radio.stats(0, 1).delivered, 0u);
  EXPECT_FALSE(radio.in_range(0, 1));
  radio.set_position(1, 100.0, 0);  // exactly at range: heard
  EXPECT_TRUE(radio.in_range(0, 1));
}

TEST(RadioModel, ReceiverLeavingRangeWhileQueuedLosesTheDatagram) {
  RadioConfig c = ideal();
  c.latency_s = 1.0;
  RadioModel radio(c, 1, 2);
  radio.set_position(1, 50, 0);
  EXPECT_EQ(radio.send(0, 0, 1, kPayload), 1u);
  radio.set_position(1, 500, 0);
  std::vector<Delivery> out;
  EXPECT_EQ(radio.deliver(2 * kNsPerS, out), 0u);
  EXPECT_EQ(radio.stats(0, 1).dropped_range, 1u);
  EXPECT_EQ(radio.in_flight(), 0u);
}

TEST(RadioModel, LossRateMatchesTheConfiguration) {
  RadioConfig c = ideal();
  c.loss_probability = 0.2;
  RadioModel radio(c, 42, 2);
  constexpr int kN = 20000;
  for (int i = 0; i < kN; ++i) radio.send(i * kNsPerMs, 0, 1, kPayload);
  std::vector<Delivery> out;
  radio.deliver(100 * kNsPerS, out);
  const double delivered = static_cast<double>(out.size()) / kN;
  const double sigma = std::sqrt(0.2 * 0.8 / kN);
  EXPECT_NEAR(delivered, 0.8, 4 * sigma);
  const LinkStats& s = radio.stats(0, 1);
  EXPECT_EQ(s.delivered + s.dropped_loss, static_cast<std::uint64_t>(kN));
  EXPECT_EQ(s.bytes_delivered, s.delivered * kPayload.size());
}

TEST(RadioModel, LatencyAndJitterAreRespected) {
  RadioConfig c = ideal();
  c.latency_s = 0.05;
  c.jitter_s = 0.01;
  RadioModel radio(c, 7, 2);
  std::vector<Delivery> out;
  for (int i = 0; i < 1000; ++i) {
    const TimeNs t = i * 100 * kNsPerMs;
    radio.send(t, 0, 1, kPayload);
    // Nothing arrives before the fixed latency.
    EXPECT_EQ(radio.deliver(t + 49 * kNsPerMs, out), 0u);
    EXPECT_EQ(radio.deliver(t + 61 * kNsPerMs, out), 1u);
  }
  ASSERT_EQ(out.size(), 1000u);
  double min_d = 1e9, max_d = 0, sum = 0;
  for (const Delivery& d : out) {
    const double delay = to_seconds(d.arrival - d.sent);
    min_d = std::min(min_d, delay);
    max_d = std::max(max_d, delay);
    sum += delay;
    EXPECT_EQ(d.bytes, kPayload);
    EXPECT_EQ(d.from, 0);
    EXPECT_EQ(d.to, 1);
  }
  EXPECT_GE(min_d, 0.05);
  EXPECT_LE(max_d, 0.06 + 1e-9);
  EXPECT_NEAR(sum / 1000.0, 0.055, 0.001);  // uniform jitter: mean half of it
  EXPECT_GT(max_d - min_d, 0.008);          // the jitter is really there
}

TEST(RadioModel, BandwidthCapLimitsThroughput) {
  RadioConfig c = ideal();
  c.bandwidth_bytes_per_s = 10000.0;  // 10 kB/s
  c.queue_limit_bytes = 200000.0;
  RadioModel radio(c, 3, 2);
  radio.set_position(1, 10, 0);
  const std::vector<std::uint8_t> kilo(1000, 1);
  for (int i = 0; i < 100; ++i) ASSERT_EQ(radio.send(0, 0, 1, kilo), 1u);  // 100 kB at once
  EXPECT_NEAR(radio.link_backlog_bytes(0, 0, 1), 100000.0, 1.0);
  std::vector<Delivery> out;
  EXPECT_EQ(radio.deliver(from_seconds(0.099), out), 0u);
  EXPECT_EQ(radio.deliver(from_seconds(0.1), out), 1u);    // 1 kB takes 0.1 s
  EXPECT_EQ(radio.deliver(from_seconds(5.0), out), 49u);   // 50 kB in 5 s
  EXPECT_EQ(radio.deliver(from_seconds(9.99), out), 49u);
  EXPECT_EQ(radio.deliver(from_seconds(10.0), out), 1u);   // the last at exactly 10 s
  ASSERT_EQ(out.size(), 100u);
  for (std::size_t k = 0; k < out.size(); ++k)
    EXPECT_NEAR(to_seconds(out[k].arrival), 0.1 * static_cast<double>(k + 1), 1e-6);
  // The other direction is a separate link with its own capacity.
  EXPECT_EQ(radio.send(from_seconds(10.0), 1, 0, kilo), 1u);
  EXPECT_EQ(radio.deliver(from_seconds(10.1), out), 1u);
}

TEST(RadioModel, FullQueueDropsAndDrains) {
  RadioConfig c = ideal();
  c.bandwidth_bytes_per_s = 10000.0;
  c.queue_limit_bytes = 20000.0;
  RadioModel radio(c, 3, 2);
  const std::vector<std::uint8_t> kilo(1000, 1);
  std::size_t accepted = 0;
  for (int i = 0; i < 100; ++i) accepted += radio.send(0, 0, 1, kilo);
  EXPECT_EQ(accepted, 20u);
  EXPECT_EQ(radio.stats(0, 1).dropped_queue, 80u);
  // After 1 s, 10 kB have left the queue: room for 10 more.
  accepted = 0;
  for (int i = 0; i < 20; ++i) accepted += radio.send(kNsPerS, 0, 1, kilo);
  EXPECT_EQ(accepted, 10u);
  // Oversize datagrams are refused outright.
  c.max_datagram_bytes = 500;
  RadioModel small(c, 3, 2);
  EXPECT_EQ(small.send(0, 0, 1, kilo), 0u);
  EXPECT_EQ(small.stats(0, 1).dropped_queue, 1u);
}

TEST(RadioModel, OverheadCountsAgainstBandwidth) {
  RadioConfig c = ideal();
  c.bandwidth_bytes_per_s = 1000.0;
  c.overhead_bytes = 28.0;
  RadioModel radio(c, 3, 2);
  radio.send(0, 0, 1, std::vector<std::uint8_t>(72, 0));  // 100 bytes on the air
  std::vector<Delivery> out;
  EXPECT_EQ(radio.deliver(from_seconds(0.0999), out), 0u);
  EXPECT_EQ(radio.deliver(from_seconds(0.1), out), 1u);
}

TEST(RadioModel, BroadcastReachesOnlyNodesInRange) {
  RadioModel radio(ideal(), 5, 5);
  radio.set_position(0, 0, 0);
  radio.set_position(1, 50, 0);
  radio.set_position(2, 0, 99.9);
  radio.set_position(3, 101, 0);
  radio.set_position(4, -80, -80);  // 113 m
  EXPECT_EQ(radio.send(0, 0, RadioModel::kBroadcast, kPayload), 2u);
  std::vector<Delivery> out;
  ASSERT_EQ(radio.deliver(kNsPerS, out), 2u);
  EXPECT_EQ(out[0].to, 1);  // same arrival time: send order
  EXPECT_EQ(out[1].to, 2);
  EXPECT_EQ(radio.stats(0, 3).sent, 0u);  // not addressed, not a drop
  EXPECT_EQ(radio.total().delivered, 2u);
}

TEST(RadioModel, InvalidNodesAreIgnored) {
  RadioModel radio(ideal(), 5, 2);
  EXPECT_EQ(radio.send(0, 0, 0, kPayload), 0u);
  EXPECT_EQ(radio.send(0, 2, 1, kPayload), 0u);
  EXPECT_EQ(radio.send(0, 0, 5, kPayload), 0u);
  EXPECT_EQ(radio.send(0, -1, 1, kPayload), 0u);
  EXPECT_EQ(radio.total().sent, 0u);
  EXPECT_EQ(radio.stats(9, 9).sent, 0u);
}

std::vector<Delivery> run_mesh(std::uint64_t seed) {
  RadioConfig c;  // defaults: loss, jitter and bandwidth all on
  RadioModel radio(c, seed, 4);
  std::vector<Delivery> all;
  for (int step = 0; step < 500; ++step) {
    const TimeNs t = step * 10 * kNsPerMs;
    for (int n = 0; n < 4; ++n) radio.set_position(n, 40.0 * n + 20.0 * std::sin(0.01 * step), 0);
    for (int n = 0; n < 4; ++n)
      radio.send(t, n, step % 3 == 0 ? RadioModel::kBroadcast : (n + 1) % 4,
                 std::vector<std::uint8_t>(static_cast<std::size_t>(50 + 17 * n), static_cast<std::uint8_t>(step)));
    radio.deliver(t, all);
  }
  return all;
}

TEST(RadioModel, DeterministicGivenSeedAndCallOrder) {
  const auto a = run_mesh(11), b = run_mesh(11), c = run_mesh(12);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].arrival, b[i].arrival);
    EXPECT_EQ(a[i].from, b[i].from);
    EXPECT_EQ(a[i].to, b[i].to);
    EXPECT_EQ(a[i].bytes, b[i].bytes);
  }
  bool differs = a.size() != c.size();
  for (std::size_t i = 0; !differs && i < a.size(); ++i) differs = a[i].arrival != c[i].arrival;
  EXPECT_TRUE(differs);
}

TEST(RadioConfigYaml, LoadsAndValidatesEveryKey) {
  auto ok = load_radio_config("range_m: 250\nloss_probability: 0.1\nbandwidth_bytes_per_s: 0\n", "radio.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_DOUBLE_EQ(ok->range_m, 250.0);
  EXPECT_DOUBLE_EQ(ok->loss_probability, 0.1);
  EXPECT_DOUBLE_EQ(ok->bandwidth_bytes_per_s, 0.0);
  EXPECT_DOUBLE_EQ(ok->latency_s, RadioConfig{}.latency_s);

  auto empty = load_radio_config("", "radio.yaml");
  ASSERT_TRUE(empty.ok());
  EXPECT_DOUBLE_EQ(empty->range_m, RadioConfig{}.range_m);

  auto unknown = load_radio_config("range_m: 10\nrange: 5\n", "radio.yaml");
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().code, ErrorCode::kConfig);
  EXPECT_NE(unknown.error().message.find("'radio.range'"), std::string::npos) << unknown.error().message;
  EXPECT_NE(unknown.error().message.find("radio.yaml:2"), std::string::npos) << unknown.error().message;

  auto type = load_radio_config("latency_s: soon\n", "radio.yaml");
  ASSERT_FALSE(type.ok());
  EXPECT_NE(type.error().message.find("latency_s"), std::string::npos);
  EXPECT_NE(type.error().message.find("[0, 60] s"), std::string::npos) << type.error().message;

  auto range = load_radio_config("loss_probability: 1.5\n", "radio.yaml");
  ASSERT_FALSE(range.ok());
  EXPECT_NE(range.error().message.find("loss_probability"), std::string::npos);
  EXPECT_NE(range.error().message.find("[0, 1]"), std::string::npos) << range.error().message;

  auto list = load_radio_config("range_m: [1, 2]\n", "radio.yaml");
  ASSERT_FALSE(list.ok());
  EXPECT_NE(list.error().message.find("single value"), std::string::npos);

  auto not_map = load_radio_config("- a\n- b\n", "radio.yaml");
  EXPECT_FALSE(not_map.ok());
  auto malformed = load_radio_config("range_m: [1,\n", "radio.yaml");
  EXPECT_FALSE(malformed.ok());
}

}  // namespace
}  // namespace ag::sim
