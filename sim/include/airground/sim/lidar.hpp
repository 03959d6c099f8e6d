// The simulated Ouster OS-1 LiDAR of the ground robots: real beam intrinsics, ray-cast ranges, seeded noise.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/platform/result.hpp"
#include "airground/sim/raycast.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// Beam intrinsics from an Ouster metadata JSON, with the Ouster SDK's geometry (make_xyz_lut): for
// beam (ring) i and measurement column c of W,
//   encoder  theta_e = 2 pi (1 - c / W),   azimuth theta_a = -azimuth_deg[i],   altitude phi = altitude_deg[i]
//   direction d = (cos(theta_e + theta_a) cos phi, sin(theta_e + theta_a) cos phi, sin phi)   (lidar frame)
//   point     p = (r - |b|) d + b,   beam origin b = (n cos theta_e, n sin theta_e, n_z)
// with n = lidar_origin_to_beam_origin, n_z = beam_origin_z (0 on an OS-1 gen 1), and sensor-frame
// point = lidar_to_sensor * p: the range counts from the lidar origin. Ring 0 is the top beam; column 0
// looks along lidar +x, which is sensor -x (backward) on an OS-1; columns sweep clockwise from above.
struct OusterBeamModel {
  std::vector<double> altitude_deg;  // [deg] per beam, top first
  std::vector<double> azimuth_deg;   // [deg] per beam
  int columns{1024};                 // measurement columns per revolution: 512, 1024 or 2048
  double lidar_origin_to_beam_origin_mm{12.163};
  double beam_origin_z_mm{0.0};  // beam_to_lidar_transform[2][3] of newer sensors
  Eigen::Matrix4d lidar_to_sensor{Eigen::Matrix4d::Identity()};  // translation in [mm], as in the JSON

  [[nodiscard]] int rings() const noexcept { return static_cast<int>(altitude_deg.size()); }

  // Reads beam_altitude_angles and beam_azimuth_angles (top level, or under "beam_intrinsics" in newer
  // metadata), lidar_origin_to_beam_origin_mm or beam_to_lidar_transform, and lidar_to_sensor_transform
  // (under "lidar_intrinsics" in newer metadata). The offsets are optional and default to the OS-1 values
  // (12.163 mm; a half turn about z and 36.18 mm up). Errors (ErrorCode::kMalformed for the content,
  // kIo, kInvalidArgument for columns) name the file and the key.
  static Result<OusterBeamModel> from_metadata_json(const std::string& path, int columns);
  static Result<OusterBeamModel> from_metadata_string(std::string_view json, std::string_view origin, int columns);
  // config/sensors/ouster/os1-64_legacy_metadata.json in the source tree.
  static std::string default_metadata_path();
  static Result<OusterBeamModel> load_default(int columns = 1024);
};

// One return, in the sensor frame of the scan pose.
struct LidarPoint {
  float x, y, z;       // [m] sensor frame (x forward, y left, z up)
  float range;         // [m] Ouster range: from the lidar origin via the beam origin, noise included
  std::uint8_t cls;    // ground-truth class of the surface hit
  std::uint16_t ring;  // beam index, 0 = top
  std::uint16_t col;   // measurement column
};

struct LidarNoise {
  double range_sigma_m{0.03};  // [m] Gaussian range noise
  double min_range_m{0.3};     // [m] returns closer than this are dropped
  double max_range_m{120};     // [m] nothing is seen beyond this
  double dropout_prob{0.0};    // [-] chance that a return is lost
  // Water returns nothing: at the Ouster's 865 nm the surface is specular (the beam glances off) and
  // water absorbs what enters it, so a ground robot's LiDAR sees holes where ponds are (Henley et al.,
  // "Detection and Mapping of Specular Surfaces Using Multibounce Lidar Returns", arXiv:2209.03336;
  // puddle detectors use these holes). true = water returns like ground (the simulator before session 39).
  bool water_returns{false};

  [[nodiscard]] Status check() const;
  // YAML section `lidar_noise:` with the keys above; errors name the file and the key.
  static Result<LidarNoise> load_file(const std::string& path);
  static Result<LidarNoise> load_string(std::string_view yaml, std::string_view origin);
};

// One full revolution, taken instantaneously at a pose (no motion distortion).
class LidarSimulator {
 public:
  // Throws std::invalid_argument for an empty beam model, mismatched angle lists, a column count other
  // than 512/1024/2048, noise that fails check(), or World layers that do not match its grid.
  LidarSimulator(const World& world, const OusterBeamModel& beams, const LidarNoise& noise,
                 std::shared_ptr<const HeightfieldRaycaster> raycaster = nullptr);

  // Replaces `out` with the returns (column by column, top ring first; pixels without a return are
  // absent). Range noise and dropouts come from a counter-based PRNG keyed by (seed, ring, col): the
  // same pose and seed give the same scan. Reuses out's capacity: no allocation after the first call.
  // Beams of about the same horizontal direction (from a few neighbouring columns, whose origins lie
  // millimetres apart) are bounded together by one march of the raycaster (fan_free_bounds), then
  // finished by an exact cast each: the same returns as scan_per_ray().
  void scan(const Pose3& sensor_pose_in_map, std::uint64_t seed, std::vector<LidarPoint>& out) const;
  // The same scan with one full cast per ray: the reference scan() is tested against (and the fallback
  // when the raycaster has no fan pyramid or the sensor is outside the world).
  void scan_per_ray(const Pose3& sensor_pose_in_map, std::uint64_t seed, std::vector<LidarPoint>& out) const;
  // Only the measurement columns [col_begin, col_end) (clamped), replacing `out`: parts of one scan can be
  // simulated in parallel and concatenated in column order to give exactly scan()'s result.
  void scan_columns(const Pose3& sensor_pose_in_map, std::uint64_t seed, int col_begin, int col_end,
                    std::vector<LidarPoint>& out) const;
  void scan_per_ray_columns(const Pose3& sensor_pose_in_map, std::uint64_t seed, int col_begin, int col_end,
                            std::vector<LidarPoint>& out) const;

  [[nodiscard]] const OusterBeamModel& beams() const noexcept { return beams_; }
  [[nodiscard]] const LidarNoise& noise() const noexcept { return noise_; }
  [[nodiscard]] std::size_t rays_per_scan() const noexcept { return ray_dir_.size(); }

 private:
  const World& world_;
  OusterBeamModel beams_;
  LidarNoise noise_;
  std::shared_ptr<const HeightfieldRaycaster> raycaster_;
  double beam_offset_m_{0};  // |b| [m]: the part of every range before the beam origin
  // Per ray (column-major: col * rings + ring), sensor frame: beam origin [m] and unit direction.
  std::vector<Eigen::Vector3d> ray_origin_;
  std::vector<Eigen::Vector3d> ray_dir_;
  // The fast scan's slots: slot k holds ring r of column k + slot_shift_[r], so that all of a slot's
  // beams point about the same way (the OS-1's four beam azimuth offsets cancel to within half a
  // column step). slot_rings_: every ring, ascending altitude.
  std::vector<int> slot_shift_;
  std::vector<int> slot_rings_;
  int shift_min_{0}, shift_max_{0};

  // Appends the return of ring/col for a hit at `hit_range` [m] on cell (cell_col, cell_row), after noise.
  void emit(std::size_t k, double hit_range, std::int32_t cell_col, std::int32_t cell_row, std::uint64_t key,
            std::vector<LidarPoint>& out) const;
};

}  // namespace ag::sim
