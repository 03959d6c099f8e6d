// One lidar frame (a full rotation) assembled from column packets. Images are staggered (as measured:
// pixel (row, col) is beam `row` at measurement_id `col`), row-major, sized once at construction.
// The assembler survives lost packets (the frame is emitted incomplete and counted) and reordered
// packets: any order within a frame, and across a frame boundary the first packet of the next frame is
// held back so a packet of the current frame it overtook still lands. A packet of a frame already
// emitted is counted late and dropped.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "airground/drivers/lidar/ouster/packet_format.hpp"

namespace ag::ouster {

struct LidarFrame {
  int width{0}, height{0};
  int columns_expected{0};  // the metadata's column window (width unless the sensor sends a window)
  std::uint16_t frame_id{0};
  int columns_received{0};
  std::vector<std::uint32_t> range_mm;        // height * width, the first (strongest) return
  std::vector<std::uint16_t> reflectivity, signal, nir;
  std::vector<std::uint8_t> flags;            // the profile's flag bits, as sent
  // The second return (dual profile only; empty otherwise), height * width.
  std::vector<std::uint32_t> range2_mm;
  std::vector<std::uint16_t> signal2;
  std::vector<std::uint8_t> reflectivity2, flags2;
  std::vector<std::uint64_t> column_timestamp_ns;  // width
  std::vector<std::uint8_t> column_valid;          // width, 1 = received and valid
  // FW 2.2+ packet header bytes 4..31 and footer of the frame's first packet (the sensor repeats them).
  std::array<std::uint8_t, kPacketHeaderSize - 4> packet_header{};
  std::array<std::uint8_t, kPacketFooterSize> packet_footer{};

  LidarFrame() = default;
  LidarFrame(int w, int h, bool second_return = false);
  void clear() noexcept;  // keeps the storage
  [[nodiscard]] bool has_second_return() const noexcept { return !range2_mm.empty(); }
  [[nodiscard]] bool complete() const noexcept { return columns_received == columns_expected; }
  [[nodiscard]] std::size_t index(int row, int col) const noexcept {
    return static_cast<std::size_t>(row) * static_cast<std::size_t>(width) + static_cast<std::size_t>(col);
  }
};

struct AssemblerCounters {
  std::uint64_t packets{0};
  std::uint64_t frames_complete{0};
  std::uint64_t frames_incomplete{0};   // emitted with columns missing (lost packets)
  std::uint64_t columns_invalid{0};     // flagged invalid by the sensor or out of range
  std::uint64_t columns_duplicate{0};   // same measurement_id twice in one frame
  std::uint64_t packets_late{0};        // for a frame already emitted (reordered across frames)
};

class FrameAssembler {
 public:
  explicit FrameAssembler(const SensorInfo& info);
  // Adds one decoded packet; returns the frame it finished (complete, or incomplete because a newer
  // frame began), valid until the next call, or nullptr. Never allocates.
  const LidarFrame* add(const LidarPacket& p) noexcept;
  // The frame in progress, emitted as it is (end of a recording); nullptr when none. Call until nullptr
  // (a held-back packet of the next frame comes out as a frame of its own).
  const LidarFrame* flush() noexcept;
  [[nodiscard]] const AssemblerCounters& counters() const noexcept { return c_; }

 private:
  void emit() noexcept;
  void start(std::uint16_t frame_id) noexcept;
  void fill(const LidarPacket& p) noexcept;
  void start_pending() noexcept;
  LidarFrame cur_, done_;
  LidarPacket pending_{};
  bool have_cur_{false}, have_last_{false}, have_pending_{false};
  std::uint16_t last_emitted_{0};
  bool second_return_{false};
  AssemblerCounters c_;
};

// The inverse of decode_lidar, for a simulated sensor (HIL) and the tests: the packet carrying columns
// first_column .. first_column + columns_per_packet - 1 of `f` (stamps from the frame, status valid
// where the frame has the column; legacy encoder counts at 90112 ticks per turn; FW 2.2+ header and
// footer bytes from the frame; RNG15 range rounded to 8 mm and NIR to 16 photons, reflectivity clipped to
// 8 bits). Returns the size, 0 when `out` is too small or the columns are outside the frame.
std::size_t encode_lidar_packet(const PacketFormat& fmt, const LidarFrame& f, int first_column, std::span<std::uint8_t> out) noexcept;
std::size_t encode_imu_packet(const ImuSample& s, std::span<std::uint8_t> out) noexcept;

}  // namespace ag::ouster
