// The ortho-map: binning keyframes into cells, versioned tiles, rebuilds after pose corrections.
#include "airground/aerial_mapping/ortho_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "airground/messages/classes.hpp"

namespace ag::mapping {

namespace {

std::int64_t floor_div(std::int64_t a, std::int64_t b) noexcept {
  const std::int64_t q = a / b;
  return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

std::int64_t cell_index(double v, double inv_res) noexcept { return static_cast<std::int64_t>(std::floor(v * inv_res)); }

// Tree, building and vehicle stand above the ground; the other classes are the ground itself.
bool raised(std::uint8_t c) noexcept {
  return c == raw(ClassId::kTree) || c == raw(ClassId::kBuilding) || c == raw(ClassId::kVehicle);
}
bool same_kind(std::uint8_t c, std::uint8_t cell) noexcept { return c != 255 && raised(c) == raised(cell); }
bool flat(std::uint8_t c) noexcept { return c != 255 && !raised(c); }

double rotation_angle(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) noexcept {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

// The local ground under each cell of the w x h scratch grid (see OrthoMapParams::ground_check_m): the
// median height of each cell's flat-class points (ground), then the median of those over the window
// around it (local_ground); NaN where there is none. start and order: the points sorted by cell.
void local_ground_heights(std::span<const MapPoint> points, const std::vector<std::uint32_t>& start,
                          const std::vector<std::uint32_t>& order, std::size_t w, std::size_t h, const OrthoMapParams& p,
                          std::vector<float>& heights, std::vector<float>& ground, std::vector<float>& local_ground) {
  constexpr float kNone = std::numeric_limits<float>::quiet_NaN();
  ground.assign(w * h, kNone);
  for (std::size_t cidx = 0; cidx < w * h; ++cidx) {
    heights.clear();
    for (std::uint32_t k = start[cidx]; k < start[cidx + 1]; ++k)
      if (flat(points[order[k]].cls)) heights.push_back(points[order[k]].z);
    if (heights.size() < static_cast<std::size_t>(std::max(1, p.min_keyframe_points))) continue;
    auto mid = heights.begin() + static_cast<std::ptrdiff_t>(heights.size() / 2);
    std::nth_element(heights.begin(), mid, heights.end());
    ground[cidx] = *mid;
  }
  local_ground.assign(w * h, kNone);
  const auto r = static_cast<std::ptrdiff_t>(std::max(0, p.ground_window_cells));
  const auto sw = static_cast<std::ptrdiff_t>(w), sh = static_cast<std::ptrdiff_t>(h);
  for (std::ptrdiff_t y = 0; y < sh; ++y)
    for (std::ptrdiff_t x = 0; x < sw; ++x) {
      const auto cidx = static_cast<std::size_t>(y * sw + x);
      if (start[cidx] == start[cidx + 1]) continue;
      heights.clear();
      for (std::ptrdiff_t yy = std::max<std::ptrdiff_t>(0, y - r); yy <= std::min(sh - 1, y + r); ++yy)
        for (std::ptrdiff_t xx = std::max<std::ptrdiff_t>(0, x - r); xx <= std::min(sw - 1, x + r); ++xx) {
          const float g = ground[static_cast<std::size_t>(yy * sw + xx)];
          if (!std::isnan(g)) heights.push_back(g);
        }
      if (heights.empty()) continue;
      auto mid = heights.begin() + static_cast<std::ptrdiff_t>(heights.size() / 2);
      std::nth_element(heights.begin(), mid, heights.end());
      local_ground[cidx] = *mid;
    }
}

// The ground of a whole keyframe: the median of its flat-class points (NaN without any).
float keyframe_ground(std::span<const MapPoint> points, std::vector<float>& heights) {
  float patch_ground = std::numeric_limits<float>::quiet_NaN();
  heights.clear();
  for (const MapPoint& m : points)
    if (flat(m.cls)) heights.push_back(m.z);
  if (!heights.empty()) {
    auto mid = heights.begin() + static_cast<std::ptrdiff_t>(heights.size() / 2);
    std::nth_element(heights.begin(), mid, heights.end());
    patch_ground = *mid;
  }
  return patch_ground;
}


}  // namespace

OrthoMap::OrthoMap(const OrthoMapParams& params) : p_(params), inv_res_(1.0 / params.resolution_m) {}

Tile* OrthoMap::tile_for(std::int64_t cx, std::int64_t cy, bool create) {
  const std::int64_t t = p_.tile_cells;
  const TileKey key{static_cast<std::int32_t>(floor_div(cx, t)), static_cast<std::int32_t>(floor_div(cy, t))};
  const auto it = tiles_.find(key.packed());
  if (it != tiles_.end()) return it->second.get();
  if (!create || tiles_.size() >= p_.max_tiles) return nullptr;
  auto tile = std::make_unique<Tile>();
  tile->key = key;
  const auto n = static_cast<std::size_t>(t * t);
  tile->base.assign(n, Cell{});
  tile->live.assign(n, Cell{});
  Tile* raw = tile.get();
  tiles_.emplace(key.packed(), std::move(tile));
  return raw;
}

void OrthoMap::touched_tiles(Patch& patch) const {
  patch.tiles.clear();
  const std::int64_t t = p_.tile_cells;
  for (const PatchCell& c : patch.cells) {
    const Eigen::Vector3d p = patch.pose * (patch.depth_scale * Eigen::Vector3d(c.x, c.y, c.z));
    const TileKey key{static_cast<std::int32_t>(floor_div(cell_index(p.x(), inv_res_), t)),
                      static_cast<std::int32_t>(floor_div(cell_index(p.y(), inv_res_), t))};
    const std::uint64_t k = key.packed();
    if (std::find(patch.tiles.begin(), patch.tiles.end(), k) == patch.tiles.end()) patch.tiles.push_back(k);
  }
}

void OrthoMap::apply(const Patch& patch, bool to_base, const std::unordered_map<std::uint64_t, Tile*>* only) {
  const std::int64_t t = p_.tile_cells;
  const auto gate = static_cast<float>(p_.elevation_gate_m);
  const auto min_points = static_cast<std::uint32_t>(p_.min_points);
  for (const PatchCell& c : patch.cells) {
    const Eigen::Vector3d p = patch.pose * (patch.depth_scale * Eigen::Vector3d(c.x, c.y, c.z));
    const std::int64_t cx = cell_index(p.x(), inv_res_), cy = cell_index(p.y(), inv_res_);
    Tile* tile = nullptr;
    if (only != nullptr) {
      const TileKey key{static_cast<std::int32_t>(floor_div(cx, t)), static_cast<std::int32_t>(floor_div(cy, t))};
      const auto it = only->find(key.packed());
      if (it == only->end()) continue;
      tile = it->second;
    } else {
      tile = tile_for(cx, cy, true);
      if (tile == nullptr) {
        stats_.points_refused += c.count;
        continue;
      }
    }
    const auto lx = static_cast<std::size_t>(cx - static_cast<std::int64_t>(tile->key.tx) * t);
    const auto ly = static_cast<std::size_t>(cy - static_cast<std::int64_t>(tile->key.ty) * t);
    Cell& cell = (to_base ? tile->base : tile->live)[ly * static_cast<std::size_t>(t) + lx];
    const auto z = static_cast<float>(p.z());
    const auto n = static_cast<float>(c.count);
    if (cell.count == 0 || std::fabs(z - cell.elevation()) <= gate) {
      cell.elevation_sum += z * n;
      cell.count += c.count;
    } else if (cell.rival_count == 0 || std::fabs(z - cell.rival()) <= gate) {
      cell.rival_sum += z * n;
      cell.rival_count += c.count;
      if (cell.rival_count > cell.count) {  // the rival now has more support: it leads
        std::swap(cell.elevation_sum, cell.rival_sum);
        std::swap(cell.count, cell.rival_count);
        cell.best_cos = -2.0F;  // colour and class were accepted against the old surface
        cell.cls_cos = -2.0F;
        cell.cls = 255;
      }
    } else if (c.count > cell.rival_count) {  // a third surface: keep the better supported of the two rivals
      cell.rival_sum = z * n;
      cell.rival_count = c.count;
    }
    if (cell.count >= min_points && std::fabs(z - cell.elevation()) <= gate) {
      if (c.cls != 255 && (cell.cls == 255 || c.cos > cell.cls_cos)) {
        cell.cls = c.cls;
        cell.cls_cos = c.cos;
      }
      if (c.cos > cell.best_cos) {
        cell.best_cos = c.cos;
        cell.r = c.r;
        cell.g = c.g;
        cell.b = c.b;
      }
    }
    if (!to_base) tile->version = version_ + 1;
  }
  ++version_;
}

void OrthoMap::add_keyframe(std::uint32_t id, const Eigen::Isometry3d& map_from_camera, std::span<const MapPoint> points,
                            std::uint32_t partner, double baseline_m) {
  ++stats_.keyframes;
  stats_.points += points.size();
  if (points.empty()) return;
  // Bin in a dense scratch grid over the points' extent.
  std::int64_t x0 = std::numeric_limits<std::int64_t>::max(), y0 = x0, x1 = std::numeric_limits<std::int64_t>::min(), y1 = x1;
  for (const MapPoint& m : points) {
    const std::int64_t cx = cell_index(m.x, inv_res_), cy = cell_index(m.y, inv_res_);
    x0 = std::min(x0, cx);
    x1 = std::max(x1, cx);
    y0 = std::min(y0, cy);
    y1 = std::max(y1, cy);
  }
  const auto w = static_cast<std::size_t>(x1 - x0 + 1), h = static_cast<std::size_t>(y1 - y0 + 1);
  auto index_of = [&](const MapPoint& m) {
    return static_cast<std::size_t>(cell_index(m.y, inv_res_) - y0) * w + static_cast<std::size_t>(cell_index(m.x, inv_res_) - x0);
  };
  // Counting sort of the points by cell, so each cell's heights are contiguous.
  start_.assign(w * h + 1, 0);
  for (const MapPoint& m : points) ++start_[index_of(m) + 1];
  for (std::size_t i = 1; i < start_.size(); ++i) start_[i] += start_[i - 1];
  order_.resize(points.size());
  fill_ = start_;
  for (std::uint32_t k = 0; k < points.size(); ++k) order_[fill_[index_of(points[k])]++] = k;
  acc_.assign(w * h, Acc{});
  const double gate = p_.elevation_gate_m;
  // The local ground under each cell (see OrthoMapParams::ground_check_m).
  const bool check = p_.ground_check_m > 0;
  if (check) local_ground_heights(points, start_, order_, w, h, p_, heights_, ground_, local_ground_);
  const auto ground_tol = static_cast<float>(p_.ground_check_m), raised_min = static_cast<float>(p_.raised_min_height_m);
  // Where no flat-class point lies within the window (inside a paved square or a big roof), the ground of
  // the whole keyframe: the median of its flat-class points.
  const float patch_ground = check ? keyframe_ground(points, heights_) : std::numeric_limits<float>::quiet_NaN();
  for (std::size_t cidx = 0; cidx < w * h; ++cidx) {
    const std::uint32_t b = start_[cidx], e = start_[cidx + 1];
    if (e - b < static_cast<std::uint32_t>(std::max(1, p_.min_keyframe_points))) continue;  // too few to trust
    const float local = check ? local_ground_[cidx] : std::numeric_limits<float>::quiet_NaN();
    const float ground = std::isnan(local) ? patch_ground : local;
    // A "building" at ground height is paved ground (a flat grey square looks like a roof from above).
    auto cls_of = [&](const MapPoint& m) -> std::uint8_t {
      if (m.cls == raw(ClassId::kBuilding) && !std::isnan(ground) && std::fabs(m.z - ground) <= ground_tol) return raw(ClassId::kRoad);
      return m.cls;
    };
    auto plausible = [&](const MapPoint& m) {
      const std::uint8_t c = cls_of(m);
      if (std::isnan(ground) || c == 255) return true;
      return raised(c) ? m.z >= ground + raised_min : std::fabs(m.z - ground) <= ground_tol;
    };
    // The cell's class: the labelled point nearest the image centre.
    std::uint8_t central = 255;
    float central_cos = -2.0F;
    for (std::uint32_t k = b; k < e; ++k) {
      const MapPoint& m = points[order_[k]];
      if (m.cls != 255 && m.cos_axis > central_cos && plausible(m)) {
        central_cos = m.cos_axis;
        central = cls_of(m);
      }
    }
    // Class-consistent height: when enough points carry a class of the same kind (raised: tree,
    // building, vehicle; or flat) as the cell's, only they give its height. A roof edge projected a
    // few decimetres into the road beside it then no longer lifts the road cell, nor the road the roof.
    const bool group = p_.class_consistent_elevation && central != 255;
    std::uint32_t same = 0, kept = 0;
    for (std::uint32_t k = b; k < e; ++k) {
      const MapPoint& m = points[order_[k]];
      if (!plausible(m)) continue;
      ++kept;
      same += group && same_kind(cls_of(m), central) ? 1U : 0U;
    }
    if (kept < static_cast<std::uint32_t>(std::max(1, p_.min_keyframe_points))) continue;
    const bool use_group = group && same >= static_cast<std::uint32_t>(std::max(1, p_.min_keyframe_points));
    auto counts = [&](const MapPoint& m) { return plausible(m) && (!use_group || same_kind(cls_of(m), central)); };
    // Robust height: the median, then the mean of the points within the gate of it (a wrong stereo
    // match lands metres away and must not drag the cell).
    heights_.clear();
    for (std::uint32_t k = b; k < e; ++k)
      if (counts(points[order_[k]])) heights_.push_back(points[order_[k]].z);
    auto mid = heights_.begin() + static_cast<std::ptrdiff_t>(heights_.size() / 2);
    std::nth_element(heights_.begin(), mid, heights_.end());
    const double median = static_cast<double>(*mid);
    Acc& a = acc_[cidx];
    for (std::uint32_t k = b; k < e; ++k) {
      const MapPoint& m = points[order_[k]];
      if (!counts(m) || std::fabs(static_cast<double>(m.z) - median) > gate) continue;
      a.sx += static_cast<double>(m.x);
      a.sy += static_cast<double>(m.y);
      a.sz += static_cast<double>(m.z);
      ++a.n;
      if (m.cos_axis > a.cos) {
        a.cos = m.cos_axis;
        a.r = m.r;
        a.g = m.g;
        a.b = m.b;
      }
      if (m.cls != 255 && m.cos_axis > a.cls_cos) {
        a.cls_cos = m.cos_axis;
        a.cls = cls_of(m);
      }
    }
  }
  Patch patch;
  patch.id = id;
  patch.pose = map_from_camera;
  patch.partner = partner;
  patch.baseline_m = baseline_m;
  const Eigen::Isometry3d camera_from_map = map_from_camera.inverse();
  for (const Acc& a : acc_) {
    if (a.n == 0) continue;
    const double n = a.n;
    const Eigen::Vector3d c = camera_from_map * Eigen::Vector3d(a.sx / n, a.sy / n, a.sz / n);
    patch.cells.push_back(PatchCell{static_cast<float>(c.x()), static_cast<float>(c.y()), static_cast<float>(c.z()), a.n,
                                    std::max(a.cos, a.cls_cos), a.r, a.g, a.b, a.cls});
  }
  double depth_sum = 0;
  for (const PatchCell& c : patch.cells) depth_sum += std::fabs(static_cast<double>(c.z));
  patch.depth_m = patch.cells.empty() ? 0.0F : static_cast<float>(depth_sum / static_cast<double>(patch.cells.size()));
  touched_tiles(patch);
  apply(patch, false, nullptr);
  window_.push_back(std::move(patch));
  while (window_.size() > static_cast<std::size_t>(std::max(1, p_.window_keyframes))) freeze_oldest();
}

void OrthoMap::freeze_oldest() {
  apply(window_.front(), true, nullptr);
  window_.erase(window_.begin());
  ++stats_.keyframes_frozen;
}

std::size_t OrthoMap::memory_bytes() const noexcept {
  std::size_t n = tiles_.bucket_count() * sizeof(void*);
  for (const auto& [k, t] : tiles_)
    n += sizeof(Tile) + 32 + (t->base.capacity() + t->live.capacity()) * sizeof(Cell);
  n += window_.capacity() * sizeof(Patch);
  for (const Patch& p : window_) n += p.cells.capacity() * sizeof(PatchCell) + p.tiles.capacity() * sizeof(std::uint64_t);
  n += (acc_.capacity() * sizeof(Acc)) + (start_.capacity() + fill_.capacity() + order_.capacity()) * sizeof(std::uint32_t) +
       (heights_.capacity() + ground_.capacity() + local_ground_.capacity()) * sizeof(float);
  return n;
}

const Eigen::Isometry3d* OrthoMap::keyframe_pose(std::uint32_t id) const noexcept {
  const auto it = std::lower_bound(window_.begin(), window_.end(), id, [](const Patch& p, std::uint32_t v) { return p.id < v; });
  return (it != window_.end() && it->id == id) ? &it->pose : nullptr;
}

std::size_t OrthoMap::correct(std::span<const std::pair<std::uint32_t, Eigen::Isometry3d>> poses) {
  std::unordered_map<std::uint64_t, Tile*> affected;
  auto mark = [&](const Patch& p) {
    for (const std::uint64_t k : p.tiles) {
      const auto it = tiles_.find(k);
      if (it != tiles_.end()) affected.emplace(k, it->second.get());
    }
  };
  for (const auto& [id, pose] : poses) {
    auto it = std::lower_bound(window_.begin(), window_.end(), id, [](const Patch& p, std::uint32_t v) { return p.id < v; });
    if (it == window_.end() || it->id != id) continue;
    const double moved = (pose.translation() - it->pose.translation()).norm();
    const double turned = rotation_angle(pose.linear(), it->pose.linear());
    double depth_scale = it->depth_scale;
    if (p_.rescale_depth && it->partner != kNoPartner && it->baseline_m > 0) {
      const auto q = std::lower_bound(poses.begin(), poses.end(), it->partner,
                                      [](const std::pair<std::uint32_t, Eigen::Isometry3d>& e, std::uint32_t v) { return e.first < v; });
      if (q != poses.end() && q->first == it->partner)
        depth_scale = (pose.translation() - q->second.translation()).norm() / it->baseline_m;
    }
    const double rescaled = std::fabs(depth_scale - it->depth_scale) * static_cast<double>(it->depth_m);
    if (moved <= p_.rebuild_translation_m && turned <= p_.rebuild_rotation_rad && rescaled <= p_.rebuild_translation_m) continue;
    ++stats_.keyframes_moved;
    mark(*it);
    it->pose = pose;
    it->depth_scale = depth_scale;
    touched_tiles(*it);
    for (const std::uint64_t k : it->tiles) {  // tiles it now reaches for the first time
      const std::int64_t t = p_.tile_cells;
      const auto tx = static_cast<std::int32_t>(static_cast<std::uint32_t>(k >> 32));
      const auto ty = static_cast<std::int32_t>(static_cast<std::uint32_t>(k & 0xffffffffU));
      if (Tile* tile = tile_for(static_cast<std::int64_t>(tx) * t, static_cast<std::int64_t>(ty) * t, true)) affected.emplace(k, tile);
    }
  }
  if (affected.empty()) return 0;
  for (auto& [k, tile] : affected) tile->live = tile->base;
  for (const Patch& p : window_) {
    const bool touches = std::any_of(p.tiles.begin(), p.tiles.end(), [&](std::uint64_t k) { return affected.count(k) != 0; });
    if (touches) apply(p, false, &affected);
  }
  ++version_;
  for (auto& [k, tile] : affected) tile->version = version_;
  stats_.tiles_rebuilt += affected.size();
  return affected.size();
}

const Cell* OrthoMap::cell_at(double x, double y) const noexcept {
  const std::int64_t t = p_.tile_cells;
  const std::int64_t cx = cell_index(x, inv_res_), cy = cell_index(y, inv_res_);
  const TileKey key{static_cast<std::int32_t>(floor_div(cx, t)), static_cast<std::int32_t>(floor_div(cy, t))};
  const auto it = tiles_.find(key.packed());
  if (it == tiles_.end()) return nullptr;
  const auto lx = static_cast<std::size_t>(cx - static_cast<std::int64_t>(key.tx) * t);
  const auto ly = static_cast<std::size_t>(cy - static_cast<std::int64_t>(key.ty) * t);
  return &it->second->live[ly * static_cast<std::size_t>(t) + lx];
}

std::uint64_t OrthoMap::cells_classified() const noexcept {
  std::uint64_t n = 0;
  for (const auto& [k, t] : tiles_)
    for (const Cell& c : t->live) n += c.cls != 255 ? 1U : 0U;
  return n;
}

MapRaster OrthoMap::raster() const {
  GridGeometry g;
  g.resolution = p_.resolution_m;
  if (tiles_.empty()) return raster(g);
  std::int32_t tx0 = std::numeric_limits<std::int32_t>::max(), ty0 = tx0, tx1 = std::numeric_limits<std::int32_t>::min(), ty1 = tx1;
  for (const auto& [k, t] : tiles_) {
    tx0 = std::min(tx0, t->key.tx);
    tx1 = std::max(tx1, t->key.tx);
    ty0 = std::min(ty0, t->key.ty);
    ty1 = std::max(ty1, t->key.ty);
  }
  const double tile_m = p_.tile_cells * p_.resolution_m;
  g.width = (tx1 - tx0 + 1) * p_.tile_cells;
  g.height = (ty1 - ty0 + 1) * p_.tile_cells;
  g.origin_x = tx0 * tile_m;
  g.origin_y = (ty1 + 1) * tile_m;
  return raster(g);
}

MapRaster OrthoMap::raster(const GridGeometry& grid) const {
  MapRaster r;
  r.grid = grid;
  const auto n = static_cast<std::size_t>(grid.width) * static_cast<std::size_t>(grid.height);
  r.cls.assign(n, 255);
  r.elevation.assign(n, std::numeric_limits<float>::quiet_NaN());
  r.rgb.assign(n * 3, 0);
  r.count.assign(n, 0);
  for (std::int32_t row = 0; row < grid.height; ++row)
    for (std::int32_t col = 0; col < grid.width; ++col) {
      const Cell* c = cell_at(grid.x_of(col), grid.y_of(row));
      if (c == nullptr || c->count == 0) continue;
      const auto i = static_cast<std::size_t>(row) * static_cast<std::size_t>(grid.width) + static_cast<std::size_t>(col);
      r.cls[i] = c->cls;
      r.elevation[i] = c->reported_elevation(static_cast<std::uint32_t>(std::max(1, p_.min_elevation_points)));
      r.rgb[3 * i] = c->r;
      r.rgb[3 * i + 1] = c->g;
      r.rgb[3 * i + 2] = c->b;
      r.count[i] = c->count;
    }
  return r;
}

}  // namespace ag::mapping
