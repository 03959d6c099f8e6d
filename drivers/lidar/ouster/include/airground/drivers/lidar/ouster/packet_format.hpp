// Ouster lidar and IMU UDP packets, transcribed from the Ouster Software User Manual (FW 2.x) and the
// SDK's packet_format: byte layouts, sizes, decoders that take raw bytes and never allocate.
//
// LEGACY lidar packet (FW <= 2.1): columns_per_packet column blocks, each
//   [0]  u64 timestamp [ns]  [8] u16 measurement_id  [10] u16 frame_id  [12] u32 encoder_count
//   [16] pixels_per_column x 12 B: u32 word: bits 0-19 range [mm], bits 28-31 flags; u16 reflectivity,
//        u16 signal, u16 NIR, u16 reserved
//   [16 + 12 ppc] u32 block status (0xFFFFFFFF = valid)
// FW 2.2+ profiles share one frame: a 32 B packet header ([0] u16 packet_type = 1, [2] u16 frame_id,
//   [4] u24 init_id, [7] u40 serial, [16] u8 thermal-shutdown countdown, [17] u8 shot-limiting countdown,
//   [18] thermal shutdown, [19] shot limiting, reserved to 31), columns_per_packet column blocks of
//   [0] u64 timestamp [ns] [8] u16 measurement_id [10] u16 status (bit 0 valid) then pixels_per_column
//   pixels, then a 32 B footer (reserved on FW 2.2/2.3, kept as it came). The pixel per profile:
//   RNG19_RFL8_SIG16_NIR16 (12 B): u32 word: bits 0-18 range [mm], bits 19-23 flags; [4] u8 reflectivity,
//     [5] reserved, [6] u16 signal, [8] u16 NIR, [10] u16 reserved
//   RNG19_RFL8_SIG16_NIR16_DUAL (16 B): [0] u32: bits 0-18 range [mm], bits 19-23 flags, bits 24-31
//     reflectivity; [4] u32: the same for the second return; [8] u16 signal, [10] u16 signal of the
//     second return, [12] u16 NIR, [14] u16 reserved
//   RNG15_RFL8_NIR8 (4 B, low data rate): [0] u16: bits 0-14 range in units of 8 mm, bit 15 flag;
//     [2] u8 reflectivity, [3] u8 NIR in units of 16 photons; no signal
// IMU packet (48 B): [0] u64 sys ts, [8] u64 accel ts, [16] u64 gyro ts [ns], [24] 3 x f32 acceleration [g],
//   [36] 3 x f32 angular velocity [deg/s]. All little-endian.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "airground/drivers/lidar/ouster/metadata.hpp"

namespace ag::ouster {

inline constexpr int kMaxColumnsPerPacket = 16;
inline constexpr int kMaxPixelsPerColumn = 128;
inline constexpr std::size_t kImuPacketSize = 48;
inline constexpr std::size_t kMaxPacketSize = 65536;

inline constexpr std::size_t kPacketHeaderSize = 32;  // FW 2.2+ profiles
inline constexpr std::size_t kPacketFooterSize = 32;

// One beam of one column. The second return's fields are written only by the dual profile.
struct Pixel {
  std::uint32_t range_mm{0};   // 0 = no return
  std::uint16_t reflectivity{0};
  std::uint16_t signal{0};     // photons (0 in RNG15_RFL8_NIR8, which has none)
  std::uint16_t nir{0};        // ambient near-infrared photons
  std::uint8_t flags{0};       // the profile's flag bits as sent (legacy 4, RNG19 5, RNG15 1)
  std::uint8_t flags2{0};
  std::uint32_t range2_mm{0};  // second return (dual profile)
  std::uint16_t signal2{0};
  std::uint8_t reflectivity2{0};
};

struct Column {
  std::uint64_t timestamp_ns{0};
  std::uint16_t measurement_id{0};  // column index in the frame, 0..columns-1
  std::uint16_t frame_id{0};
  std::uint32_t encoder_count{0};   // legacy only
  bool valid{false};                // status says valid and measurement_id is in the frame
  std::array<Pixel, kMaxPixelsPerColumn> pixels{};
};

struct LidarPacket {
  std::uint16_t frame_id{0};        // of the packet (FW 2.2+ profiles) or its first valid column (legacy)
  int columns{0};
  // FW 2.2+ profiles: the header after packet_type and frame_id (init_id, serial, thermal and shot
  // limiting; bytes 4..31) and the footer, as they came, so an encoder can write them back.
  std::array<std::uint8_t, kPacketHeaderSize - 4> header{};
  std::array<std::uint8_t, kPacketFooterSize> footer{};
  [[nodiscard]] std::uint32_t init_id() const noexcept { return header[0] | header[1] << 8 | static_cast<std::uint32_t>(header[2]) << 16; }
  [[nodiscard]] std::uint64_t serial() const noexcept {
    std::uint64_t v = 0;
    for (int i = 4; i >= 0; --i) v = v << 8 | header[static_cast<std::size_t>(3 + i)];
    return v;
  }
  std::array<Column, kMaxColumnsPerPacket> column{};
};

struct ImuSample {
  std::uint64_t sys_ts_ns{0}, accel_ts_ns{0}, gyro_ts_ns{0};
  std::array<float, 3> accel_g{};       // [g]
  std::array<float, 3> gyro_deg_s{};    // [deg/s]
};

enum class DecodeStatus : std::uint8_t {
  kOk = 0,
  kWrongSize = 1,       // the datagram is not this profile's packet size
  kBadPacketType = 2,   // a FW 2.2+ header's packet_type is not 1
  kNoValidColumn = 3,   // every column flagged invalid or out of the frame
};
const char* to_string(DecodeStatus s) noexcept;

// The layout a SensorInfo implies.
class PacketFormat {
 public:
  explicit PacketFormat(const SensorInfo& info) noexcept;
  [[nodiscard]] std::size_t lidar_packet_size() const noexcept { return packet_size_; }
  [[nodiscard]] std::size_t column_size() const noexcept { return column_size_; }
  [[nodiscard]] int columns_per_packet() const noexcept { return cols_; }
  [[nodiscard]] int pixels_per_column() const noexcept { return ppc_; }
  [[nodiscard]] int columns_per_frame() const noexcept { return cpf_; }
  [[nodiscard]] UdpProfile profile() const noexcept { return profile_; }
  [[nodiscard]] std::size_t pixel_size() const noexcept { return pixel_size_; }
  [[nodiscard]] std::size_t header_size() const noexcept { return header_; }
  [[nodiscard]] std::size_t column_header_size() const noexcept { return col_header_; }

  // Decodes one lidar datagram; columns flagged invalid (or with measurement_id out of range, counted
  // in `bad_ids`) have valid = false. Never reads beyond `bytes`.
  [[nodiscard]] DecodeStatus decode_lidar(std::span<const std::uint8_t> bytes, LidarPacket& out, int* bad_ids = nullptr) const noexcept;

 private:
  UdpProfile profile_;
  int cols_, ppc_, cpf_;
  std::size_t header_, footer_, col_header_, pixel_size_, column_size_, packet_size_;
};

[[nodiscard]] DecodeStatus decode_imu(std::span<const std::uint8_t> bytes, ImuSample& out) noexcept;

}  // namespace ag::ouster
