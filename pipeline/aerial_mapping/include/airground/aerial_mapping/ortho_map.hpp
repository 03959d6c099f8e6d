// The ortho-map: 0.5 m cells in fixed-size, versioned tiles over the map frame, built from keyframes'
// stereo points. Per cell (ASOOM): elevation is the running mean of every point's height; colour and
// class come from the observation nearest the image centre, accepted only within `elevation_gate_m` of
// the cell's mean and once the cell has `min_points`; "unknown" never overwrites a class.
//
// Rebuilds: each keyframe's contribution is kept as a compact patch (one entry per cell it saw, in the
// keyframe camera's frame) while it is inside the window of keyframes the pose graph may still move.
// When the graph moves a keyframe beyond the thresholds, only the tiles it touched (before and after)
// are rebuilt: from their base layer (everything that left the window) plus the window's patches. A
// keyframe leaving the window is folded into the base layers, so memory stays bounded by the area.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <unordered_map>
#include <utility>
#include <vector>

#include "airground/aerial_mapping/stereo.hpp"
#include "airground/messages/geometry.hpp"

namespace ag::mapping {

struct OrthoMapParams {
  double resolution_m{0.5};          // [m] cell size (DESIGN.md: 0.5 m)
  int tile_cells{64};                // [cells] tile edge (64 x 0.5 m = 32 m)
  double elevation_gate_m{1.0};      // [m] colour/class accepted only this close to the cell's mean (ASOOM: 1 m)
  int min_points{4};                 // [points] a cell needs this many before it takes a class
  bool class_consistent_elevation{true};  // a cell's height from the points of its own kind (raised or flat) when enough
  int min_keyframe_points{3};        // [points] one keyframe's points in a cell below this are dropped (no robust median)
  // Semantic plausibility per keyframe: the local ground is the median height of the flat-class points
  // (road, dirt, grass, water) of the cells within ground_window_cells; a flat-class point further than
  // ground_check_m from it, or a raised-class point (tree, building, vehicle) less than
  // raised_min_height_m above it, is a wrong match (block matching spreads a roof or a crown over the
  // ground beside it, and the ground over the crown's rim) and is dropped. 0 = off.
  double ground_check_m{1.0};        // [m]
  int ground_window_cells{3};        // [cells] half-width of the window (3: 7 x 7 cells, 3.5 m at 0.5 m)
  double raised_min_height_m{0.3};   // [m]
  // A cell reports an elevation once its leading hypothesis has this many points (a typical cell seen
  // from 40 m gathers hundreds; the few points that reach a narrow gap between crowns, or the far side of
  // a wall, are mostly wrong matches). Fewer: elevation unknown (NaN), class and colour still shown.
  int min_elevation_points{32};      // [points]
  int window_keyframes{256};         // keyframes kept re-binnable (>= the pose graph's free window)
  double rebuild_translation_m{0.2}; // [m] a keyframe moved further than this is re-binned
  double rebuild_rotation_rad{0.005};  // [rad] ... or turned by more than this
  // Stereo depth is metric only through the pair's baseline, which the pose graph keeps correcting after
  // the pair was matched (the newest frames' scale is a prediction until GPS has seen them travel). On,
  // a keyframe's points are re-scaled about its camera by (baseline now / baseline matched) whenever the
  // graph moves it or its stereo partner; off, they keep the depth of the moment they were matched
  // (ASOOM, OpenREALM).
  bool rescale_depth{true};
  std::size_t max_tiles{16384};      // refuse (and count) points beyond this many tiles (16 km^2 at defaults)
};

// Elevation keeps two hypotheses: the running mean of the observations that agree (within the gate)
// with the leading one, and a rival built from those that do not. Block matching puts occluded ground
// on a roof edge, or a roof on the ground beside it, from some viewpoints only; when the rival gathers
// more support than the leader they swap. With one consistent surface this is ASOOM's running mean.
struct Cell {
  float elevation_sum{0};   // [m x points] sum of the leading hypothesis's heights
  std::uint32_t count{0};   // points in the leading hypothesis
  float rival_sum{0};       // [m x points]
  std::uint32_t rival_count{0};
  float best_cos{-2.0F};    // cosine to the optical axis of the accepted colour observation
  float cls_cos{-2.0F};     // ... and of the accepted class observation (unknown ones never count)
  std::uint8_t r{0}, g{0}, b{0};
  std::uint8_t cls{255};    // class id, 255 unknown
  [[nodiscard]] float elevation() const noexcept { return count ? elevation_sum / static_cast<float>(count) : 0.0F; }
  [[nodiscard]] float rival() const noexcept { return rival_count ? rival_sum / static_cast<float>(rival_count) : 0.0F; }
  // What the map reports: the leading hypothesis once it has min_points points, else NaN (unknown).
  [[nodiscard]] float reported_elevation(std::uint32_t min_points) const noexcept {
    return count > 0 && count >= min_points ? elevation() : std::numeric_limits<float>::quiet_NaN();
  }
};

struct TileKey {
  std::int32_t tx{0}, ty{0};  // tile column (east) and row (north) index; tile (0,0) starts at the map origin
  [[nodiscard]] std::uint64_t packed() const noexcept {
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(tx)) << 32) | static_cast<std::uint32_t>(ty);
  }
  friend bool operator==(const TileKey&, const TileKey&) = default;
};

struct Tile {
  TileKey key;
  std::uint64_t version{0};  // changes with every change to its cells
  std::vector<Cell> base;    // keyframes that left the window
  std::vector<Cell> live;    // base + the window's keyframes; what the map shows
  // live cell (col east, row north) within the tile; row 0 is the SOUTH edge here (map-frame indexing)
};

struct OrthoMapStats {
  std::uint64_t keyframes{0};
  std::uint64_t points{0};
  std::uint64_t points_refused{0};  // beyond max_tiles
  std::uint64_t keyframes_moved{0};
  std::uint64_t tiles_rebuilt{0};
  std::uint64_t keyframes_frozen{0};
};

// A north-up raster of the live map (row 0 = north edge), for export and evaluation.
struct MapRaster {
  GridGeometry grid;
  std::vector<std::uint8_t> cls;        // 255 unknown
  std::vector<float> elevation;         // [m] NaN where no point
  std::vector<std::uint8_t> rgb;        // 3 per cell
  std::vector<std::uint32_t> count;     // points per cell
};

class OrthoMap {
 public:
  explicit OrthoMap(const OrthoMapParams& params = {});

  static constexpr std::uint32_t kNoPartner = 0xffffffffU;
  // Bins one keyframe's stereo points (map frame, made with camera pose `map_from_camera`) into the map.
  // `partner`: the keyframe it was matched with, at `baseline_m` between the two cameras (for rescale_depth).
  void add_keyframe(std::uint32_t id, const Eigen::Isometry3d& map_from_camera, std::span<const MapPoint> points,
                    std::uint32_t partner = kNoPartner, double baseline_m = 0.0);

  // New camera poses of keyframes (id, map_from_camera), sorted by id; they may include keyframes without
  // points (stereo partners). Keyframes still in the window that moved beyond the thresholds, or whose
  // depth scale (rescale_depth) changed by as much at their median depth, are re-binned; returns the
  // number of tiles rebuilt.
  std::size_t correct(std::span<const std::pair<std::uint32_t, Eigen::Isometry3d>> poses);

  [[nodiscard]] const Cell* cell_at(double x, double y) const noexcept;
  [[nodiscard]] std::uint64_t version() const noexcept { return version_; }
  [[nodiscard]] std::size_t tile_count() const noexcept { return tiles_.size(); }
  [[nodiscard]] std::uint64_t cells_classified() const noexcept;
  [[nodiscard]] const OrthoMapStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const OrthoMapParams& params() const noexcept { return p_; }
  // Every tile (unordered), for export and for the gossip of changed tiles.
  template <typename F>
  void for_each_tile(F&& f) const {
    for (const auto& [k, t] : tiles_) f(*t);
  }
  // The pose a keyframe in the window was last binned with (nullptr once it left the window).
  [[nodiscard]] const Eigen::Isometry3d* keyframe_pose(std::uint32_t id) const noexcept;
  [[nodiscard]] std::size_t window_size() const noexcept { return window_.size(); }
  // Heap bytes held by the tiles and the window's patches (what grows with the area and the flight).
  [[nodiscard]] std::size_t memory_bytes() const noexcept;

  // North-up raster of the live layers over the mapped extent, or over `grid`.
  [[nodiscard]] MapRaster raster() const;
  [[nodiscard]] MapRaster raster(const GridGeometry& grid) const;

 private:
  struct PatchCell {
    float x, y, z;          // [m] centroid in the keyframe camera's frame
    std::uint32_t count;
    float cos;              // best observation's cosine to the optical axis
    std::uint8_t r, g, b, cls;
  };
  struct Patch {
    std::uint32_t id{0};
    Eigen::Isometry3d pose{Eigen::Isometry3d::Identity()};  // map_from_camera it is binned with
    std::uint32_t partner{kNoPartner};  // its stereo partner
    double baseline_m{0};               // [m] between the two cameras when they were matched
    double depth_scale{1};              // [-] the cells' positions are multiplied by this (rescale_depth)
    float depth_m{0};                   // [m] mean cell depth, to judge a scale change in metres
    std::vector<PatchCell> cells;
    std::vector<std::uint64_t> tiles;  // packed keys of the tiles it touches at `pose`
  };

  Tile* tile_for(std::int64_t cx, std::int64_t cy, bool create);
  void apply(const Patch& patch, bool to_base, const std::unordered_map<std::uint64_t, Tile*>* only);
  void touched_tiles(Patch& patch) const;
  void freeze_oldest();

  OrthoMapParams p_;
  double inv_res_{2.0};
  std::unordered_map<std::uint64_t, std::unique_ptr<Tile>> tiles_;
  std::vector<Patch> window_;  // oldest first
  std::uint64_t version_{0};
  OrthoMapStats stats_;
  // scratch for binning one keyframe
  struct Acc {
    double sx{0}, sy{0}, sz{0};
    std::uint32_t n{0};
    float cos{-2.0F}, cls_cos{-2.0F};
    std::uint8_t r{0}, g{0}, b{0}, cls{255};
  };
  std::vector<Acc> acc_;
  std::vector<std::uint32_t> start_, fill_, order_;
  std::vector<float> heights_;
  std::vector<float> ground_, local_ground_;  // per scratch cell: flat-class median height, and the window's median of those
};

}  // namespace ag::mapping
