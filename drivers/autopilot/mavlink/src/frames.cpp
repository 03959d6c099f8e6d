// FRD/NED to FLU/ENU attitude conversion.
#include "airground/drivers/autopilot/mavlink/frames.hpp"

#include <algorithm>
#include <cmath>

namespace ag::mavlink {

namespace {
constexpr double kPi = 3.14159265358979323846;
}

double wrap_pi(double a) noexcept {
  a = std::remainder(a, 2.0 * kPi);  // [-pi, pi]
  return a <= -kPi ? a + 2.0 * kPi : a;
}

EulerAttitude frd_ned_to_flu_enu(const EulerAttitude& a) noexcept {
  EulerAttitude r;
  r.roll = a.roll;
  r.pitch = -a.pitch;
  r.yaw = wrap_pi(kPi / 2 - a.yaw);
  r.roll_rate = a.roll_rate;
  r.pitch_rate = -a.pitch_rate;
  r.yaw_rate = -a.yaw_rate;
  return r;
}

EulerAttitude euler_from_quaternion(double w, double x, double y, double z) noexcept {
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  EulerAttitude e;
  if (!(n > 0)) return e;
  w /= n;
  x /= n;
  y /= n;
  z /= n;
  e.roll = std::atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
  e.pitch = std::asin(std::clamp(2.0 * (w * y - z * x), -1.0, 1.0));
  e.yaw = std::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
  return e;
}

}  // namespace ag::mavlink
