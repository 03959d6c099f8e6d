// Map tiles on the wire: the tile codec, the bytes a full 500 m x 500 m map at 0.5 m costs against its
// raw size, and that a one-tile change sends that tile and nothing else.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "airground/comms/tile_codec.hpp"
#include "map_fixture.hpp"
#include "team_rig.hpp"

namespace ag::comms {
namespace {

bool same_tile(const MapTileMsg& a, const MapTileMsg& b) {
  if (a.tx != b.tx || a.ty != b.ty || a.version != b.version || a.stamp != b.stamp || a.cls != b.cls) return false;
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    if (std::isnan(a.elevation[i]) != std::isnan(b.elevation[i])) return false;
    if (!std::isnan(a.elevation[i]) && std::fabs(a.elevation[i] - b.elevation[i]) > 0.0051f) return false;
  }
  return true;
}

TEST(TileCodec, RoundTripsExactlyAndRefusesDamagedPayloads) {
  auto tile = std::make_unique<MapTileMsg>();
  auto back = std::make_unique<MapTileMsg>();
  test::make_tile(*tile, 15, 3, 500.0, 7);  // an edge tile: part unknown (NaN, 255)
  TileCodec codec;
  std::vector<std::uint8_t> buf(TileCodec::max_payload_bytes());
  const std::size_t n = codec.encode(*tile, buf);
  ASSERT_GT(n, kTileHeaderBytes);
  ASSERT_TRUE(codec.decode(std::span<const std::uint8_t>(buf.data(), n), *back));
  EXPECT_TRUE(same_tile(*tile, *back));
  EXPECT_FALSE(codec.decode(std::span<const std::uint8_t>(buf.data(), n - 1), *back)) << "truncated";
  EXPECT_FALSE(codec.decode(std::span<const std::uint8_t>(buf.data(), 10), *back)) << "header only";
  auto bad = buf;
  bad[0] = 9;
  EXPECT_FALSE(codec.decode(std::span<const std::uint8_t>(bad.data(), n), *back)) << "unknown format";
  bad = buf;
  bad[n / 2] ^= 0xFF;
  MapTileMsg& keep = *back;
  (void)codec.decode(std::span<const std::uint8_t>(bad.data(), n), keep);  // may or may not detect; must not crash
  EXPECT_EQ(codec.encode(*tile, std::span<std::uint8_t>(buf.data(), 40)), 0U) << "no room";
  // Within 5 mm means exactly that: a cell off by 1 cm is told apart.
  *back = *tile;
  back->elevation[100] += 0.01f;
  EXPECT_FALSE(same_tile(*tile, *back));
}

TEST(MapBandwidth, FullMapThenOneChangedTile) {
  constexpr double kSize = 500.0;
  const int tiles_per_side = static_cast<int>(std::ceil(kSize / (kTileCells * kMapResolutionM)));
  GossipParams p;
  p.budget_bytes_per_s = 2e6;  // measure bytes, not time
  test::Team team(2, 0.0, 17, p, StoreLimits{1024, 16u << 20, TileCodec::max_payload_bytes()});
  TileCodec codec;
  auto tile = std::make_unique<MapTileMsg>();
  std::vector<std::uint8_t> buf(TileCodec::max_payload_bytes());
  std::size_t payload_total = 0;
  int count = 0;
  for (int ty = 0; ty < tiles_per_side; ++ty)
    for (int tx = 0; tx < tiles_per_side; ++tx) {
      test::make_tile(*tile, tx, ty, kSize, 1);
      const std::size_t n = codec.encode(*tile, buf);
      ASSERT_GT(n, 0U);
      payload_total += n;
      ASSERT_NE(team.node(0).publish(tile_topic(tx, ty), 2, tile->stamp, std::span<const std::uint8_t>(buf.data(), n)),
                PutResult::kFull);
      ++count;
    }
  const std::size_t raw = static_cast<std::size_t>(count) * kTileRawBytes;
  ASSERT_GE(team.run_until_converged(60 * kNsPerS), 0);
  const GossipStats& s0 = team.node(0).stats();
  const GossipStats& s1 = team.node(1).stats();
  const std::uint64_t wire = s0.bytes_out + s1.bytes_out;
  const std::uint64_t datagrams = s0.datagrams_out + s1.datagrams_out;
  const std::uint64_t with_ip = wire + 28 * datagrams;
  std::printf("[bandwidth] full map %.0f m x %.0f m at %.1f m: %d tiles, raw %zu B (classes + float32 elevation), "
              "compressed payloads (classes exact, elevation to 1 cm) %zu B (%.1f%%), on the wire %llu B in %llu datagrams (%llu B with IP/UDP headers) = "
              "%.1f%% of raw\n",
              kSize, kSize, kMapResolutionM, count, raw, payload_total, 100.0 * static_cast<double>(payload_total) / static_cast<double>(raw),
              static_cast<unsigned long long>(wire), static_cast<unsigned long long>(datagrams),
              static_cast<unsigned long long>(with_ip), 100.0 * static_cast<double>(with_ip) / static_cast<double>(raw));
  EXPECT_LT(with_ip, raw / 3) << "compression pays for the protocol several times over";
  EXPECT_LT(static_cast<double>(wire), 1.15 * static_cast<double>(payload_total)) << "protocol overhead under 15 %";
  EXPECT_EQ(s1.records_in, static_cast<std::uint64_t>(count));
  EXPECT_EQ(s1.duplicates_in, 0U);

  // Idle: only digests travel.
  const std::uint64_t out0 = s0.records_out, rec_dg0 = s0.records_datagrams_out, bytes0 = s0.bytes_out, bytes1 = s1.bytes_out;
  for (int k = 0; k < 50; ++k) team.step(100 * kNsPerMs);
  EXPECT_EQ(s0.records_out, out0) << "nothing re-sent while nothing changes";
  const std::uint64_t idle = s0.bytes_out - bytes0 + s1.bytes_out - bytes1;
  std::printf("[bandwidth] idle, converged: %llu B in 5 s (digests only)\n", static_cast<unsigned long long>(idle));
  EXPECT_LT(idle, 5U * 2U * 200U);

  // One tile changes.
  test::make_tile(*tile, 5, 7, kSize, 2);
  for (std::size_t i = 0; i < 300; ++i) tile->cls[i] = 4;
  const std::size_t n = codec.encode(*tile, buf);
  const std::uint64_t in1 = s1.records_in, b0 = s0.bytes_out, b1 = s1.bytes_out, dg0 = s0.records_datagrams_out;
  (void)rec_dg0;
  ASSERT_EQ(team.node(0).publish(tile_topic(5, 7), 2, tile->stamp, std::span<const std::uint8_t>(buf.data(), n)), PutResult::kReplaced);
  ASSERT_GE(team.run_until_converged(10 * kNsPerS), 0);
  const std::uint64_t delta = s0.bytes_out - b0 + s1.bytes_out - b1;
  const std::uint64_t record_datagrams = s0.records_datagrams_out - dg0;
  std::printf("[bandwidth] one changed tile: payload %zu B, sent in %llu record datagrams; all bytes on the wire "
              "meanwhile %llu B (digests included)\n",
              n, static_cast<unsigned long long>(record_datagrams), static_cast<unsigned long long>(delta));
  EXPECT_EQ(s1.records_in - in1, 1U) << "exactly one record travelled";
  EXPECT_EQ(s0.records_out - out0, 1U);
  const std::uint64_t frag = (n + 1100) / 1100;
  EXPECT_LE(record_datagrams, frag + 1);
  EXPECT_LT(delta, n + 64 * record_datagrams + 1500) << "the changed tile and a few digests, nothing else";
  auto back = std::make_unique<MapTileMsg>();
  const auto slot = team.store(1).find(RecordKey{0, tile_topic(5, 7)});
  ASSERT_TRUE(codec.decode(team.store(1).payload(slot), *back));
  EXPECT_TRUE(same_tile(*tile, *back));
}

}  // namespace
}  // namespace ag::comms
