// Time as int64 nanoseconds: every timestamp, period and budget in airground uses this one type.
#pragma once

#include <cstdint>

namespace ag {

using TimeNs = std::int64_t;  // [ns]

inline constexpr TimeNs kNsPerUs = 1'000;
inline constexpr TimeNs kNsPerMs = 1'000'000;
inline constexpr TimeNs kNsPerS = 1'000'000'000;

constexpr TimeNs period_from_hz(double rate_hz) noexcept {
  return static_cast<TimeNs>(static_cast<double>(kNsPerS) / rate_hz + 0.5);
}
constexpr double to_seconds(TimeNs t) noexcept { return static_cast<double>(t) * 1e-9; }
constexpr double to_us(TimeNs t) noexcept { return static_cast<double>(t) * 1e-3; }
constexpr TimeNs from_seconds(double s) noexcept { return static_cast<TimeNs>(s * 1e9); }

}  // namespace ag
