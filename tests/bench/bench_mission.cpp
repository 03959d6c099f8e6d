// bench_mission: one region extraction (opening, grouping by a 12 m merge distance via an exact distance
// transform, ids, clearance, reachable components, goals) over a 512 m x 512 m area (1M cells) with 60
// parked-car groups between buildings and roads, against a reference grouping that stamps a 6 m disc
// around every vehicle cell (the direct dilation); and one mission-manager tick with 300 regions and 10
// team-mates.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "airground/mission/manager.hpp"
#include "airground/mission/regions.hpp"

namespace {
using namespace ag;
using namespace ag::mission;
using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }
}  // namespace

int main() {
  const int tiles = 16, T = 64, W = tiles * T;
  std::vector<std::uint8_t> grid(static_cast<std::size_t>(W) * W, raw(ClassId::kGrass));
  std::mt19937 rng(1);
  auto rect = [&](int c0, int r0, int c1, int r1, ClassId c) {
    for (int r = std::max(0, r0); r < std::min(W, r1); ++r)
      for (int col = std::max(0, c0); col < std::min(W, c1); ++col) grid[static_cast<std::size_t>(r * W + col)] = raw(c);
  };
  for (int k = 0; k < W; k += 80) {  // a road grid every 40 m, 8 m wide
    rect(k, 0, k + 16, W, ClassId::kRoad);
    rect(0, k, W, k + 16, ClassId::kRoad);
  }
  for (int k = 0; k < 120; ++k) {  // buildings
    const int c = static_cast<int>(rng() % W), r = static_cast<int>(rng() % W);
    rect(c, r, c + 20 + static_cast<int>(rng() % 30), r + 20 + static_cast<int>(rng() % 30), ClassId::kBuilding);
  }
  for (int k = 0; k < 60; ++k) {  // car groups of 1-4 cars on the roads' edges
    const int c = (static_cast<int>(rng() % (W / 80))) * 80 + 2, r = static_cast<int>(rng() % (W - 40));
    const int n = 1 + static_cast<int>(rng() % 4);
    for (int i = 0; i < n; ++i) rect(c, r + i * 11, c + 4, r + i * 11 + 9, ClassId::kVehicle);
  }
  RegionExtractor ex(RegionParams{}, ClassTable::builtin(), TileExtent{0, 0, tiles, tiles});
  std::copy(grid.begin(), grid.end(), ex.classes().begin());
  ex.mark_changed();
  ex.extract();  // warm
  const int reps = 5;
  auto t0 = Clock::now();
  for (int i = 0; i < reps; ++i) ex.extract();
  const double ms = ms_since(t0) / reps;

  // reference: stamp a disc of 12 cells (6 m) around every vehicle cell
  std::vector<std::uint8_t> dil(grid.size(), 0);
  const int rad = 12;
  t0 = Clock::now();
  for (int i = 0; i < reps; ++i) {
    std::fill(dil.begin(), dil.end(), 0);
    for (int r = 0; r < W; ++r)
      for (int c = 0; c < W; ++c) {
        if (grid[static_cast<std::size_t>(r * W + c)] != raw(ClassId::kVehicle)) continue;
        for (int dr = -rad; dr <= rad; ++dr)
          for (int dc = -rad; dc <= rad; ++dc)
            if (dr * dr + dc * dc <= rad * rad && r + dr >= 0 && r + dr < W && c + dc >= 0 && c + dc < W)
              dil[static_cast<std::size_t>((r + dr) * W + c + dc)] = 1;
      }
  }
  const double ref_ms = ms_since(t0) / reps;
  std::size_t veh = 0;
  for (auto v : grid) veh += v == raw(ClassId::kVehicle);
  std::printf("regions: %zu regions from %zu vehicle cells over %d x %d cells (%.1f MB): extraction %.1f ms\n", ex.regions().size(), veh, W, W,
              static_cast<double>(ex.memory_bytes()) / 1e6, ms);
  std::printf("regions: reference disc-stamp dilation alone %.1f ms (extraction / reference = %.2f)\n", ref_ms, ms / ref_ms);

  // one manager tick with 300 regions and 10 peers
  ManagerParams p;
  MissionManager m(p);
  std::array<std::uint8_t, comms::kGossipPayloadMax> buf{};
  for (std::uint32_t b = 0; b < 8; ++b) {
    RegionBatch rb;
    rb.batches = 8;
    rb.regions_version = 1;
    rb.count = b < 7 ? 40 : 20;
    for (std::uint32_t i = 0; i < rb.count; ++i) {
      const float x = static_cast<float>(rng() % 500), y = static_cast<float>(rng() % 500);
      rb.regions[i] = RegionRecord{b * 40 + i + 1, x, y, x, y, 36, true};
    }
    (void)m.on_record(0, regions_topic(b), std::span<const std::uint8_t>(buf.data(), encode(rb, buf)), 0);
  }
  for (comms::RobotId r = 2; r < 12; ++r) {
    VisitedRecord v;
    v.count = 20;
    for (std::uint16_t i = 0; i < 20; ++i) v.entries[i] = VisitedEntry{static_cast<std::uint32_t>(r * 20 + i), 0, 0};
    (void)m.on_record(r, kVisitedTopic, std::span<const std::uint8_t>(buf.data(), encode(v, buf)), 0);
    m.on_peer_heard(r, 0);
  }
  LocalizationMsg l;
  l.status = LocalizationStatus::kTracking;
  l.covariance = {0.1, 0, 0, 0, 0.1, 0, 0, 0, 0.01};
  m.on_localization(l);
  const int ticks = 2000;
  t0 = Clock::now();
  for (int i = 0; i < ticks; ++i) {
    m.tick(from_seconds(0.2 * i));
    m.clear_outbox();
  }
  std::printf("manager: one tick with %zu regions, 10 peers x 20 visited: %.1f us\n", m.regions_known(), ms_since(t0) * 1e3 / ticks);
  return 0;
}
