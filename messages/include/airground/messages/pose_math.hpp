// Pose3 <-> Eigen, for the algorithms that work in matrices (R = Rz(yaw) * Ry(pitch) * Rx(roll)).
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "airground/messages/geometry.hpp"

namespace ag {

[[nodiscard]] inline Eigen::Matrix3d rotation_matrix(double roll, double pitch, double yaw) noexcept {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

[[nodiscard]] inline Eigen::Isometry3d to_isometry(const Pose3& p) noexcept {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = rotation_matrix(p.roll, p.pitch, p.yaw);
  t.translation() = Eigen::Vector3d(p.x, p.y, p.z);
  return t;
}

// Roll, pitch, yaw of a rotation (pitch in [-pi/2, pi/2]).
[[nodiscard]] inline Pose3 to_pose3(const Eigen::Isometry3d& t) noexcept {
  const Eigen::Matrix3d& r = t.linear();
  Pose3 p;
  p.x = t.translation().x();
  p.y = t.translation().y();
  p.z = t.translation().z();
  p.pitch = std::asin(std::clamp(-r(2, 0), -1.0, 1.0));
  p.roll = std::atan2(r(2, 1), r(2, 2));
  p.yaw = std::atan2(r(1, 0), r(0, 0));
  return p;
}

}  // namespace ag
