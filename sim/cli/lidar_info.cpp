// airground-sim lidar-info: a look at an Ouster capture with its metadata, as `ouster-cli` gives its
// users (sensor, firmware, profile, mode, packets, frames, returns, errors), and the first frame written
// as range and reflectivity PNGs and a PLY point cloud.
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "airground/drivers/lidar/ouster/capture_info.hpp"

namespace fs = std::filesystem;

namespace {

constexpr const char* kLidarInfoHelp =
    "airground-sim lidar-info --pcap FILE --metadata FILE [--out DIR]\n\n"
    "Decodes an Ouster capture (pcap or pcapng) with the sensor's metadata JSON (any layout: legacy,\n"
    "flat FW 2.x, reduced, nested FW 2.2+/3.x) and prints the sensor, firmware, metadata layout, packet\n"
    "profile, mode, packets (lidar, IMU, other ports), frames (complete / incomplete), returns per frame\n"
    "(both returns for the dual profile) and the decode errors by kind; when no frame comes out, the likely\n"
    "cause. With --out, writes the first frame into DIR (destaggered by the metadata's pixel_shift_by_row):\n"
    "  range.png          8-bit, 0 = no return, 1..255 linear up to the frame's 99th-percentile range\n"
    "  reflectivity.png   8-bit reflectivity (clipped to 255)\n"
    "  cloud.ply          ASCII PLY: x y z [m] in the sensor frame, range [m], reflectivity\n"
    "Exit status: 0 frames decoded, 1 no frame decoded, 2 bad usage or a file that cannot be read.\n";

[[noreturn]] void fail(int code, const std::string& msg) {
  std::fprintf(stderr, "airground-sim lidar-info: %s\n", msg.c_str());
  std::exit(code);
}

cv::Mat image_of(const ag::ouster::LidarFrame& f, const std::vector<std::size_t>& idx, bool range) {
  cv::Mat img(f.height, f.width, CV_8UC1);
  double scale = 1.0;
  if (range) {
    std::vector<std::uint32_t> r;
    for (std::uint32_t v : f.range_mm)
      if (v != 0) r.push_back(v);
    if (!r.empty()) {
      const auto p99 = r.begin() + static_cast<long>(static_cast<double>(r.size() - 1) * 0.99);
      std::nth_element(r.begin(), p99, r.end());
      scale = 254.0 / std::max(1.0, static_cast<double>(*p99));
    }
  }
  for (int row = 0; row < f.height; ++row)
    for (int c = 0; c < f.width; ++c) {
      const std::size_t k = idx[static_cast<std::size_t>(row) * static_cast<std::size_t>(f.width) + static_cast<std::size_t>(c)];
      const double v = range ? (f.range_mm[k] == 0 ? 0.0 : 1.0 + std::min(254.0, static_cast<double>(f.range_mm[k]) * scale))
                             : std::min<double>(255.0, f.reflectivity[k]);
      img.at<std::uint8_t>(row, c) = static_cast<std::uint8_t>(v);
    }
  return img;
}

}  // namespace

int lidar_info_cmd(int argc, char** argv) {
  std::string pcap, metadata, out;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::fputs(kLidarInfoHelp, stdout);
      return 0;
    }
    if (i + 1 >= argc) fail(2, "option " + a + " needs a value (see airground-sim lidar-info --help)");
    const std::string v = argv[++i];
    if (a == "--pcap") pcap = v;
    else if (a == "--metadata") metadata = v;
    else if (a == "--out") out = v;
    else fail(2, "unknown option " + a + " (see airground-sim lidar-info --help)");
  }
  if (pcap.empty() || metadata.empty()) fail(2, "--pcap FILE and --metadata FILE are required (see airground-sim lidar-info --help)");
  auto r = ag::ouster::read_capture_info(pcap, metadata);
  if (!r) fail(2, r.error().message);
  const ag::ouster::CaptureInfo& ci = r.value();
  const ag::ouster::SensorInfo& s = ci.sensor;
  const ag::ouster::PacketFormat fmt(s);
  std::printf("sensor      %s%s%s, firmware %s (metadata: %s layout)\n", s.prod_line.empty() ? "(unnamed)" : s.prod_line.c_str(),
              ci.have_header ? ", serial " : "", ci.have_header ? std::to_string(ci.serial).c_str() : "",
              s.firmware.empty() ? "(unknown)" : s.firmware.c_str(), s.layout.c_str());
  std::printf("profile     %s: %d beams, %d columns per packet, %zu B packets\n", ag::ouster::to_string(s.profile), s.pixels_per_column,
              s.columns_per_packet, fmt.lidar_packet_size());
  std::printf("mode        %dx%d, column window [%d, %d], UDP ports %u/%u\n", s.mode.columns, s.mode.frequency_hz, s.column_window_first,
              s.column_window_last, static_cast<unsigned>(s.udp_port_lidar), static_cast<unsigned>(s.udp_port_imu));
  std::printf("packets     lidar %llu (%llu B), imu %llu, other ports %llu\n", static_cast<unsigned long long>(ci.lidar_packets),
              static_cast<unsigned long long>(ci.lidar_bytes), static_cast<unsigned long long>(ci.imu_packets),
              static_cast<unsigned long long>(ci.other_ports));
  std::printf("frames      %llu (%llu complete, %llu incomplete)\n", static_cast<unsigned long long>(ci.frames()),
              static_cast<unsigned long long>(ci.assembly.frames_complete), static_cast<unsigned long long>(ci.assembly.frames_incomplete));
  const std::size_t pixels = static_cast<std::size_t>(s.mode.columns) * static_cast<std::size_t>(s.pixels_per_column);
  for (std::size_t i = 0; i < ci.returns_per_frame.size() && i < 20; ++i) {
    std::printf("  frame %zu   %u returns of %zu pixels", i, ci.returns_per_frame[i], pixels);
    if (i < ci.second_returns_per_frame.size()) std::printf(", %u second returns", ci.second_returns_per_frame[i]);
    std::printf("\n");
  }
  if (ci.returns_per_frame.size() > 20) std::printf("  ... %zu frames in all\n", ci.returns_per_frame.size());
  std::printf("errors      wrong size %llu, not lidar %llu, no valid column %llu; columns invalid %llu, duplicate %llu; late packets %llu\n",
              static_cast<unsigned long long>(ci.wrong_size), static_cast<unsigned long long>(ci.bad_type),
              static_cast<unsigned long long>(ci.no_valid_column), static_cast<unsigned long long>(ci.assembly.columns_invalid),
              static_cast<unsigned long long>(ci.assembly.columns_duplicate), static_cast<unsigned long long>(ci.assembly.packets_late));
  if (!ci.capture_error.empty()) std::printf("capture     %s\n", ci.capture_error.c_str());
  if (!ci.have_frame) {
    std::fprintf(stderr, "airground-sim lidar-info: no frame decoded: %s\n", ci.problem().c_str());
    return 1;
  }
  if (out.empty()) return 0;
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) fail(2, "cannot create " + out + ": " + ec.message());
  const ag::ouster::LidarFrame& f = ci.first_frame;
  const auto idx = ag::ouster::destagger_index(s, f.width, f.height);
  for (const bool range : {true, false}) {
    const std::string path = (fs::path(out) / (range ? "range.png" : "reflectivity.png")).string();
    if (!cv::imwrite(path, image_of(f, idx, range))) fail(2, "cannot write " + path);
  }
  const ag::ouster::XyzLut lut(s);
  const std::string ply = (fs::path(out) / "cloud.ply").string();
  if (auto st = ag::ouster::write_ply(ply, f, lut); !st) fail(2, st.error().message);
  std::printf("first frame (id %u) written to %s: range.png, reflectivity.png, cloud.ply\n", static_cast<unsigned>(f.frame_id), out.c_str());
  return 0;
}
