// Aerial class distance fields: for every channel, the truncated Euclidean distance from each cell of
// the aerial class map to the nearest cell that is a source of the channel, quantised to one byte.
//
// The map arrives as ortho-map tiles (tile_cells^2 class ids, row 0 at the south edge, tile (0, 0)
// starting at the map-frame origin) over a fixed extent given in tiles (the mission area). A changed
// tile only recomputes the fields within the truncation distance of it: an exact two-pass transform
// (column sweeps, then Felzenszwalb-Huttenlocher lower envelopes along rows) over the tile plus two
// margins, a few milliseconds, so the fields follow a map that is still being built.
//
// Unknown cells (class 255, and everything outside the extent) are unknown: each cell stores its class
// next to its distances, so the filter leaves the bins that fall on unknown cells out of a particle's
// cost. With unknown_is_source, unknown cells also count as sources of every channel, so a distance
// next to unexplored ground is the optimistic min(distance to the class, distance to the unknown): the
// class may be just behind the edge of what the quadrotor has seen.
//
// A surface channel (LocalizationChannels::set_surface) takes as sources only its member cells with a
// 4-neighbour that is not a member (unknown and outside count as members when unknown_is_source); a
// changed tile then also changes the sources one cell beyond it, so its recomputed rectangle reaches one
// cell further.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/localization/scan.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/distance_transform.hpp"

namespace ag::loc {

struct DistanceFieldParams {
  double resolution_m{0.5};     // [m] cell size of the aerial map (DESIGN.md: 0.5 m)
  int tile_cells{64};           // [cells] tile edge of the aerial map
  double truncation_m{25.0};    // [m] distances are clamped here (their code: 50 px)
  bool unknown_is_source{true}; // unknown cells count as sources of every channel (optimistic distances)
  int full_block_tiles{4};      // recompute_all() works in blocks of this many tiles squared; update() groups
                                // changed tiles within such a block
  bool obstacle_faces{true};    // geometric labels: obstacle points match the faces of the map's obstacle regions
};

inline constexpr ParamField<DistanceFieldParams> kDistanceFieldFields[] = {
    field::real("field_truncation_m", &DistanceFieldParams::truncation_m, 1.0, 60.0, "m", "distances are clamped here (their code: 50 px)"),
    field::boolean("field_unknown_is_source", &DistanceFieldParams::unknown_is_source, "unknown cells count as sources (optimistic distances near the unknown)"),
    field::boolean("field_obstacle_faces", &DistanceFieldParams::obstacle_faces, "geometric labels: an obstacle point matches the edge of the map's obstacle regions (walls, vehicles, "
                       "crowns down to the ground), not their inside; false where the LiDAR sees trunks deep under wide crowns"),
};
inline constexpr auto kDistanceFieldParamSpecs = param_specs(kDistanceFieldFields);
// resolution_m and tile_cells come from the aerial map, not from here.
DistanceFieldParams load_distance_field_params(const SectionView& s, double resolution_m, int tile_cells);


class ClassDistanceFields {
 public:
  // Allocates everything for the extent; all cells start unknown and the fields are consistent.
  ClassDistanceFields(const DistanceFieldParams& params, const LocalizationChannels& channels, const TileExtent& extent);

  // Copies one tile's class ids (tile_cells^2, row-major, row 0 = south). Returns false when the tile is
  // outside the extent, the size is wrong, or the version equals the stored one. The fields around it
  // are stale until update(); a new version with the same class ids changes no field and is not pending.
  // Never allocates.
  bool set_tile(std::int32_t tx, std::int32_t ty, std::uint64_t version, std::span<const std::uint8_t> cls) noexcept;
  // Recomputes the fields around the changed tiles, oldest change first, for at most the work of
  // `max_tiles` tiles done one by one: neighbouring changed tiles (within full_block_tiles) go in one
  // rectangle, which shares their margins, so more tiles may be done for that work. Returns the number
  // of tiles done (at least one when any is pending). Never allocates.
  std::size_t update(std::size_t max_tiles = SIZE_MAX) noexcept;
  // Recomputes every field from the classes (and clears the changed set). Never allocates.
  void recompute_all() noexcept;
  [[nodiscard]] std::size_t pending_tiles() const noexcept { return n_dirty_; }
  [[nodiscard]] std::uint64_t tile_version(std::int32_t tx, std::int32_t ty) const noexcept;

  // Cells: width x height, row-major, row 0 at the south edge (map-frame y grows with the row). Each
  // cell is `stride()` bytes: the channels' quantised distances (distance = byte x quantum_m()), then
  // the cell's class id at [stride() - 1]. One more cell at index width x height is the "outside" cell
  // (unknown, class 255), for lookups that leave the extent.
  [[nodiscard]] const std::uint8_t* cells() const noexcept { return cells_.data(); }
  [[nodiscard]] int stride() const noexcept { return kStride; }
  [[nodiscard]] std::int32_t width() const noexcept { return width_; }
  [[nodiscard]] std::int32_t height() const noexcept { return height_; }
  [[nodiscard]] double origin_x() const noexcept { return origin_x_; }  // [m] west edge
  [[nodiscard]] double origin_y() const noexcept { return origin_y_; }  // [m] south edge
  [[nodiscard]] double resolution_m() const noexcept { return p_.resolution_m; }
  [[nodiscard]] double quantum_m() const noexcept { return quantum_m_; }
  [[nodiscard]] std::size_t outside_index() const noexcept { return static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_); }
  // Cell index of a map-frame point, outside_index() when outside the extent.
  [[nodiscard]] std::size_t index_at(double x, double y) const noexcept;
  [[nodiscard]] std::uint8_t class_at(double x, double y) const noexcept;
  [[nodiscard]] double distance_m(double x, double y, int channel) const noexcept;  // [m] quantised, truncated
  [[nodiscard]] const LocalizationChannels& channels() const noexcept { return channels_; }
  [[nodiscard]] const DistanceFieldParams& params() const noexcept { return p_; }
  [[nodiscard]] const TileExtent& extent() const noexcept { return extent_; }
  [[nodiscard]] std::size_t memory_bytes() const noexcept;  // everything this object holds

  static constexpr int kStride = kMaxChannels + 1;

 private:
  // Recomputes the output rectangle [x0, x1) x [y0, y1) (cells, clamped to the extent).
  void recompute_rect(std::int32_t x0, std::int32_t y0, std::int32_t x1, std::int32_t y1) noexcept;
  // Clears the surface-channel bits of the interior cells in row gy, cells gx0 .. gx0 + n - 1.
  void keep_faces(std::int32_t gy, std::int32_t gx0, std::int32_t n, std::uint8_t* bits) const noexcept;
  // The work of recompute_rect() around a rectangle of tiles_w x tiles_h tiles [cell visits].
  [[nodiscard]] double rect_cost(std::int32_t tiles_w, std::int32_t tiles_h) const noexcept;

  DistanceFieldParams p_;
  LocalizationChannels channels_;
  TileExtent extent_;
  std::int32_t width_{0}, height_{0};
  double origin_x_{0}, origin_y_{0};
  double quantum_m_{0.1};
  std::int32_t margin_{0};  // [cells] ceil(truncation / resolution)
  std::int32_t reach_{0};   // [cells] how far a changed tile's fields change: margin_, + 1 with surface channels
  std::int32_t max_out_{0};  // [cells] largest output rectangle edge the scratch holds
  std::array<std::uint8_t, 256> source_mask_{};  // class id -> channel bits
  std::vector<std::uint8_t> cells_;
  std::vector<std::uint64_t> tile_version_;
  std::vector<std::uint8_t> tile_dirty_;
  std::vector<std::uint32_t> dirty_;  // changed tiles in order of change (a ring of tile indices)
  std::size_t dirty_head_{0}, n_dirty_{0};
  std::vector<std::uint8_t> quantise_;  // squared distance [cells^2] -> byte
  // scratch of one rectangle
  std::vector<std::uint8_t> src_;   // [in_row][in_col] channel bits
  std::vector<std::int16_t> g_;     // [channel][out_row][in_col] vertical distance [cells], > margin = none
  std::vector<std::int16_t> run_;   // [channel][in_col] the sweeps' run lengths [cells]
  dt::EnvelopeScratch<double> envelope_;  // the row pass (platform/distance_transform.hpp)
};

}  // namespace ag::loc
