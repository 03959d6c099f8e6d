// bench_planning: the ground robot's roadmap planner on a synthetic 1024 x 1024-cell (512 m) world.
//   - full build from the class map (goal <= 2 s);
//   - one changed 64 x 64 tile folded in (goal <= 50 ms), against the full build;
//   - one query between random reachable points 40 m or more apart (goal <= 5 ms), against an
//     8-connected grid Dijkstra between the same points (the reference planner of the evaluation);
//   - path length against that grid optimum, and the roadmap's size and memory.
// Times are thread CPU time (medians of repeated runs). AG_BENCH_OUT=<file> appends one JSON line.
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include "../unit/planning/planning_world.hpp"
#include "bench_common.hpp"

namespace {
using namespace ag;
using namespace ag::plan;

double now_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}
}  // namespace

int main() {
  auto w = loc::test::make_world(16, 16, 42);
  std::printf("bench_planning: synthetic world %d x %d cells (%.0f m), R = %.0f m, min clearance %.1f m\n", w.width, w.height,
              w.width * w.resolution, RoadmapParams{}.visibility_radius_m, RoadmapParams{}.min_clearance_m);
  auto rm = std::make_unique<Roadmap>(RoadmapParams{}, ClassTable::builtin(), test::extent_of(w));
  for (int ty = 0; ty < w.tiles_y(); ++ty)
    for (int tx = 0; tx < w.tiles_x(); ++tx) (void)rm->set_tile(tx, ty, 1, w.tile(tx, ty));
  std::vector<double> builds;
  for (int k = 0; k < 3; ++k) {
    const double t0 = now_ms();
    rm->rebuild();
    builds.push_back(now_ms() - t0);
  }
  const double build_ms = median(builds);
  const RoadmapStats st = rm->stats();
  std::printf("  full build           %8.1f ms   (goal <= 2000 ms)  %u nodes (%u bridges), %u edges, %.1f MiB\n", build_ms, st.nodes,
              st.bridges, st.edges, static_cast<double>(rm->memory_bytes()) / (1024.0 * 1024.0));

  // The dense case: grass allowed at a cost, so most of the map is free.
  {
    RoadmapParams pg;
    pg.max_level = Traversability::kCostly;
    auto dense = std::make_unique<Roadmap>(pg, ClassTable::builtin(), test::extent_of(w));
    for (int ty = 0; ty < w.tiles_y(); ++ty)
      for (int tx = 0; tx < w.tiles_x(); ++tx) (void)dense->set_tile(tx, ty, 1, w.tile(tx, ty));
    const double t0 = now_ms();
    dense->rebuild();
    const double ms = now_ms() - t0;
    auto changed = w.tile(7, 7);
    for (int r = 20; r < 30; ++r)
      for (int c = 20; c < 24; ++c) changed[static_cast<std::size_t>(r * 64 + c)] = raw(ClassId::kVehicle);
    (void)dense->set_tile(7, 7, 2, changed);
    const double t1 = now_ms();
    (void)dense->update(1);
    const double tms = now_ms() - t1;
    std::printf("  full build, grass    %8.1f ms   (goal <= 2000 ms)  %u nodes (%u bridges), %u edges; one tile update %.2f ms\n", ms,
                dense->stats().nodes, dense->stats().bridges, dense->stats().edges, tms);
  }

  // Tile updates: a parked vehicle appears on a road in each of several tiles, then goes away.
  std::vector<double> tiles;
  for (int k = 0; k < 12; ++k) {
    const int tx = 2 + (k * 5) % 12, ty = 2 + (k * 7) % 12;
    const auto orig = w.tile(tx, ty);
    auto changed = orig;
    for (int r = 20; r < 30; ++r)
      for (int c = 20; c < 24; ++c) changed[static_cast<std::size_t>(r * 64 + c)] = raw(ClassId::kVehicle);
    (void)rm->set_tile(tx, ty, 2 + 2 * static_cast<std::uint64_t>(k), changed);
    double t0 = now_ms();
    (void)rm->update(1);
    tiles.push_back(now_ms() - t0);
    (void)rm->set_tile(tx, ty, 3 + 2 * static_cast<std::uint64_t>(k), orig);
    t0 = now_ms();
    (void)rm->update(1);
    tiles.push_back(now_ms() - t0);
  }
  const double tile_ms = median(tiles);
  std::printf("  one tile update      %8.2f ms   (goal <= 50 ms)    %.0fx faster than the full build; max %.2f ms\n", tile_ms,
              build_ms / std::max(tile_ms, 1e-6), *std::max_element(tiles.begin(), tiles.end()));

  // Queries.
  const GridReference ref = test::reference_of(w);
  const auto pairs = test::reachable_pairs(w, ref, 30, 7, 40.0);
  auto path = std::make_unique<PlannedPath>();
  std::vector<double> q, g;
  double ratio_sum = 0, ratio_max = 0, len_sum = 0;
  int ok = 0;
  for (const auto& [a, b] : pairs) {
    double t0 = now_ms();
    rm->plan(a, b, *path);
    q.push_back(now_ms() - t0);
    t0 = now_ms();
    const double grid = ref.shortest_m(a, b);
    g.push_back(now_ms() - t0);
    if (path->status != PlanStatus::kOk || grid <= 0) continue;
    ++ok;
    len_sum += path->length_m;
    ratio_sum += path->length_m / grid;
    ratio_max = std::max(ratio_max, path->length_m / grid);
  }
  const double q_ms = median(q), g_ms = median(g);
  std::printf("  one query            %8.3f ms   (goal <= 5 ms)     grid Dijkstra %.1f ms: %.0fx; max %.3f ms\n", q_ms, g_ms,
              g_ms / std::max(q_ms, 1e-6), *std::max_element(q.begin(), q.end()));
  std::printf("  paths                %d/%zu planned, mean %.0f m, length / grid optimum mean %.3f max %.3f\n", ok, pairs.size(),
              ok > 0 ? len_sum / ok : 0.0, ok > 0 ? ratio_sum / ok : 0.0, ratio_max);
  char json[512];
  std::snprintf(json, sizeof json,
                "{\"bench\":\"planning\",\"build_ms\":%.2f,\"tile_update_ms\":%.3f,\"query_ms\":%.4f,\"grid_dijkstra_ms\":%.3f,"
                "\"nodes\":%u,\"edges\":%u,\"ratio_mean\":%.4f,\"ratio_max\":%.4f}",
                build_ms, tile_ms, q_ms, g_ms, st.nodes, st.edges, ok > 0 ? ratio_sum / ok : 0.0, ratio_max);
  ag::bench::append_result_line(json);
  return 0;  // figures, not a test
}
