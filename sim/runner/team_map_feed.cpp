// The ground robots' map feed in simulation: tiles of the world's class map (ground truth) or of the
// quadrotor's ortho-map (online), pushed on each robot's map_tiles channel as its map link would.
#include <algorithm>
#include <cmath>

#include "airground/sim/map_coverage.hpp"
#include "airground/sim/world.hpp"
#include "team.hpp"

namespace ag::sim::lockstep {
namespace {

// Ground-truth map tiles: the world's class raster resampled to the map's cells. A map cell takes the
// majority class of the world cells whose centres lie in it (ties: the first in row-major order from the
// north-west; the world cell under its centre when none does, as for worlds coarser than the map) and
// the mean surface elevation (terrain + height) of those cells. Cells outside the world are unknown.
void build_gt_tile(const World& w, std::int32_t tx, std::int32_t ty, MapTileMsg& m) {
  const double res = kMapResolutionM;
  m.tx = tx;
  m.ty = ty;
  m.version = 1;
  for (int r = 0; r < kTileCells; ++r) {
    for (int c = 0; c < kTileCells; ++c) {
      const auto i = static_cast<std::size_t>(r) * kTileCells + static_cast<std::size_t>(c);
      const double x = (static_cast<double>(tx) * kTileCells + c + 0.5) * res;
      const double y = (static_cast<double>(ty) * kTileCells + r + 0.5) * res;
      const WorldCellSummary cell = summarise_cell(w, x, y, res);
      m.cls[i] = cell.cls;
      m.elevation[i] = static_cast<float>(cell.surface);
    }
  }
}

void build_online_tile(const mapping::Tile& tile, std::uint32_t min_elevation_points, MapTileMsg& m) {
  m.tx = tile.key.tx;
  m.ty = tile.key.ty;
  m.version = tile.version;
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    const mapping::Cell& c = tile.live[i];
    m.cls[i] = c.cls;
    m.elevation[i] = c.reported_elevation(min_elevation_points);
  }
}

}  // namespace

// The tiles of the world's extent, nearest to `p` first (ties by index, so the order is fixed).
std::vector<std::pair<std::int32_t, std::int32_t>> gt_tile_order(const World& w, const Pose2& p) {
  const GridGeometry& g = w.grid();
  const double tile_m = kTileCells * kMapResolutionM;
  const auto tx0 = static_cast<std::int32_t>(std::floor(g.origin_x / tile_m));
  const auto tx1 = static_cast<std::int32_t>(std::ceil((g.origin_x + g.size_x()) / tile_m)) - 1;
  const auto ty0 = static_cast<std::int32_t>(std::floor((g.origin_y - g.size_y()) / tile_m));
  const auto ty1 = static_cast<std::int32_t>(std::ceil(g.origin_y / tile_m)) - 1;
  std::vector<std::pair<std::int32_t, std::int32_t>> out;
  for (std::int32_t ty = ty0; ty <= ty1; ++ty)
    for (std::int32_t tx = tx0; tx <= tx1; ++tx) out.emplace_back(tx, ty);
  auto d2 = [&](const std::pair<std::int32_t, std::int32_t>& k) {
    const double cx = (k.first + 0.5) * tile_m - p.x, cy = (k.second + 0.5) * tile_m - p.y;
    return cx * cx + cy * cy;
  };
  std::stable_sort(out.begin(), out.end(), [&](const auto& a, const auto& b) { return d2(a) < d2(b); });
  return out;
}

// Online source: note every tile whose version changed since the last look, for every ground robot.
void scan_online_map(Team& t) {
  const mapping::OrthoMap& m = *t.ortho;
  if (m.version() == t.ortho_version_seen) return;
  t.ortho_version_seen = m.version();
  t.changed.clear();
  m.for_each_tile([&](const mapping::Tile& tile) {
    const std::uint64_t key = tile.key.packed();
    t.tile_ptrs[key] = &tile;
    auto [it, fresh] = t.tile_versions.try_emplace(key, tile.version);
    if (!fresh && it->second == tile.version) return;
    it->second = tile.version;
    t.changed.push_back(key);
  });
  std::sort(t.changed.begin(), t.changed.end());  // the map's hash order is not an order to rely on
  for (auto& up : t.ugvs)
    for (const std::uint64_t key : t.changed)
      if (up->pending_set.insert(key).second) up->pending.push_back(key);
}

// Pushes this robot's next tiles while every reader's ring has room (the rest follow on later steps, so
// each reader gets each version once; a refused push would be retried, as a driver's would).
void publish_tiles(Team& t, Ugv& u, TimeNs now) {
  MapTileMsg& m = *t.tile_msg;
  for (int pushed = 0; pushed < t.opt.map_tiles_per_tick && u.tiles_out.free_slots() > 0; ++pushed) {
    if (t.opt.ugv_map == UgvMapSource::kGroundTruth) {
      if (u.gt_next >= u.gt_order.size()) return;
      build_gt_tile(*t.world, u.gt_order[u.gt_next].first, u.gt_order[u.gt_next].second, m);
      m.stamp = 0;  // the world never changes
    } else {
      if (u.pending.empty()) return;
      build_online_tile(*t.tile_ptrs.at(u.pending.front()), static_cast<std::uint32_t>(std::max(1, t.ortho->params().min_elevation_points)), m);
      m.stamp = now;
    }
    m.published = now;
    if (u.tiles_out.push(m) > 0) {
      ++u.tiles_refused;
      return;
    }
    ++u.tiles_published;
    if (t.opt.ugv_map == UgvMapSource::kGroundTruth) {
      ++u.gt_next;
    } else {
      u.pending_set.erase(u.pending.front());
      u.pending.pop_front();
    }
  }
}

// Online source: a robot waits at its start until the map knows most of its surroundings.
bool map_covers(const mapping::OrthoMap& m, const Pose2& p, double radius, double fraction, const GridGeometry& area) {
  const auto known = [&m](double x, double y) {
    const mapping::Cell* c = m.cell_at(x, y);
    return c != nullptr && c->cls != 255;
  };
  return known_fraction(known, p.x, p.y, radius, kMapResolutionM, area) >= fraction;
}

// Online source: the share of the cells within 3 m of a route (sampled every 2 m) that have a class.
double route_covered(const mapping::OrthoMap& m, const std::vector<Eigen::Vector2d>& route) {
  std::uint64_t known = 0, total = 0;
  for (std::size_t i = 0; i < route.size(); i += 2)
    for (double dy = -3.0; dy <= 3.0; dy += 1.0)
      for (double dx = -3.0; dx <= 3.0; dx += 1.0) {
        ++total;
        const mapping::Cell* c = m.cell_at(route[i].x() + dx, route[i].y() + dy);
        if (c != nullptr && c->cls != 255) ++known;
      }
  return total == 0 ? 1.0 : static_cast<double>(known) / static_cast<double>(total);
}

}  // namespace ag::sim::lockstep
