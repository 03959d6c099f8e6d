// Ouster lidar and IMU UDP packets, transcribed from the Ouster Software User Manual (FW 2.x) and the
// SDK's packet_format: byte layouts, sizes, decoders that take raw bytes and never allocate.
//
// LEGACY lidar packet: columns_per_packet column blocks, each
//   [0]  u64 timestamp [ns]  [8] u16 measurement_id  [10] u16 frame_id  [12] u32 encoder_count
//   [16] pixels_per_column x 12 B: u32 range (low 20 bits, mm), u16 reflectivity, u16 signal, u16 NIR, u16 -
//   [16 + 12 ppc] u32 block status (0xFFFFFFFF = valid)
// RNG19_RFL8_SIG16_NIR16: 32 B packet header ([0] u16 packet_type = 1, [2] u16 frame_id, [4] u24 init_id,
//   [7] u40 serial, [16] u8 thermal-shutdown countdown, [17] u8 shot-limiting countdown, [18] thermal
//   shutdown, [19] shot limiting), column blocks of [0] u64 timestamp [8] u16 measurement_id [10] u16 status
//   (bit 0 valid) then 12 B pixels: u32 range (low 19 bits, mm), u8 reflectivity, u8 -, u16 signal, u16 NIR,
//   u16 -; then a 32 B footer.
// IMU packet (48 B): [0] u64 sys ts, [8] u64 accel ts, [16] u64 gyro ts [ns], [24] 3 x f32 acceleration [g],
//   [36] 3 x f32 angular velocity [deg/s]. All little-endian.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "airground/drivers/ouster/metadata.hpp"

namespace ag::ouster {

inline constexpr int kMaxColumnsPerPacket = 16;
inline constexpr int kMaxPixelsPerColumn = 128;
inline constexpr std::size_t kImuPacketSize = 48;
inline constexpr std::size_t kMaxPacketSize = 65536;

struct Pixel {
  std::uint32_t range_mm{0};   // 0 = no return
  std::uint16_t reflectivity{0};
  std::uint16_t signal{0};     // photons
  std::uint16_t nir{0};        // ambient near-infrared photons
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
  std::uint16_t frame_id{0};        // of the packet (RNG19) or its first valid column (legacy)
  int columns{0};
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
  kBadPacketType = 2,   // RNG19 header's packet_type is not 1
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

  // Decodes one lidar datagram; columns flagged invalid (or with measurement_id out of range, counted
  // in `bad_ids`) have valid = false. Never reads beyond `bytes`.
  [[nodiscard]] DecodeStatus decode_lidar(std::span<const std::uint8_t> bytes, LidarPacket& out, int* bad_ids = nullptr) const noexcept;

 private:
  UdpProfile profile_;
  int cols_, ppc_, cpf_;
  std::size_t header_, footer_, col_header_, column_size_, packet_size_;
};

[[nodiscard]] DecodeStatus decode_imu(std::span<const std::uint8_t> bytes, ImuSample& out) noexcept;

}  // namespace ag::ouster
