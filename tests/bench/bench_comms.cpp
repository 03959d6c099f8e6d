// The gossip's costs, each against a reference measured in the same run: sealing + opening a datagram
// vs copying it; encoding + decoding a map tile vs copying it raw; syncing a full 500 m map between two
// nodes (time per MB of map) vs the same bytes pushed through memcpy.
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <vector>

#include "../unit/comms/map_fixture.hpp"
#include "../unit/comms/team_rig.hpp"
#include "airground/comms/tile_codec.hpp"
#include "airground/comms/wire.hpp"
#include "bench_common.hpp"

namespace {
using namespace ag;
using namespace ag::comms;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

int main() {
  std::printf("bench_comms: gossip costs against references measured in this run\n");
  // 1. Datagram sealing and opening (ChaCha20-Poly1305) vs memcpy of the same bytes.
  {
    DatagramCodec codec(test::test_key());
    ReplayGuard guard;
    std::vector<std::uint8_t> body(1200 - kSealOverhead, 0x5A), out(1200), back(1200);
    const int n = 200'000;
    auto t0 = Clock::now();
    std::size_t len = 0;
    for (int i = 0; i < n; ++i) {
      DatagramHeader h;
      h.type = MsgType::kRecords;
      h.sender = 2;
      h.epoch = 1;
      h.counter = static_cast<std::uint64_t>(i);
      const std::size_t s = codec.seal(h, body, out);
      DatagramHeader hh;
      DropReason why{};
      if (!codec.open(std::span<const std::uint8_t>(out.data(), s), 1, guard, hh, back, len, why)) std::abort();
    }
    const double crypto = seconds_since(t0) / n;
    t0 = Clock::now();
    volatile std::uint8_t sink = 0;
    for (int i = 0; i < n; ++i) {
      body[0] = static_cast<std::uint8_t>(i);
      std::memcpy(out.data(), body.data(), body.size());
      std::memcpy(back.data(), out.data(), body.size());
      sink = static_cast<std::uint8_t>(sink + back[0]);
    }
    const double copy = seconds_since(t0) / n;
    std::printf("  seal+open of a 1200 B datagram: %.2f us (%.0f MB/s), copy twice: %.3f us -> %.0fx the copy\n", crypto * 1e6,
                1200 / crypto / 1e6, copy * 1e6, crypto / copy);
  }
  // 2. Map tile encode + decode vs copying the raw tile.
  {
    TileCodec codec;
    auto tile = std::make_unique<MapTileMsg>();
    auto back = std::make_unique<MapTileMsg>();
    auto copy = std::make_unique<MapTileMsg>();
    std::vector<std::uint8_t> buf(TileCodec::max_payload_bytes());
    const int n = 300;
    std::size_t bytes = 0;
    test::make_tile(*tile, 5, 5, 500.0, 1);
    auto t0 = Clock::now();
    for (int i = 0; i < n; ++i) {
      tile->cls[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(i % 7);
      const std::size_t s = codec.encode(*tile, buf);
      bytes += s;
      if (!codec.decode(std::span<const std::uint8_t>(buf.data(), s), *back)) std::abort();
    }
    const double coded = seconds_since(t0) / n;
    t0 = Clock::now();
    for (int i = 0; i < n; ++i) {
      tile->cls[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(i % 5);
      std::memcpy(copy.get(), tile.get(), sizeof(MapTileMsg));
      std::memcpy(back.get(), copy.get(), sizeof(MapTileMsg));
    }
    const double raw = seconds_since(t0) / n;
    std::printf("  map tile encode+decode: %.0f us, %zu B -> %zu B (%.1f%%); raw copy twice %.1f us -> %.0fx the copy\n",
                coded * 1e6, kTileRawBytes, bytes / n, 100.0 * static_cast<double>(bytes / n) / kTileRawBytes, raw * 1e6, coded / raw);
  }
  // 3. A full 500 m x 500 m map between two nodes: CPU seconds of the whole exchange per MB of raw map.
  {
    GossipParams p;
    p.budget_bytes_per_s = 1e9;
    test::Team team(2, 0.0, 1, p, StoreLimits{1024, 16u << 20, TileCodec::max_payload_bytes()});
    TileCodec codec;
    auto tile = std::make_unique<MapTileMsg>();
    std::vector<std::uint8_t> buf(TileCodec::max_payload_bytes());
    for (int ty = 0; ty < 16; ++ty)
      for (int tx = 0; tx < 16; ++tx) {
        test::make_tile(*tile, tx, ty, 500.0, 1);
        const std::size_t n = codec.encode(*tile, buf);
        team.node(0).publish(tile_topic(tx, ty), 2, 1, std::span<const std::uint8_t>(buf.data(), n));
      }
    const auto t0 = Clock::now();
    const TimeNs sim = team.run_until_converged(60 * kNsPerS, 20 * kNsPerMs);
    const double cpu = seconds_since(t0);
    const double mb = 256.0 * kTileRawBytes / 1e6;
    std::vector<std::uint8_t> a(256 * kTileRawBytes, 1), b(a.size());
    const auto t1 = Clock::now();
    for (int i = 0; i < 10; ++i) {
      a[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(i);
      std::memcpy(b.data(), a.data(), a.size());
    }
    const double copy = seconds_since(t1) / 10;
    std::printf("  full map sync (256 tiles, %.1f MB raw): %.1f ms (one thread, both nodes) (%.1f ms/MB), %llu B on the wire, "
                "%.1f s simulated; memcpy of the raw map %.2f ms -> %.0fx\n",
                mb, cpu * 1e3, cpu * 1e3 / mb, static_cast<unsigned long long>(team.bytes_out()), to_seconds(sim), copy * 1e3, cpu / copy);
    bench::append_result_line("{\"bench\":\"comms_map_sync\",\"cpu_ms\":" + std::to_string(cpu * 1e3) +
                              ",\"wire_bytes\":" + std::to_string(team.bytes_out()) + "}");
  }
  return 0;
}
