// The simulated u-blox receiver, shared by the lockstep runner (bytes into the gps stage's `source: sim`)
// and HIL (bytes on a pseudo-terminal to airground-uav): a fix as the UBX NAV-PVT message it sends.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "airground/drivers/gps/ublox/ubx.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/gps.hpp"

namespace ag::sim {

using NavPvtBytes = std::array<std::uint8_t, ublox::kNavPvtLength + 8>;

// The fix as a whole UBX NAV-PVT frame (sync, class, id, length, payload, checksum); returns its length.
std::size_t encode_nav_pvt_message(TimeNs now, const GpsFix& fix, NavPvtBytes& out) noexcept;

}  // namespace ag::sim
