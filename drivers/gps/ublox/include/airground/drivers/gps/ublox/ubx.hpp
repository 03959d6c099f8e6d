// UBX protocol (u-blox 9 Interface Description, UBX-18010854): frames are
//   0xB5 0x62 class id length(u16 LE) payload ck_a ck_b
// with the 8-bit Fletcher checksum over class..payload. NAV-PVT (0x01 0x07, 92 bytes) is the fix.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace ag::ublox {

inline constexpr std::uint8_t kSync1 = 0xB5, kSync2 = 0x62;
inline constexpr std::uint8_t kClassNav = 0x01, kIdNavPvt = 0x07;
inline constexpr std::size_t kNavPvtLength = 92;

struct Fletcher8 {
  std::uint8_t a{0}, b{0};
  void add(std::uint8_t x) noexcept {
    a = static_cast<std::uint8_t>(a + x);
    b = static_cast<std::uint8_t>(b + a);
  }
};
// Checksum of class, id, length and payload.
[[nodiscard]] Fletcher8 ubx_checksum(std::uint8_t cls, std::uint8_t id, std::span<const std::uint8_t> payload) noexcept;
// Writes a whole frame into out (8 + payload bytes); returns its size, 0 if out is too small.
std::size_t ubx_encode(std::uint8_t cls, std::uint8_t id, std::span<const std::uint8_t> payload, std::span<std::uint8_t> out) noexcept;

enum class FixType : std::uint8_t { kNone = 0, kDeadReckoning = 1, k2D = 2, k3D = 3, kGnssDeadReckoning = 4, kTimeOnly = 5 };
enum class CarrierSolution : std::uint8_t { kNone = 0, kFloat = 1, kFixed = 2 };

struct NavPvt {
  std::uint32_t itow_ms{0};          // GPS time of week [ms]
  std::uint16_t year{0};
  std::uint8_t month{0}, day{0}, hour{0}, minute{0}, second{0};
  bool valid_date{false}, valid_time{false}, fully_resolved{false};
  std::int32_t nano{0};              // [ns] fraction of the second, may be negative
  std::uint32_t t_acc_ns{0};
  FixType fix_type{FixType::kNone};
  bool gnss_fix_ok{false}, diff_soln{false};
  CarrierSolution carrier{CarrierSolution::kNone};
  std::uint8_t num_sv{0};
  double lat_deg{0}, lon_deg{0};     // [deg] (1e-7 deg resolution)
  std::int32_t lat_e7{0}, lon_e7{0};
  double height_m{0}, hmsl_m{0};     // above the ellipsoid / mean sea level [m]
  double h_acc_m{0}, v_acc_m{0};     // [m]
  double vel_ned_m_s[3]{0, 0, 0};    // [m/s]
  double ground_speed_m_s{0}, heading_motion_deg{0};
  double s_acc_m_s{0}, head_acc_deg{0};
  double pdop{0};
  // As received, so a frame can be written back unchanged (the simulator's receiver, HIL).
  std::uint8_t flags_raw{0}, flags2_raw{0};
  std::uint16_t flags3_raw{0};
  std::int32_t height_mm{0}, hmsl_mm{0}, vel_ned_mm_s[3]{0, 0, 0}, ground_speed_mm_s{0}, heading_motion_e5{0}, head_veh_e5{0};
  std::uint32_t h_acc_mm{0}, v_acc_mm{0}, s_acc_mm_s{0}, head_acc_e5{0};
  std::uint16_t pdop_e2{0};
  std::int16_t mag_dec_e2{0};
  std::uint16_t mag_acc_e2{0};
  std::uint8_t valid_raw{0};
};

// Decodes a NAV-PVT payload; false when it is not 92 bytes or its fix type is out of range.
[[nodiscard]] bool decode_nav_pvt(std::span<const std::uint8_t> payload, NavPvt& out) noexcept;
// The inverse: a 92-byte payload from the integer (as-received) fields; reserved bytes are zero. For a
// simulated receiver, fill the integer fields (the doubles are ignored).
void encode_nav_pvt(const NavPvt& p, std::span<std::uint8_t, kNavPvtLength> out) noexcept;

}  // namespace ag::ublox
