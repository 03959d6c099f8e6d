// Messages between the stages of one robot: plain structs, fixed size (they live in preallocated ring
// slots), units in comments, and two stamps: when the data was sampled and when it was published [ns].
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "airground/messages/geometry.hpp"
#include "airground/platform/time.hpp"

namespace ag {

// Images travel at the size the mapper and the segmentation work at (ASOOM: the 1280x800 camera
// downscaled by 0.5). A camera driver resamples to this before publishing.
inline constexpr int kImageWidth = 640;
inline constexpr int kImageHeight = 400;
inline constexpr std::size_t kImagePixels = static_cast<std::size_t>(kImageWidth) * kImageHeight;

// Ring capacities of the UAV's channels (writer and readers must agree on them).
inline constexpr std::size_t kCameraRing = 4;
inline constexpr std::size_t kVoRing = 64;
inline constexpr std::size_t kGpsRing = 32;
inline constexpr std::size_t kKeyframeRing = 4;

enum class LabelSource : std::uint8_t { kNone = 0, kGroundTruth = 1, kSegmentation = 2 };

// Channel "camera" (ring): one frame of the nadir camera.
struct CameraImageMsg {
  TimeNs stamp{0};      // [ns] exposure time
  TimeNs published{0};  // [ns]
  std::uint32_t seq{0};
  LabelSource labels{LabelSource::kNone};  // whether `cls` holds class ids (else all 255, unknown)
  std::array<std::uint8_t, kImagePixels * 3> rgb{};  // RGB, row-major
  std::array<std::uint8_t, kImagePixels> cls{};      // class id per pixel (config/classes.yaml)
};

// Channel "visual_odometry" (ring): the camera's odometry for one frame.
struct VoMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t segment{0};  // a new value after every tracking loss (new origin, yaw and scale)
  bool tracking{false};      // false: tracking lost, pose is stale and must not be used
  Pose3 pose;                // body pose in the segment's frame [odometry units, rad]; roll/pitch gravity-aligned
};

// Channel "attitude" (ring): the autopilot's attitude estimate (PX4 / ArduPilot EKF, MAVLink ATTITUDE),
// converted from the autopilot's FRD body in NED to REP-103: body FLU in the local ENU frame.
inline constexpr std::size_t kAttitudeRing = 128;
struct AttitudeMsg {
  TimeNs stamp{0};       // [ns] sample time on this computer's clock
  TimeNs published{0};   // [ns]
  double roll{0}, pitch{0}, yaw{0};  // [rad] body FLU in ENU (ZYX: yaw about up, then pitch, then roll)
  double roll_rate{0}, pitch_rate{0}, yaw_rate{0};  // [rad/s] about the body FLU axes
};

// Channel "gps" (ring): one GNSS fix converted to the map frame (local ENU around the mission datum).
struct GpsMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint8_t fix_type{0};   // UBX-NAV-PVT fixType: 0 no fix, 2 2D, 3 3D
  double east_m{0}, north_m{0}, up_m{0};  // [m] map frame
  double h_accuracy_m{0};     // [m] receiver's 1-sigma horizontal accuracy
  double v_accuracy_m{0};     // [m]
};

// Channel "keyframes" (ring): a keyframe chosen by the pose-graph stage for the ortho-mapper.
struct KeyframeMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t id{0};        // keyframe number, from 0
  std::uint32_t segment{0};
  Pose3 body_pose;            // [m, rad] optimised body pose in the map frame when chosen
  LabelSource labels{LabelSource::kNone};
  std::array<std::uint8_t, kImagePixels * 3> rgb{};
  std::array<std::uint8_t, kImagePixels> cls{};
};

// Channel "keyframe_poses" (latest value): the current optimised body poses of the newest keyframes,
// republished after every solve, so the mapper re-bins keyframes the graph moved.
struct KeyframePosesMsg {
  static constexpr std::size_t kCapacity = 512;
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint32_t solve{0};     // solve number that produced them
  std::uint32_t first_id{0};  // id of poses[0]; poses[i] belongs to keyframe first_id + i
  std::uint32_t count{0};
  bool initialised{false};    // the newest frame's segment is georeferenced
  std::uint32_t segment{0};   // newest frame's segment
  double scale{0};            // [m per odometry unit] of that segment
  std::array<Pose3, kCapacity> poses{};
};

// Channel "map_status" (latest value): what the ortho-mapper has built so far.
struct MapStatusMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  std::uint64_t version{0};        // increases with every change to any tile
  std::uint32_t keyframes{0};      // keyframes mapped
  std::uint32_t tiles{0};          // tiles holding data
  std::uint32_t tiles_rebuilt{0};  // total tile rebuilds after pose-graph corrections
  std::uint64_t cells_mapped{0};   // cells with a class
  double scale{0};                 // [m per odometry unit] of the current segment (0 before initialisation)
  bool initialised{false};         // pose graph georeferenced
};

// ------------------------------------------------------------------------------------ map tiles

// The aerial map travels as tiles of kTileCells x kTileCells cells of kMapResolutionM (DESIGN.md §4):
// tile (tx, ty) covers map-frame x in [tx, tx + 1) * kTileCells * kMapResolutionM, likewise y.
inline constexpr int kTileCells = 64;
inline constexpr double kMapResolutionM = 0.5;
inline constexpr std::size_t kTileCellCount = static_cast<std::size_t>(kTileCells) * kTileCells;
inline constexpr std::size_t kMapTileRing = 64;

// Channel "map_tiles" (ring): one changed tile of the aerial map (from the mapper on the quadrotor, from
// gossip on the others). Cells row-major from the SOUTH-west corner (row = north index, col = east index).
struct MapTileMsg {
  TimeNs stamp{0};             // [ns] when the tile last changed
  TimeNs published{0};
  std::int32_t tx{0}, ty{0};   // tile index east, north
  std::uint64_t version{0};    // the tile's version: newer replaces older
  std::array<std::uint8_t, kTileCellCount> cls{};  // class id, 255 unknown
  std::array<float, kTileCellCount> elevation{};   // [m] map frame, NaN where unknown
};

// ------------------------------------------------------------------------------ the ground robot

inline constexpr std::size_t kMaxScanPoints = 64 * 2048;  // Ouster OS-1-64 at its densest mode
inline constexpr std::size_t kLidarRing = 2;
inline constexpr std::size_t kWheelOdometryRing = 128;

// One return of an organised LiDAR scan; pixels without a return are absent.
struct ScanReturn {
  float x{0}, y{0}, z{0};    // [m] sensor frame (x forward, y left, z up)
  float range{0};            // [m]
  std::uint8_t cls{255};     // class id when the driver or a labeller knows it, else 255
  std::uint16_t ring{0};     // beam, 0 = top
  std::uint16_t col{0};      // measurement column
};

// Channel "lidar_scan" (ring): one revolution.
struct LidarScanMsg {
  TimeNs stamp{0};           // [ns] of the revolution (motion within it is not compensated)
  TimeNs published{0};
  std::uint32_t seq{0};
  std::uint16_t rings{0}, columns{0};
  LabelSource labels{LabelSource::kNone};  // whether `cls` is set
  Pose3 sensor_in_body;      // [m, rad] mount of the sensor on the robot
  std::uint32_t count{0};    // valid entries of points
  // Only points[0, count) mean anything, and a copy (one per reader of the ring) moves only those: a
  // 1024-column scan fills under half the array. In an anonymous union so that a copy does not first
  // initialise the whole array (3 MB); ScanReturn is trivially copyable, so memcpy creates the points.
  union {
    std::array<ScanReturn, kMaxScanPoints> points;
  };

  LidarScanMsg() noexcept : points{} {}
  LidarScanMsg(const LidarScanMsg& o) noexcept
      : stamp(o.stamp), published(o.published), seq(o.seq), rings(o.rings), columns(o.columns), labels(o.labels),
        sensor_in_body(o.sensor_in_body), count(o.count) {
    std::memcpy(static_cast<void*>(&points), static_cast<const void*>(&o.points), sizeof(ScanReturn) * valid());
  }
  LidarScanMsg& operator=(const LidarScanMsg& o) noexcept {
    if (this == &o) return *this;
    stamp = o.stamp;
    published = o.published;
    seq = o.seq;
    rings = o.rings;
    columns = o.columns;
    labels = o.labels;
    sensor_in_body = o.sensor_in_body;
    count = o.count;
    std::memcpy(static_cast<void*>(&points), static_cast<const void*>(&o.points), sizeof(ScanReturn) * valid());
    return *this;
  }
  ~LidarScanMsg() = default;
  // The entries a copy carries: count, unless a broken producer claimed more than the array holds (the
  // count travels as it is, for the reader to refuse the scan).
  [[nodiscard]] std::size_t valid() const noexcept { return count < kMaxScanPoints ? count : kMaxScanPoints; }
};
static_assert(std::is_trivially_copyable_v<ScanReturn>);

// Channel "wheel_odometry" (ring): the base's integrated odometry.
struct WheelOdometryMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  Pose2 pose;                // [m, rad] in the odometry frame (fixed at start-up)
  double v_mps{0}, w_radps{0};
  bool moving{false};        // the wheels turned since the previous sample
};

// Channel "initial_pose" (latest value): a guess of the robot's pose in the map frame, from the mission
// file, an operator or a team-mate (like nav2's /initialpose). A new stamp re-initialises the localizer.
struct InitialPoseMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  Pose2 pose;                // [m, rad] map frame
  double sigma_xy_m{16};     // [m] how far off it may be
  double sigma_yaw_rad{0.5};
};

enum class LocalizationStatus : std::uint8_t { kNoMap = 0, kInitialising = 1, kTracking = 2, kLost = 3 };

// Channel "localization" (latest value): the robot's pose in the map frame at 10 Hz.
struct LocalizationMsg {
  TimeNs stamp{0};
  TimeNs published{0};
  LocalizationStatus status{LocalizationStatus::kNoMap};
  Pose2 pose;                // [m, rad] map frame
  std::array<double, 9> covariance{};  // [m^2, m rad, rad^2] x, y, yaw row-major
  double spread_m{0};        // [m] the filter's particle spread
  std::uint32_t particles{0};
  std::uint32_t updates{0};  // filter updates so far
};

}  // namespace ag
