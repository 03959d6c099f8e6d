// Target mapping (ALGORITHMS.md §5, docs/missions.md): a vehicle detector over the ground robot's labelled
// LiDAR points and an EKF per object.
//   VehicleDetector: the returns labelled vehicle within max_range_m (+6 m so objects near the limit are
//     seen whole; only clusters within max_range_m count), put in the map frame with the
//     robot's pose and the sensor mount, binned into 0.5 m cells of a window around the robot, 8-connected
//     cells clustered; a cluster of at least min_points is a detection at its centroid, with a covariance
//     from the range, the cluster's extent and the robot's own xy covariance.
//   ObjectTracker: a static-position EKF per object (state x, y; a small process noise per second so an
//     object can drift with re-localization); a detection is gated (Mahalanobis^2 < gate_chi2 on the
//     innovation covariance, and within gate_max_m) and fused into the nearest gated object, else it starts
//     a new object. Objects with at least min_detections are shared (ObjectRecord).
// Both allocate in their constructors only.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/messages/geometry.hpp"
#include "airground/messages/messages.hpp"
#include "airground/mission/records.hpp"

namespace ag::mission {

struct DetectorParams {
  std::uint8_t cls{5};
  double max_range_m{40.0};
  double min_range_m{0.5};
  double cell_m{0.5};
  int min_points{15};
  double sigma0_m{0.3};          // measurement sigma at 0 m
  double sigma_per_m{0.01};      // ... growing with range
  std::size_t max_detections{32};
};

struct Detection {
  double x{0}, y{0};                   // [m] map frame
  double cxx{0}, cxy{0}, cyy{0};       // [m^2]
  std::uint32_t points{0};
  double range_m{0};
};

class VehicleDetector {
 public:
  explicit VehicleDetector(const DetectorParams& p);
  // robot_cov: the robot's xy covariance (row-major 3x3 of LocalizationMsg). Returns the detections found.
  std::span<const Detection> detect(std::span<const ScanReturn> points, const Pose3& sensor_in_body, const Pose2& robot,
                                    const std::array<double, 9>& robot_cov) noexcept;

 private:
  DetectorParams p_;
  std::int32_t n_{0};                   // window cells per side
  std::vector<std::uint16_t> count_;    // points per cell
  std::vector<float> sx_, sy_;          // sums of map-frame x, y per cell
  std::vector<std::int32_t> label_, queue_, touched_;
  std::size_t n_touched_{0};
  std::vector<Detection> out_;
  std::size_t n_out_{0};
};

struct TrackerParams {
  double gate_chi2{9.21};          // 99 % for 2 dof
  double gate_max_m{5.0};
  double process_noise_m2_per_s{0.01};
  std::uint16_t min_detections{3};
  std::size_t max_objects{64};
};

struct TrackedObject {
  std::uint32_t id{0};
  double x{0}, y{0};
  double cxx{0}, cxy{0}, cyy{0};
  std::uint16_t detections{0};
  TimeNs last{0};
};

class ObjectTracker {
 public:
  explicit ObjectTracker(const TrackerParams& p);
  // Fuses one detection; returns the object's index, or -1 when it was dropped (capacity, counted).
  int update(const Detection& d, TimeNs now) noexcept;
  [[nodiscard]] std::span<const TrackedObject> objects() const noexcept { return {objs_.data(), n_}; }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_; }
  // The record of object i (index into objects()).
  [[nodiscard]] ObjectRecord record(std::size_t i, std::uint8_t cls = 5) const noexcept;
  [[nodiscard]] bool confirmed(std::size_t i) const noexcept { return objs_[i].detections >= p_.min_detections; }

 private:
  TrackerParams p_;
  std::vector<TrackedObject> objs_;
  std::size_t n_{0};
  std::uint32_t next_id_{1};
  std::uint64_t dropped_{0};
};

}  // namespace ag::mission
