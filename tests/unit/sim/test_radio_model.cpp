// Tests of the radio model's single-link behaviour: range, path-loss curve, loss, retries, latency, airtime,
// queue limits, broadcast, determinism, config. The shared medium is in test_radio_medium.cpp.
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
  c.shadowing_sigma_db = 0.0;  // a hard edge at range_m
  c.loss_probability = 0.0;
  c.latency_s = 0.0;
  c.jitter_s = 0.0;
  c.cw_min = 0;  // no random backoff: exact timing
  return c;
}

const std::vector<std::uint8_t> kPayload(100, 0xAB);

TEST(RadioModel, OutOfRangeIsNeverDelivered) {
  RadioConfig c = ideal();
  c.retry_limit = 0;
  RadioModel radio(c, 1, 2);
  radio.set_position(0, 0, 0);
  radio.set_position(1, 100.5, 0);
  for (int i = 0; i < 100; ++i) EXPECT_EQ(radio.send(i * kNsPerMs * 10, 0, 1, kPayload), 1u);  // addressed ...
  EXPECT_EQ(radio.send(kNsPerS, 0, RadioModel::kBroadcast, kPayload), 0u);  // ... a broadcast has nobody to address
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

TEST(RadioModel, ReceiverLeavingRangeWhileTheDatagramFliesLosesIt) {
  RadioConfig c = ideal();
  c.latency_s = 1.0;
  RadioModel radio(c, 1, 2);
  radio.set_position(1, 50, 0);
  EXPECT_EQ(radio.send(0, 0, RadioModel::kBroadcast, kPayload), 1u);
  std::vector<Delivery> out;
  EXPECT_EQ(radio.deliver(kNsPerS / 2, out), 0u);  // on the air and done; now in flight
  radio.set_position(1, 500, 0);
  EXPECT_EQ(radio.deliver(2 * kNsPerS, out), 0u);
  EXPECT_EQ(radio.stats(0, 1).dropped_range, 1u);
  EXPECT_EQ(radio.in_flight(), 0u);
}

TEST(RadioModel, LossRateMatchesTheConfiguration) {
  RadioConfig c = ideal();
  c.loss_probability = 0.2;
  RadioModel radio(c, 42, 2);
  constexpr int kN = 20000;
  for (int i = 0; i < kN; ++i) radio.send(i * kNsPerMs, 0, RadioModel::kBroadcast, kPayload);  // broadcasts: no retries
  std::vector<Delivery> out;
  radio.deliver(100 * kNsPerS, out);
  const double delivered = static_cast<double>(out.size()) / kN;
  const double sigma = std::sqrt(0.2 * 0.8 / kN);
  EXPECT_NEAR(delivered, 0.8, 4 * sigma);
  const LinkStats& s = radio.stats(0, 1);
  EXPECT_EQ(s.delivered + s.dropped_loss, static_cast<std::uint64_t>(kN));
  EXPECT_EQ(s.bytes_delivered, s.delivered * kPayload.size());
}

TEST(RadioModel, UnicastRetriesHideChannelLossAndCostAirtime) {
  RadioConfig c = ideal();
  c.loss_probability = 0.3;
  RadioModel radio(c, 9, 2);
  radio.set_position(1, 20, 0);
  constexpr int kN = 2000;
  for (int i = 0; i < kN; ++i) radio.send(i * 10 * kNsPerMs, 0, 1, kPayload);
  std::vector<Delivery> out;
  radio.deliver(100 * kNsPerS, out);
  const LinkStats& s = radio.stats(0, 1);
  EXPECT_GE(s.delivered, static_cast<std::uint64_t>(kN - 2)) << "0.3^8 of the frames fail all 8 tries";
  EXPECT_NEAR(static_cast<double>(s.retries) / kN, 0.3 / 0.7, 0.05);  // geometric: p / (1 - p) retries per frame
  EXPECT_EQ(radio.medium(0).transmissions, kN + s.retries);
}

TEST(RadioModel, LatencyAndJitterAreRespected) {
  RadioConfig c = ideal();
  c.latency_s = 0.05;
  c.jitter_s = 0.01;
  RadioModel radio(c, 7, 2);
  const double on_air = difs_s(c) + frame_airtime_s(c, kPayload.size(), false);
  std::vector<Delivery> out;
  for (int i = 0; i < 1000; ++i) {
    const TimeNs t = i * 100 * kNsPerMs;
    radio.send(t, 0, RadioModel::kBroadcast, kPayload);
    // Nothing arrives before the airtime and the fixed latency.
    EXPECT_EQ(radio.deliver(t + 49 * kNsPerMs, out), 0u);
    EXPECT_EQ(radio.deliver(t + 62 * kNsPerMs, out), 1u);
  }
  ASSERT_EQ(out.size(), 1000u);
  double min_d = 1e9, max_d = 0, sum = 0;
  for (const Delivery& d : out) {
    const double delay = to_seconds(d.arrival - d.sent) - on_air;
    min_d = std::min(min_d, delay);
    max_d = std::max(max_d, delay);
    sum += delay;
    EXPECT_EQ(d.bytes, kPayload);
    EXPECT_EQ(d.from, 0);
    EXPECT_EQ(d.to, 1);
  }
  EXPECT_GE(min_d, 0.05 - 1e-6);
  EXPECT_LE(max_d, 0.06 + 1e-6);
  EXPECT_NEAR(sum / 1000.0, 0.055, 0.001);  // uniform jitter: mean half of it
  EXPECT_GT(max_d - min_d, 0.008);          // the jitter is really there
}

TEST(RadioModel, AirtimeFollowsThe80211OfdmTiming) {
  const RadioConfig c;  // defaults: 6 Mbit/s, 20 us preamble, 4 us symbols of 24 bits
  // 1200 B payload + 28 IP/UDP + 36 MAC = 1264 B: 16 + 10112 + 6 bits = 423 symbols.
  EXPECT_NEAR(frame_airtime_s(c, 1200, false), 20e-6 + 423 * 4e-6, 1e-12);
  // A unicast adds SIFS and a 14-byte ACK (134 bits: 6 symbols).
  EXPECT_NEAR(frame_airtime_s(c, 1200, true), 20e-6 + 423 * 4e-6 + 16e-6 + 20e-6 + 6 * 4e-6, 1e-12);
  EXPECT_NEAR(difs_s(c), 34e-6, 1e-12);
  // One frame on an idle medium without backoff: DIFS, then its airtime.
  RadioModel radio(ideal(), 3, 2);
  radio.send(0, 0, RadioModel::kBroadcast, std::vector<std::uint8_t>(1200, 0));
  std::vector<Delivery> out;
  const TimeNs arrival = from_seconds(34e-6 + 1712e-6 + 1e-9);
  EXPECT_EQ(radio.deliver(arrival - 2000, out), 0u);
  EXPECT_EQ(radio.deliver(arrival, out), 1u);
}

TEST(RadioModel, FullQueueDropsAndDrains) {
  RadioConfig c = ideal();
  c.phy_rate_bps = 1e5;  // 1064 B on the air take 85 ms
  c.queue_limit_bytes = 20000.0;
  RadioModel radio(c, 3, 2);
  const std::vector<std::uint8_t> kilo(1000, 1);
  std::size_t accepted = 0;
  for (int i = 0; i < 100; ++i) accepted += radio.send(0, 0, RadioModel::kBroadcast, kilo);
  EXPECT_EQ(accepted, 18u);  // 18 x 1064 B fit in 20000 B
  EXPECT_EQ(radio.stats(0, 1).dropped_queue, 82u);
  // After 1 s, 12 frames have left the queue (11 sent, the 12th on the air): room for 12 more.
  accepted = 0;
  for (int i = 0; i < 20; ++i) accepted += radio.send(kNsPerS, 0, RadioModel::kBroadcast, kilo);
  EXPECT_EQ(accepted, 12u);
  // Oversize datagrams are refused outright.
  c.max_datagram_bytes = 500;
  RadioModel small(c, 3, 2);
  EXPECT_EQ(small.send(0, 0, 1, kilo), 0u);
  EXPECT_EQ(small.stats(0, 1).dropped_queue, 1u);
}

TEST(RadioModel, DeliveryFallsOffAlongThePathLossCurve) {
  RadioConfig c;  // n = 3, sigma = 6 dB
  c.range_m = 100;
  EXPECT_NEAR(delivery_probability(c, 100), 0.5, 1e-12);  // the nominal range keeps its meaning
  EXPECT_NEAR(delivery_probability(c, 50), 0.934, 0.001);  // 9.0 dB margin, 1.5 sigma
  EXPECT_NEAR(delivery_probability(c, 200), 0.066, 0.001);
  EXPECT_GT(delivery_probability(c, 10), 0.9999);
  EXPECT_NEAR(delivery_probability(c, reach_m(c)), 1e-3, 1e-5);
  EXPECT_NEAR(carrier_sense_range_m(c), 100 * std::pow(10.0, 6.0 / 30.0), 1e-9);
  // Measured: frames sent far apart in time (no contention) at 50, 100 and 150 m.
  c.loss_probability = 0;
  for (const double d : {50.0, 100.0, 150.0}) {
    RadioModel radio(c, 5, 2);
    radio.set_position(1, d, 0);
    constexpr int kN = 4000;
    for (int i = 0; i < kN; ++i) radio.send(i * 10 * kNsPerMs, 0, RadioModel::kBroadcast, kPayload);
    std::vector<Delivery> out;
    radio.deliver(100 * kNsPerS, out);
    const double p = delivery_probability(c, d);
    EXPECT_NEAR(static_cast<double>(out.size()) / kN, p, 4 * std::sqrt(p * (1 - p) / kN) + 1e-3) << d << " m";
  }
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
  EXPECT_EQ(out[0].to, 1);  // same arrival time: node order
  EXPECT_EQ(out[1].to, 2);
  EXPECT_EQ(radio.stats(0, 3).sent, 0u);  // not addressed, not a drop
  EXPECT_EQ(radio.total().delivered, 2u);
  EXPECT_EQ(radio.medium(0).transmissions, 1u) << "a broadcast goes on the air once";
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
  RadioConfig c;  // defaults: path loss, shadowing, backoff, collisions, retries, jitter all on
  RadioModel radio(c, seed, 4);
  std::vector<Delivery> all;
  for (int step = 0; step < 500; ++step) {
    const TimeNs t = step * 10 * kNsPerMs;
    for (int n = 0; n < 4; ++n) radio.set_position(n, 40.0 * n + 20.0 * std::sin(0.01 * step), 0);
    for (int n = 0; n < 4; ++n)  // a burst that keeps the medium contended
      radio.send(t, n, RadioModel::kBroadcast, std::vector<std::uint8_t>(1200, static_cast<std::uint8_t>(n)));
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
  EXPECT_GT(a.size(), 1000u);
}

TEST(RadioConfigYaml, LoadsAndValidatesEveryKey) {
  auto ok = load_radio_config("range_m: 250\nloss_probability: 0.1\nphy_rate_bps: 12e6\ncw_min: 31\ncarrier_sense_range_m: 400\n", "radio.yaml");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_DOUBLE_EQ(ok->range_m, 250.0);
  EXPECT_DOUBLE_EQ(ok->loss_probability, 0.1);
  EXPECT_DOUBLE_EQ(ok->phy_rate_bps, 12e6);
  EXPECT_EQ(ok->cw_min, 31);
  EXPECT_DOUBLE_EQ(carrier_sense_range_m(ok.value()), 400.0);
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

  auto rate = load_radio_config("phy_rate_bps: 10\n", "radio.yaml");
  ASSERT_FALSE(rate.ok());
  EXPECT_NE(rate.error().message.find("phy_rate_bps"), std::string::npos) << rate.error().message;
  auto cw = load_radio_config("cw_min: 63\ncw_max: 31\n", "radio.yaml");
  ASSERT_FALSE(cw.ok());
  EXPECT_NE(cw.error().message.find("radio.cw_max"), std::string::npos) << cw.error().message;
  auto old_key = load_radio_config("bandwidth_bytes_per_s: 250000\n", "radio.yaml");  // the per-link model's key
  ASSERT_FALSE(old_key.ok());
  EXPECT_NE(old_key.error().message.find("bandwidth_bytes_per_s"), std::string::npos) << old_key.error().message;

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
