// From MAVLink's aeronautical frames (body FRD: x forward, y right, z down; world NED) to REP-103
// (body FLU: x forward, y left, z up; world ENU). With R_enu_ned swapping x/y and negating z and
// R_frd_flu = diag(1, -1, -1), the ZYX Euler angles map exactly as
//   roll_flu = roll_frd,  pitch_flu = -pitch_frd,  yaw_enu = pi/2 - yaw_ned (wrapped to (-pi, pi]),
// and the body rates as p_flu = p_frd, q_flu = -q_frd, r_flu = -r_frd.
#pragma once

namespace ag::mavlink {

struct EulerAttitude {
  double roll{0}, pitch{0}, yaw{0};                   // [rad] ZYX
  double roll_rate{0}, pitch_rate{0}, yaw_rate{0};    // [rad/s] about the body axes
};

// Wraps an angle to (-pi, pi].
[[nodiscard]] double wrap_pi(double a) noexcept;
// FRD body in NED (MAVLink ATTITUDE) to FLU body in ENU (AttitudeMsg).
[[nodiscard]] EulerAttitude frd_ned_to_flu_enu(const EulerAttitude& a) noexcept;
// And back (a simulated autopilot's ATTITUDE): the map is its own inverse.
[[nodiscard]] inline EulerAttitude flu_enu_to_frd_ned(const EulerAttitude& a) noexcept { return frd_ned_to_flu_enu(a); }
// ZYX Euler angles of a unit quaternion (w, x, y, z) (normalised first); the rates are left at zero.
[[nodiscard]] EulerAttitude euler_from_quaternion(double w, double x, double y, double z) noexcept;

}  // namespace ag::mavlink
