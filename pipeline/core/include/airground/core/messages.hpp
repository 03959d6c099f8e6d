// Messages between the stages of one robot: plain structs, fixed size (they live in preallocated ring
// slots), units in comments, and two stamps: when the data was sampled and when it was published [ns].
#pragma once

#include <array>
#include <cstdint>

#include "airground/core/geometry.hpp"
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

}  // namespace ag
