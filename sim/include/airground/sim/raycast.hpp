// Exact ray casting against the World's 2.5D surface, shared by the simulated camera and LiDAR.
#pragma once

#include <memory>

#include <Eigen/Core>

#include <cstdint>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// The first surface a ray meets. Every cell is a flat-topped column reaching down forever, its top at
// terrain + height, so building sides are vertical faces; a hit on a side face names the column hit.
struct RayHit {
  bool hit{false};
  double range{0};                                  // [m] from the ray origin along the unit direction
  Eigen::Vector3d point{Eigen::Vector3d::Zero()};   // [m] map frame
  std::int32_t col{-1}, row{-1};                    // the cell whose face was hit
  bool vertical_face{false};                        // a column side, not its top
  Eigen::Vector3d normal{Eigen::Vector3d::UnitZ()};  // outward unit face normal, map frame
};

struct RaycastOptions {
  // Max-height pyramid over blocks of 4 to 64 cells: a ray skips any block it passes above.
  // Off = plain cell-by-cell traversal (the reference the pyramid is tested against).
  bool hierarchical{true};
  // A second max pyramid over the surface dilated by one cell (3x3 max, ~1 float per cell) for
  // fan_free_bounds(): one march bounds many nearly parallel rays at once (the LiDAR's fast scan).
  bool fan_bounds{true};
};

// Input of HeightfieldRaycaster::fan_free_bounds: rays from one origin whose horizontal directions lie
// within one cell of lateral distance of a centre line (grid units) over the part that matters.
struct FanBeam {
  double slope;  // [m of z per cell of horizontal travel]: the rays must be sorted by it, ascending
  double bound;  // out: horizontal distance [cells] before which the ray provably meets no surface
  bool blocked;  // out: the bound is where it first dipped under the dilated surface (a hit is near)
};

// Built once per World (copies the surface and builds the pyramid); cast() is const, allocation-free and
// safe to call from many threads. Rays leaving the world's rectangle return no hit; a ray starting
// inside a column hits at range 0.
class HeightfieldRaycaster {
 public:
  // Throws std::invalid_argument when the height/terrain layers do not match the grid or are not finite.
  explicit HeightfieldRaycaster(const World& world, RaycastOptions options = {});

  // unit_dir must have unit length (ranges are measured along it); max_range [m].
  [[nodiscard]] RayHit cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir,
                            double max_range) const noexcept;
  // The same ray, known to meet no surface before range t_start: the traversal starts there. Gives the
  // same hit as cast() (up to rounding of the range) whenever that promise holds. `near`: the hit is
  // expected within a few cells, so the pyramid is not worth testing (plain cell stepping, same hits).
  [[nodiscard]] RayHit cast_from(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir, double max_range,
                                 double t_start, bool near = false) const noexcept;

  // Marches the horizontal centre line origin + s (cu, cv) (grid coordinates: u east, v south, unit
  // length, s in cells) and, for every beam z = origin.z + slope s whose own horizontal line stays within
  // one cell (max norm) of the centre line, sets the distance before which it is above every surface
  // (conservative: the dilated surface). Beams still unbounded at the end get `walked` (everything
  // before was checked) or +inf when they rose above the highest surface. Returns false when the fan
  // cannot be used (no dilated pyramid, origin outside the grid): bounds are then 0.
  bool fan_free_bounds(const Eigen::Vector3d& origin, double cu, double cv, double s_stop, FanBeam* beams, int n,
                       double& walked) const noexcept;
  [[nodiscard]] bool has_fan_bounds() const noexcept { return !dilated_.empty(); }

  [[nodiscard]] const GridGeometry& grid() const noexcept { return grid_; }
  // terrain + height of a cell [m] (no bounds check).
  [[nodiscard]] float surface(std::int32_t col, std::int32_t row) const noexcept {
    return surface_[static_cast<std::size_t>(row) * static_cast<std::size_t>(grid_.width) +
                    static_cast<std::size_t>(col)];
  }
  [[nodiscard]] float max_surface() const noexcept { return max_surface_; }
  // An upper bound on the surface over the cells [c0, c1] x [r0, r1] (clamped to the grid; -inf when
  // empty): exact when read cell by cell, otherwise the max of the pyramid blocks covering the rectangle,
  // the finest level that needs at most ~64 reads.
  [[nodiscard]] float max_surface_in(std::int32_t c0, std::int32_t r0, std::int32_t c1, std::int32_t r1) const noexcept;
  [[nodiscard]] float min_surface() const noexcept { return min_surface_; }

 private:
  struct Level {
    int shift{0};  // block side = 1 << shift cells
    std::int32_t width{0}, height{0};
    std::vector<float> max;  // highest surface in each block, row-major
  };
  static constexpr int kMaxLevels = 5;
  // A ray clipped to the world's box, in grid coordinates (u east, v south, per metre of range).
  struct Ray {
    const Eigen::Vector3d& origin;
    const Eigen::Vector3d& dir;
    double u0, v0, z0, du, dv, dz;
    double idu, idv;  // 1/du, 1/dv; +inf for a zero component
    double t0, t1;    // the part of the ray inside the box
    int axis;       // how it enters: 0 from above or at the origin, 1 across a u face, 2 across a v face
    std::int32_t ci{-1}, cj{-1};  // the cell it starts in when resumed (else found from t0 and axis)
  };
  // kLevels = 0 steps cell by cell; with max_steps > 0 it stops after that many cells with no hit and
  // leaves in `ray` the state to resume from (no hit, stopped = true).
  template <bool kPosU, bool kPosV, int kLevels>
  RayHit traverse(Ray& ray, int max_steps, bool& stopped) const noexcept;
  template <bool kPosU, bool kPosV>
  void fan_walk(double u0, double v0, double z0, double cu, double cv, double s_stop, FanBeam* beams, int n,
                double& walked) const noexcept;
  RayHit cast_impl(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir, double max_range,
                   double t_start, bool near) const noexcept;

  GridGeometry grid_;
  std::vector<float> surface_;  // terrain + height, row-major
  std::vector<Level> levels_;   // finest first
  std::vector<float> dilated_;  // max of surface_ over each cell's 3x3 neighbourhood, row-major
  std::vector<Level> dlevels_;  // max pyramid of dilated_, finest first
  float max_surface_{0};
  float min_surface_{0};
};

// The raycaster a sensor shares with others: `shared` when given (checked to be built for this world's
// grid, else std::invalid_argument naming `who`), otherwise a new one for `world`.
[[nodiscard]] std::shared_ptr<const HeightfieldRaycaster> raycaster_for(const World& world,
                                                                        std::shared_ptr<const HeightfieldRaycaster> shared,
                                                                        const char* who);

// Map-from-frame rotation of a pose (R = Rz(yaw) Ry(pitch) Rx(roll)).
[[nodiscard]] Eigen::Matrix3d rotation_of(const Pose3& pose) noexcept;

}  // namespace ag::sim
