// Regions of interest from the aerial class map (ALGORITHMS.md §5, docs/missions.md): the vehicle cells
// of the live ortho-map, opened (a square of open_radius_cells: noise cells and 1-cell slivers go),
// grouped by the closing's dilation with a disc of merge_distance_m / 2 (so two vehicle blobs whose gap
// is at most the merge distance form one region), and groups with fewer than min_region_cells vehicle
// cells dropped. Each region's goal: among the cells within goal_search_radius_m of the region's
// bounding box that are traversable (classes.yaml, up to max_level), keep min_goal_clearance_m from
// anything blocked, and lie in a reachable traversable component (at least reachable_min_cells cells,
// or the largest one: an enclosed courtyard is not reachable), the one with the largest clearance (capped
// at goal_clearance_cap_m) minus goal_distance_weight x its distance to the region.
//
// Ids are stable: a region whose group overlaps a group of the previous extraction keeps that group's id
// (the largest overlap, each old id used once, larger regions first); a region with no overlap gets a
// new id. The region set's version grows whenever ids, cells or goals change.
//
// The grid is the mission area in whole tiles (row 0 south, as the planner's Roadmap). All memory is
// allocated in the constructor (~26 B per cell); set_tile() and extract() never allocate.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/planning/roadmap.hpp"
#include "airground/platform/distance_transform.hpp"

namespace ag::mission {

inline constexpr std::uint32_t kNoRegionId = 0xFFFFFFFFu;

struct RegionParams {
  double resolution_m{0.5};
  int tile_cells{64};
  std::uint8_t vehicle_class{5};
  int open_radius_cells{1};              // opening square half-size [cells]; 0 = off
  double merge_distance_m{12.0};         // blobs this close (gap) form one region
  int min_region_cells{8};               // fewer vehicle cells (after the opening): dropped (8 = 2 m^2)
  Traversability max_level{Traversability::kRough};
  double goal_search_radius_m{15.0};
  double min_goal_clearance_m{0.6};      // [m] as the planner's min_clearance_m
  double goal_clearance_cap_m{3.0};      // [m] more clearance than this does not count
  double goal_distance_weight{0.05};     // [m of clearance per m of distance] prefers goals near the region
  int reachable_min_cells{1600};         // a traversable component this big is reachable (400 m^2)
  int max_regions{320};
};

struct Region {
  std::uint32_t id{0};
  double cx{0}, cy{0};                   // [m] centroid of its vehicle cells
  double goal_x{0}, goal_y{0};           // [m] goal (valid when goal_valid)
  bool goal_valid{false};
  double goal_clearance_m{0};
  std::uint32_t cells{0};                // vehicle cells
  double x0{0}, y0{0}, x1{0}, y1{0};     // [m] bounding box of its vehicle cells
};

struct RegionStats {
  std::uint64_t extractions{0};
  std::uint64_t tiles_applied{0}, tiles_rejected{0};
  std::uint64_t groups_dropped_small{0};  // last extraction
  std::uint64_t groups_over_capacity{0};  // total: groups beyond max_regions (counted, left out)
  std::uint64_t ids_issued{0};
  std::uint64_t goals_missing{0};         // last extraction: regions without a reachable goal
};

class RegionExtractor {
 public:
  RegionExtractor(const RegionParams& p, const ClassTable& classes, const TileExtent& extent);

  // Copies one tile (tile_cells^2 class ids, row 0 south); false when outside, wrong size or not newer.
  bool set_tile(std::int32_t tx, std::int32_t ty, std::uint64_t version, std::span<const std::uint8_t> cls) noexcept;
  // Direct access for tests and tools (call mark_changed() after writing).
  [[nodiscard]] std::span<std::uint8_t> classes() noexcept { return store_cls_; }
  void mark_changed() noexcept {
    changed_ = true;
    known_ = Box{0, 0, extent_.tiles_x, extent_.tiles_y};
  }
  [[nodiscard]] bool changed() const noexcept { return changed_; }

  // Re-extracts the regions (whether or not anything changed); returns their count.
  std::size_t extract() noexcept;

  [[nodiscard]] std::span<const Region> regions() const noexcept { return {regions_.data(), n_regions_}; }
  [[nodiscard]] std::uint32_t version() const noexcept { return version_; }
  [[nodiscard]] const RegionStats& stats() const noexcept { return stats_; }
  [[nodiscard]] std::int32_t width() const noexcept { return fw_; }
  [[nodiscard]] std::int32_t height() const noexcept { return fh_; }
  [[nodiscard]] double origin_x() const noexcept { return fox_; }
  [[nodiscard]] double origin_y() const noexcept { return foy_; }
  [[nodiscard]] const RegionParams& params() const noexcept { return p_; }
  // Clearance [m] of a cell as of the last extraction (0 when blocked or outside).
  [[nodiscard]] double clearance_at(double x, double y) const noexcept;
  [[nodiscard]] bool reachable_at(double x, double y) const noexcept;
  [[nodiscard]] std::size_t memory_bytes() const noexcept;

 private:
  [[nodiscard]] std::size_t idx(std::int32_t c, std::int32_t r) const noexcept {
    return static_cast<std::size_t>(r) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(c);
  }
  bool cell_of(double x, double y, std::int32_t& c, std::int32_t& r) const noexcept;
  void open_vehicle_mask() noexcept;
  void squared_distance(const std::uint8_t* feature) noexcept;  // dist_ = squared cell distance to nearest feature
  void reachable_components() noexcept;
  std::uint32_t group_components() noexcept;  // labels_ over the dilated mask; returns groups
  void find_goal(Region& r) noexcept;

  RegionParams p_;
  TileExtent extent_;
  // The whole area (storage) and the working window of one extraction: the bounding box of the tiles
  // that ever held data (everything outside is unknown: no vehicles, not traversable, so the result is
  // the same as over the whole area, at the cost of the mapped part only).
  struct Box {
    std::int32_t tx0{0}, ty0{0}, tx1{0}, ty1{0};  // tiles, [tx0, tx1) x [ty0, ty1) relative to the extent
  };
  Box known_{};
  std::int32_t fw_{0}, fh_{0};
  double fox_{0}, foy_{0};
  std::vector<std::uint8_t> store_cls_;
  std::vector<std::uint32_t> store_prev_;
  std::int32_t wc0_{0}, wr0_{0};     // working window's first cell in the storage
  std::int32_t w_{0}, h_{0};         // working window [cells]
  double ox_{0}, oy_{0};             // working window's south-west corner [m]
  std::vector<std::uint8_t> trav_lut_;     // 256: class id -> traversable
  std::vector<std::uint8_t> cls_, veh_, tmp_, reach_;
  std::vector<float> dist_;
  std::vector<std::int32_t> labels_, queue_;
  std::vector<std::uint32_t> prev_id_;
  std::vector<std::uint64_t> tile_version_;
  dt::EnvelopeScratch<double> envelope_;  // the distance transform's row pass (platform/distance_transform.hpp)
  struct Group {
    std::uint32_t cells{0};
    double sx{0}, sy{0};
    std::int32_t c0{0}, r0{0}, c1{0}, r1{0};
    std::uint32_t id{0};
    bool keep{false};
    std::array<std::uint32_t, 4> cand_id{};
    std::array<std::uint32_t, 4> cand_n{};
  };
  std::vector<Group> groups_;
  std::vector<std::uint32_t> order_;
  std::vector<Region> regions_, prev_regions_;
  std::size_t n_regions_{0}, n_prev_{0};
  std::vector<std::uint8_t> id_taken_scratch_;
  std::uint32_t next_id_{1};
  std::uint32_t version_{0};
  bool changed_{false};
  RegionStats stats_;
};

}  // namespace ag::mission
