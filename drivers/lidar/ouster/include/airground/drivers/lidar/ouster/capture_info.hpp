// A look at a capture, as `ouster-cli source FILE info` gives its users: the sensor and its profile,
// what the packets decode to (frames complete and incomplete, returns per frame, errors by kind) and the
// first frame, for `airground-sim lidar-info`. Desk-side code: it allocates freely.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/xyz_lut.hpp"
#include "airground/platform/result.hpp"

namespace ag::ouster {

struct CaptureInfo {
  SensorInfo sensor;
  bool have_header{false};          // a FW 2.2+ packet header was seen (serial, init_id below)
  std::uint64_t serial{0};
  std::uint32_t init_id{0};
  std::uint64_t lidar_packets{0}, imu_packets{0}, other_ports{0}, lidar_bytes{0};
  std::uint64_t wrong_size{0}, bad_type{0}, no_valid_column{0}, source_errors{0};
  std::size_t wrong_size_seen{0};   // [B] a refused datagram's size
  AssemblerCounters assembly;
  std::vector<std::uint32_t> returns_per_frame, second_returns_per_frame;  // one per frame, in order
  std::string capture_error;        // the reader stopped at a corrupt record (empty: read to its end)
  LidarFrame first_frame;
  bool have_frame{false};

  [[nodiscard]] std::uint64_t frames() const noexcept { return assembly.frames_complete + assembly.frames_incomplete; }
  [[nodiscard]] std::uint64_t decode_errors() const noexcept { return wrong_size + bad_type + no_valid_column; }
  // Why no frame came out, in words (empty when frames did).
  [[nodiscard]] std::string problem() const;
};

// Reads the metadata and the whole capture; errors (kConfig, kIo, kMalformed) name the file.
Result<CaptureInfo> read_capture_info(const std::string& pcap_path, const std::string& metadata_path);

// The frame destaggered by the metadata's pixel_shift_by_row (as the SDK's destagger): column c of row r
// holds the pixel measured at column (c - shift[r]) mod width; returned as indices into the frame.
std::vector<std::size_t> destagger_index(const SensorInfo& info, int width, int height);

// The frame's returns as an ASCII PLY point cloud (x y z [m] in the sensor frame, range [m], reflectivity).
Status write_ply(const std::string& path, const LidarFrame& f, const XyzLut& lut);

}  // namespace ag::ouster
