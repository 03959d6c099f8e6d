// Ouster driver against the real OS-1-64 capture (legacy profile, 1024x10, one frame, 11 IMU packets):
// metadata, decoders, frame assembly under loss and reordering, XYZ, pcap/pcapng and the UDP client.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <gtest/gtest.h>
#include <iterator>
#include <random>
#include <vector>

#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/packet_source.hpp"
#include "airground/drivers/lidar/ouster/xyz_lut.hpp"

namespace ag::ouster {
namespace {

const std::string kDir = std::string(AG_TEST_DATA_DIR) + "/ouster/";
const std::string kPcap = kDir + "OS-1-64_1024x10_fw20.pcap";

struct Capture {
  std::vector<std::vector<std::uint8_t>> lidar, imu;
};

Capture load_capture() {
  Capture c;
  auto src = PcapPacketSource::open(kPcap);
  EXPECT_TRUE(src.ok()) << (src.ok() ? "" : src.error().message);
  std::vector<std::uint8_t> buf(kMaxPacketSize);
  for (;;) {
    std::size_t n = 0;
    TimeNs t = 0;
    const PacketKind k = src.value()->next(buf, n, t);
    if (k == PacketKind::kEnd || k == PacketKind::kError) break;
    (k == PacketKind::kLidar ? c.lidar : c.imu).emplace_back(buf.begin(), buf.begin() + static_cast<long>(n));
  }
  return c;
}

SensorInfo reduced_info() {
  auto info = read_metadata_file(kDir + "OS-1-64_sensor_config_reduced.json");
  EXPECT_TRUE(info.ok()) << (info.ok() ? "" : info.error().message);
  return info.value();
}

bool same_frame(const LidarFrame& a, const LidarFrame& b) {
  return a.width == b.width && a.height == b.height && a.frame_id == b.frame_id && a.columns_received == b.columns_received &&
         a.range_mm == b.range_mm && a.reflectivity == b.reflectivity && a.signal == b.signal && a.nir == b.nir &&
         a.column_timestamp_ns == b.column_timestamp_ns && a.column_valid == b.column_valid;
}

TEST(OusterMetadata, LegacyFileHasEverything) {
  auto r = read_metadata_file(kDir + "os1-64_legacy_metadata.json");
  ASSERT_TRUE(r.ok()) << r.error().message;
  const SensorInfo& s = r.value();
  EXPECT_EQ(s.prod_line, "OS-1-64");
  EXPECT_EQ(s.firmware, "v2.1.2");
  EXPECT_EQ(s.mode.columns, 1024);
  EXPECT_EQ(s.mode.frequency_hz, 10);
  EXPECT_EQ(s.profile, UdpProfile::kLegacy);
  ASSERT_EQ(s.beam_altitude_deg.size(), 64u);
  EXPECT_DOUBLE_EQ(s.beam_altitude_deg[0], 16.729);
  EXPECT_DOUBLE_EQ(s.beam_azimuth_deg[0], 3.073);
  EXPECT_DOUBLE_EQ(s.lidar_origin_to_beam_origin_mm, 12.163);
  EXPECT_DOUBLE_EQ(s.beam_to_lidar[3], 12.163);
  EXPECT_DOUBLE_EQ(s.lidar_to_sensor[0], -1.0);
  EXPECT_DOUBLE_EQ(s.lidar_to_sensor[11], 36.18);
  EXPECT_DOUBLE_EQ(s.imu_to_sensor[3], 6.253);
  EXPECT_EQ(s.pixel_shift_by_row.size(), 64u);
  EXPECT_EQ(s.pixel_shift_by_row[0], 19);
  EXPECT_EQ(s.columns_per_packet, 16);
  EXPECT_EQ(s.udp_port_lidar, 7502);
  EXPECT_EQ(s.udp_port_imu, 7503);
}

TEST(OusterMetadata, ReducedConfigTakesOs1Defaults) {
  const SensorInfo s = reduced_info();
  EXPECT_EQ(s.mode.columns, 1024);
  ASSERT_EQ(s.beam_altitude_deg.size(), 64u);
  EXPECT_DOUBLE_EQ(s.beam_altitude_deg[63], -16.75);
  EXPECT_DOUBLE_EQ(s.beam_azimuth_deg[0], 3.12);
  EXPECT_DOUBLE_EQ(s.lidar_origin_to_beam_origin_mm, kDefaultOs1BeamOriginMm);
  EXPECT_DOUBLE_EQ(s.lidar_to_sensor[11], 36.18);
  EXPECT_EQ(s.pixels_per_column, 64);
}

TEST(OusterMetadata, NestedFirmware22LayoutAndProfile) {
  std::string alt = "[", az = "[";
  for (int i = 0; i < 16; ++i) {
    alt += std::to_string(10 - i) + (i < 15 ? "," : "]");
    az += std::string("0") + (i < 15 ? "," : "]");
  }
  const std::string j = R"({"sensor_info": {"prod_line": "OS-0-16", "build_rev": "v2.3.0"},
    "config_params": {"lidar_mode": "512x20", "udp_port_lidar": 7600, "udp_port_imu": 7601, "udp_profile_lidar": "RNG19_RFL8_SIG16_NIR16"},
    "beam_intrinsics": {"beam_altitude_angles": )" + alt + R"(, "beam_azimuth_angles": )" + az +
                        R"(, "lidar_origin_to_beam_origin_mm": 27.67},
    "lidar_data_format": {"columns_per_frame": 512, "columns_per_packet": 16, "pixels_per_column": 16, "column_window": [0, 511]}})";
  auto r = parse_metadata(j, "nested.json");
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(r.value().prod_line, "OS-0-16");
  EXPECT_EQ(r.value().profile, UdpProfile::kRng19Rfl8Sig16Nir16);
  EXPECT_EQ(r.value().mode.columns, 512);
  EXPECT_EQ(r.value().mode.frequency_hz, 20);
  EXPECT_EQ(r.value().udp_port_lidar, 7600);
  EXPECT_DOUBLE_EQ(r.value().beam_to_lidar[3], 27.67);
  EXPECT_EQ(PacketFormat(r.value()).lidar_packet_size(), 32u + 16u * (12u + 16u * 12u) + 32u);
}

TEST(OusterMetadata, BadFilesNameFileAndKey) {
  auto a = parse_metadata("{\"lidar_mode\": ", "trunc.json");
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.error().message.find("trunc.json"), std::string::npos);
  auto b = parse_metadata(R"({"lidar_mode": "1000x10", "beam_altitude_angles": [1], "beam_azimuth_angles": [1]})", "m.json");
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().message.find("1000x10"), std::string::npos);
  auto c = parse_metadata(R"({"lidar_mode": "1024x10", "beam_altitude_angles": [1, 2], "beam_azimuth_angles": [1]})", "c.json");
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().message.find("beam_azimuth_angles"), std::string::npos);
  auto d = parse_metadata(R"({"lidar_mode": "1024x10", "beam_altitude_angles": ["x"], "beam_azimuth_angles": [1]})", "d.json");
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.error().message.find("beam_altitude_angles[0]"), std::string::npos);
  auto e = parse_metadata(R"({"lidar_mode": "1024x10", "udp_profile_lidar": "FUSA_RNG15", "beam_altitude_angles": [1], "beam_azimuth_angles": [1]})", "e.json");
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("FUSA_RNG15"), std::string::npos);
}

TEST(OusterCapture, OneCompleteFrameWithIndoorXyz) {
  const Capture cap = load_capture();
  ASSERT_EQ(cap.lidar.size(), 64u);
  ASSERT_EQ(cap.imu.size(), 11u);
  const SensorInfo info = reduced_info();
  const PacketFormat fmt(info);
  ASSERT_EQ(fmt.lidar_packet_size(), 12608u);
  FrameAssembler asm_(info);
  LidarPacket pkt;
  int frames = 0;
  LidarFrame got;
  for (const auto& p : cap.lidar) {
    ASSERT_EQ(fmt.decode_lidar(p, pkt), DecodeStatus::kOk);
    if (const LidarFrame* f = asm_.add(pkt)) {
      ++frames;
      got = *f;
    }
  }
  EXPECT_EQ(asm_.flush(), nullptr);
  ASSERT_EQ(frames, 1);
  EXPECT_TRUE(got.complete());
  EXPECT_EQ(got.frame_id, 189);
  EXPECT_EQ(got.width, 1024);
  EXPECT_EQ(got.height, 64);
  EXPECT_EQ(asm_.counters().frames_complete, 1u);
  EXPECT_EQ(asm_.counters().frames_incomplete, 0u);
  // Column stamps rise by ~1/(10 Hz * 1024) = 97.7 us.
  const double dt = static_cast<double>(got.column_timestamp_ns[1023] - got.column_timestamp_ns[0]) / 1023.0;
  EXPECT_NEAR(dt, 97'656.0, 2'000.0);

  const XyzLut lut(info);
  std::vector<float> xyz(3 * 1024 * 64);
  lut.cartesian(got, xyz.data());
  std::vector<float> z, rng;
  std::size_t returns = 0;
  for (std::size_t k = 0; k < got.range_mm.size(); ++k) {
    if (got.range_mm[k] == 0) {
      EXPECT_TRUE(std::isnan(xyz[3 * k]));
      continue;
    }
    ++returns;
    z.push_back(xyz[3 * k + 2]);
    rng.push_back(std::hypot(xyz[3 * k], xyz[3 * k + 1], xyz[3 * k + 2] - 0.03618f));
  }
  std::sort(z.begin(), z.end());
  std::sort(rng.begin(), rng.end());
  const auto pct = [](const std::vector<float>& v, double q) { return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))]; };
  std::printf("returns %zu of %zu; z p5 %.2f p50 %.2f p95 %.2f m; range p50 %.2f p95 %.2f m\n", returns, got.range_mm.size(),
              static_cast<double>(pct(z, 0.05)), static_cast<double>(pct(z, 0.5)), static_cast<double>(pct(z, 0.95)),
              static_cast<double>(pct(rng, 0.5)), static_cast<double>(pct(rng, 0.95)));
  EXPECT_EQ(returns, 16749u);  // counted by an independent decode of the capture (Python struct)
  EXPECT_GT(pct(z, 0.05), -5.0f);
  EXPECT_LT(pct(z, 0.95), 5.0f);
  EXPECT_LT(pct(z, 0.05), pct(z, 0.95) - 0.5f);  // a real scene, not a plane through the sensor
  EXPECT_GT(pct(rng, 0.5), 0.5f);
  EXPECT_LT(pct(rng, 0.5), 30.0f);
}

TEST(OusterCapture, ImuPacketsDecode) {
  const Capture cap = load_capture();
  ASSERT_EQ(cap.imu.size(), 11u);
  std::uint64_t last = 0;
  for (const auto& p : cap.imu) {
    ImuSample s;
    ASSERT_EQ(decode_imu(p, s), DecodeStatus::kOk);
    const double g = std::sqrt(static_cast<double>(s.accel_g[0] * s.accel_g[0] + s.accel_g[1] * s.accel_g[1] + s.accel_g[2] * s.accel_g[2]));
    EXPECT_NEAR(g, 1.0, 0.1) << "a sensor at rest measures 1 g";
    for (float w : s.gyro_deg_s) EXPECT_LT(std::abs(w), 5.0f);
    EXPECT_GT(s.sys_ts_ns, last);
    last = s.sys_ts_ns;
  }
  ImuSample s;
  EXPECT_EQ(decode_imu(std::span(cap.imu[0]).first(47), s), DecodeStatus::kWrongSize);
}

TEST(OusterXyz, DirectionsFollowTheManual) {
  SensorInfo s;
  s.mode = {1024, 10};
  s.pixels_per_column = 1;
  s.beam_altitude_deg = {0.0};
  s.beam_azimuth_deg = {0.0};
  s.beam_to_lidar = kIdentity4;
  s.lidar_to_sensor = kIdentity4;
  const XyzLut lut(s);
  LidarFrame f(1024, 1);
  f.range_mm[0] = 2000;    // measurement id 0: +x
  f.range_mm[256] = 1000;  // a quarter turn later: -y (the encoder angle falls with measurement id)
  std::vector<float> xyz(3 * 1024);
  lut.cartesian(f, xyz.data());
  EXPECT_NEAR(xyz[0], 2.0f, 1e-5f);
  EXPECT_NEAR(xyz[1], 0.0f, 1e-5f);
  EXPECT_NEAR(xyz[3 * 256], 0.0f, 1e-5f);
  EXPECT_NEAR(xyz[3 * 256 + 1], -1.0f, 1e-5f);
  // Beam origin 10 mm out, 45 deg up, transform 180 deg about z + 100 mm up.
  s.beam_altitude_deg = {45.0};
  s.beam_to_lidar[3] = 10.0;
  s.lidar_to_sensor = kDefaultLidarToSensor;
  s.lidar_to_sensor[11] = 100.0;
  const XyzLut lut2(s);
  lut2.cartesian(f, xyz.data());
  const double c = std::cos(M_PI / 4);
  EXPECT_NEAR(xyz[0], -((2000.0 - 10.0) * c + 10.0) * 1e-3, 1e-5);
  EXPECT_NEAR(xyz[2], ((2000.0 - 10.0) * c + 100.0) * 1e-3, 1e-5);
}

TEST(OusterAssembly, ReorderedPacketsGiveTheSameFrame) {
  const Capture cap = load_capture();
  const SensorInfo info = reduced_info();
  const PacketFormat fmt(info);
  LidarPacket pkt;
  FrameAssembler in_order(info), shuffled(info);
  LidarFrame ref;
  for (const auto& p : cap.lidar) {
    ASSERT_EQ(fmt.decode_lidar(p, pkt), DecodeStatus::kOk);
    if (auto* f = in_order.add(pkt)) ref = *f;
  }
  auto order = cap.lidar;
  std::mt19937 rng(7);
  std::shuffle(order.begin(), order.end(), rng);
  const LidarFrame* got = nullptr;
  for (const auto& p : order) {
    ASSERT_EQ(fmt.decode_lidar(p, pkt), DecodeStatus::kOk);
    if (auto* f = shuffled.add(pkt)) got = f;
  }
  ASSERT_NE(got, nullptr);
  EXPECT_TRUE(same_frame(*got, ref));
}

TEST(OusterAssembly, LostPacketsMakeAnIncompleteFrameThatIsCounted) {
  const Capture cap = load_capture();
  const SensorInfo info = reduced_info();
  const PacketFormat fmt(info);
  LidarPacket pkt;
  FrameAssembler a(info);
  for (std::size_t i = 0; i < cap.lidar.size(); ++i) {
    if (i == 5 || i == 40) continue;  // lost
    ASSERT_EQ(fmt.decode_lidar(cap.lidar[i], pkt), DecodeStatus::kOk);
    EXPECT_EQ(a.add(pkt), nullptr);
  }
  // The next frame's first packet is held back (it may have overtaken one of this frame's); its second
  // closes this frame.
  auto next_a = cap.lidar[0], next_b = cap.lidar[1];
  for (int c = 0; c < 16; ++c) next_a[static_cast<std::size_t>(c) * 788 + 10] = next_b[static_cast<std::size_t>(c) * 788 + 10] = 190;
  ASSERT_EQ(fmt.decode_lidar(next_a, pkt), DecodeStatus::kOk);
  EXPECT_EQ(a.add(pkt), nullptr);
  ASSERT_EQ(fmt.decode_lidar(next_b, pkt), DecodeStatus::kOk);
  const LidarFrame* f = a.add(pkt);
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(f->frame_id, 189);
  EXPECT_FALSE(f->complete());
  EXPECT_EQ(f->columns_received, 1024 - 32);
  EXPECT_EQ(f->column_valid[5 * 16], 0);
  EXPECT_EQ(f->column_valid[6 * 16], 1);
  EXPECT_EQ(a.counters().frames_incomplete, 1u);
  // A straggler of frame 189 is late now.
  ASSERT_EQ(fmt.decode_lidar(cap.lidar[5], pkt), DecodeStatus::kOk);
  EXPECT_EQ(a.add(pkt), nullptr);
  EXPECT_EQ(a.counters().packets_late, 1u);
  // A duplicate is counted, the frame in progress is 190.
  ASSERT_EQ(fmt.decode_lidar(next_a, pkt), DecodeStatus::kOk);
  EXPECT_EQ(a.add(pkt), nullptr);
  EXPECT_EQ(a.counters().columns_duplicate, 16u);
  const LidarFrame* g = a.flush();
  ASSERT_NE(g, nullptr);
  EXPECT_EQ(g->frame_id, 190);
  EXPECT_EQ(g->columns_received, 32);
  EXPECT_EQ(a.flush(), nullptr);
}

TEST(OusterAssembly, APacketOvertakenAcrossTheFrameBoundaryStillLands) {
  const Capture cap = load_capture();
  const SensorInfo info = reduced_info();
  const PacketFormat fmt(info);
  LidarPacket pkt;
  FrameAssembler a(info);
  auto next = cap.lidar;  // the same scene as frame 190
  for (auto& p : next)
    for (int c = 0; c < 16; ++c) p[static_cast<std::size_t>(c) * 788 + 10] = 190;
  std::vector<const std::vector<std::uint8_t>*> order;
  for (std::size_t i = 0; i + 1 < cap.lidar.size(); ++i) order.push_back(&cap.lidar[i]);
  order.push_back(&next[0]);          // 190's first packet overtakes
  order.push_back(&cap.lidar.back()); // 189's last
  for (std::size_t i = 1; i < next.size(); ++i) order.push_back(&next[i]);
  std::vector<std::uint16_t> complete;
  for (const auto* p : order) {
    ASSERT_EQ(fmt.decode_lidar(*p, pkt), DecodeStatus::kOk);
    if (const LidarFrame* f = a.add(pkt)) {
      EXPECT_TRUE(f->complete()) << f->frame_id;
      complete.push_back(f->frame_id);
    }
  }
  EXPECT_EQ(complete, (std::vector<std::uint16_t>{189, 190}));
  EXPECT_EQ(a.counters().frames_incomplete, 0u);
  EXPECT_EQ(a.flush(), nullptr);
}

TEST(OusterPacket, CorruptPacketsAreRefused) {
  const Capture cap = load_capture();
  const PacketFormat fmt(reduced_info());
  LidarPacket pkt;
  EXPECT_EQ(fmt.decode_lidar(std::span(cap.lidar[0]).first(12607), pkt), DecodeStatus::kWrongSize);
  auto bad = cap.lidar[0];
  for (int c = 0; c < 16; ++c) std::memset(bad.data() + c * 788 + 784, 0, 4);  // every block status invalid
  EXPECT_EQ(fmt.decode_lidar(bad, pkt), DecodeStatus::kNoValidColumn);
  auto out_of_range = cap.lidar[0];
  out_of_range[8] = 0xFF;
  out_of_range[9] = 0x7F;  // measurement id 32767
  int bad_ids = 0;
  EXPECT_EQ(fmt.decode_lidar(out_of_range, pkt, &bad_ids), DecodeStatus::kOk);
  EXPECT_EQ(bad_ids, 1);
  EXPECT_FALSE(pkt.column[0].valid);
}

// Writes legacy columns as an RNG19_RFL8_SIG16_NIR16 packet (the layout of packet_format.hpp).
std::vector<std::uint8_t> to_rng19(const LidarPacket& p, std::uint16_t frame_id) {
  std::vector<std::uint8_t> out(32 + 16 * (12 + 64 * 12) + 32, 0);
  const std::uint16_t type = 1;
  std::memcpy(out.data(), &type, 2);
  std::memcpy(out.data() + 2, &frame_id, 2);
  for (int c = 0; c < 16; ++c) {
    std::uint8_t* col = out.data() + 32 + c * 780;
    const Column& s = p.column[static_cast<std::size_t>(c)];
    std::memcpy(col, &s.timestamp_ns, 8);
    std::memcpy(col + 8, &s.measurement_id, 2);
    const std::uint16_t status = 1;
    std::memcpy(col + 10, &status, 2);
    for (int r = 0; r < 64; ++r) {
      std::uint8_t* px = col + 12 + r * 12;
      const Pixel& q = s.pixels[static_cast<std::size_t>(r)];
      const std::uint32_t range = q.range_mm | 0xFFF80000u;  // upper bits are other fields: must be masked off
      std::memcpy(px, &range, 4);
      px[4] = static_cast<std::uint8_t>(std::min<int>(q.reflectivity, 255));
      px[5] = 0xAA;
      std::memcpy(px + 6, &q.signal, 2);
      std::memcpy(px + 8, &q.nir, 2);
    }
  }
  return out;
}

TEST(OusterPacket, Rng19ProfileDecodes) {
  const Capture cap = load_capture();
  SensorInfo legacy = reduced_info();
  SensorInfo rng19 = legacy;
  rng19.profile = UdpProfile::kRng19Rfl8Sig16Nir16;
  const PacketFormat fl(legacy), fr(rng19);
  EXPECT_EQ(fr.lidar_packet_size(), 12544u);
  LidarPacket a, b;
  ASSERT_EQ(fl.decode_lidar(cap.lidar[10], a), DecodeStatus::kOk);
  auto bytes = to_rng19(a, 4242);
  ASSERT_EQ(fr.decode_lidar(bytes, b), DecodeStatus::kOk);
  EXPECT_EQ(b.frame_id, 4242);
  int compared = 0;
  for (int c = 0; c < 16; ++c) {
    const auto& x = a.column[static_cast<std::size_t>(c)];
    const auto& y = b.column[static_cast<std::size_t>(c)];
    EXPECT_EQ(y.measurement_id, x.measurement_id);
    EXPECT_EQ(y.timestamp_ns, x.timestamp_ns);
    EXPECT_TRUE(y.valid);
    for (int r = 0; r < 64; ++r) {
      const auto& p = x.pixels[static_cast<std::size_t>(r)];
      const auto& q = y.pixels[static_cast<std::size_t>(r)];
      if (p.range_mm >= (1u << 19)) continue;
      EXPECT_EQ(q.range_mm, p.range_mm);
      EXPECT_EQ(q.reflectivity, std::min<int>(p.reflectivity, 255));
      EXPECT_EQ(q.signal, p.signal);
      EXPECT_EQ(q.nir, p.nir);
      ++compared;
    }
  }
  EXPECT_GT(compared, 500);
  bytes[0] = 2;  // not a lidar packet type
  EXPECT_EQ(fr.decode_lidar(bytes, b), DecodeStatus::kBadPacketType);
}

TEST(OusterPacket, EncoderWritesTheSensorsBytes) {
  const Capture cap = load_capture();
  const SensorInfo info = reduced_info();
  const PacketFormat fmt(info);
  FrameAssembler a(info);
  LidarPacket pkt;
  LidarFrame frame;
  for (const auto& p : cap.lidar) {
    ASSERT_EQ(fmt.decode_lidar(p, pkt), DecodeStatus::kOk);
    if (auto* f = a.add(pkt)) frame = *f;
  }
  std::vector<std::uint8_t> out(fmt.lidar_packet_size());
  std::size_t differing = 0;
  for (const auto& p : cap.lidar) {
    std::uint16_t first;
    std::memcpy(&first, p.data() + 8, 2);
    ASSERT_EQ(encode_lidar_packet(fmt, frame, first, out), out.size());
    // Byte for byte, the range word's flag bits 28-31 included (this firmware sets bit 31 on many pixels).
    for (std::size_t i = 0; i < out.size(); ++i) differing += out[i] != p[i];
  }
  EXPECT_EQ(differing, 0u) << "bytes that differ from the real sensor's packets";
  for (const auto& p : cap.imu) {
    ImuSample s;
    ASSERT_EQ(decode_imu(p, s), DecodeStatus::kOk);
    std::uint8_t b[48];
    ASSERT_EQ(encode_imu_packet(s, b), 48u);
    EXPECT_EQ(0, std::memcmp(b, p.data(), 48));
  }
  // RNG19: encode the frame, decode it, same images (reflectivity clipped to 8 bits, range to 19).
  SensorInfo r19 = info;
  r19.profile = UdpProfile::kRng19Rfl8Sig16Nir16;
  const PacketFormat f19(r19);
  FrameAssembler b(r19);
  std::vector<std::uint8_t> o19(f19.lidar_packet_size());
  const LidarFrame* got = nullptr;
  for (int c = 0; c < 1024; c += 16) {
    ASSERT_EQ(encode_lidar_packet(f19, frame, c, o19), o19.size());
    ASSERT_EQ(f19.decode_lidar(o19, pkt), DecodeStatus::kOk);
    if (auto* f = b.add(pkt)) got = f;
  }
  ASSERT_NE(got, nullptr);
  ASSERT_TRUE(got->complete());
  for (std::size_t k = 0; k < frame.range_mm.size(); ++k) {
    ASSERT_EQ(got->range_mm[k], frame.range_mm[k] & 0x7FFFFu);
    ASSERT_EQ(got->reflectivity[k], std::min<std::uint16_t>(frame.reflectivity[k], 255));
    ASSERT_EQ(got->signal[k], frame.signal[k]);
  }
  EXPECT_EQ(encode_lidar_packet(fmt, frame, 1020, out), 0u);  // beyond the frame
}

std::vector<std::uint8_t> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void put32(std::vector<std::uint8_t>& v, std::uint32_t x) {
  for (int i = 0; i < 4; ++i) v.push_back(static_cast<std::uint8_t>(x >> (8 * i)));
}

TEST(OusterPcap, PcapngAndClassicYieldTheSameDatagrams) {
  const auto classic = file_bytes(kPcap);
  // Convert: SHB, one IDB (Ethernet, nanosecond resolution), one EPB per record.
  std::vector<std::uint8_t> ng;
  put32(ng, 0x0A0D0D0A); put32(ng, 28); put32(ng, 0x1A2B3C4D); put32(ng, 1); put32(ng, 0xFFFFFFFF); put32(ng, 0xFFFFFFFF); put32(ng, 28);
  put32(ng, 1); put32(ng, 32); put32(ng, 1); put32(ng, 0);  // linktype 1, reserved, snaplen 0
  put32(ng, 0x00010009); put32(ng, 9); put32(ng, 0);        // if_tsresol = 10^-9, opt_endofopt
  put32(ng, 32);
  for (std::size_t pos = 24; pos + 16 <= classic.size();) {
    std::uint32_t sec, usec, incl;
    std::memcpy(&sec, &classic[pos], 4);
    std::memcpy(&usec, &classic[pos + 4], 4);
    std::memcpy(&incl, &classic[pos + 8], 4);
    const std::uint64_t ts = std::uint64_t{sec} * 1'000'000'000ull + std::uint64_t{usec} * 1000ull;
    const std::uint32_t padded = (incl + 3u) & ~3u, len = 32 + padded;
    put32(ng, 6); put32(ng, len); put32(ng, 0); put32(ng, static_cast<std::uint32_t>(ts >> 32)); put32(ng, static_cast<std::uint32_t>(ts));
    put32(ng, incl); put32(ng, incl);
    ng.insert(ng.end(), classic.begin() + static_cast<long>(pos + 16), classic.begin() + static_cast<long>(pos + 16 + incl));
    for (std::uint32_t k = incl; k < padded; ++k) ng.push_back(0);
    put32(ng, len);
    pos += 16 + incl;
  }
  auto a = PcapReader::from_bytes(classic, "classic");
  auto b = PcapReader::from_bytes(ng, "ng");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(b.value().pcapng());
  UdpDatagram x, y;
  int n = 0;
  while (a.value().next(x)) {
    ASSERT_TRUE(b.value().next(y));
    EXPECT_EQ(x.stamp, y.stamp);
    EXPECT_EQ(x.dst_port, y.dst_port);
    ASSERT_EQ(x.payload.size(), y.payload.size());
    EXPECT_EQ(0, std::memcmp(x.payload.data(), y.payload.data(), x.payload.size()));
    ++n;
  }
  EXPECT_FALSE(b.value().next(y));
  EXPECT_EQ(n, 75);
  EXPECT_TRUE(a.value().error().empty());
}

TEST(OusterPcap, TruncatedAndForeignFilesAreReported) {
  auto bytes = file_bytes(kPcap);
  ASSERT_GT(bytes.size(), 100u);
  bytes.erase(bytes.end() - 100, bytes.end());
  auto r = PcapReader::from_bytes(bytes, "cut.pcap");
  ASSERT_TRUE(r.ok());
  UdpDatagram d;
  int n = 0;
  while (r.value().next(d)) ++n;
  EXPECT_EQ(n, 74);
  EXPECT_NE(r.value().error().find("cut.pcap"), std::string::npos);
  EXPECT_NE(r.value().error().find("byte"), std::string::npos);
  auto bad = PcapReader::from_bytes(std::vector<std::uint8_t>(64, 0x41), "text.pcap");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("text.pcap"), std::string::npos);
  EXPECT_FALSE(PcapPacketSource::open(kDir + "missing.pcap").ok());
}

TEST(OusterUdp, LoopbackReplayGivesTheSameFrame) {
  const Capture cap = load_capture();
  const SensorInfo info = reduced_info();
  const PacketFormat fmt(info);
  LidarPacket pkt;
  FrameAssembler from_pcap(info), from_udp(info);
  LidarFrame ref;
  for (const auto& p : cap.lidar) {
    ASSERT_EQ(fmt.decode_lidar(p, pkt), DecodeStatus::kOk);
    if (auto* f = from_pcap.add(pkt)) ref = *f;
  }
  UdpSourceConfig cfg;
  cfg.bind_address = "127.0.0.1";
  cfg.lidar_port = 0;
  cfg.imu_port = 0;
  auto src = UdpPacketSource::open(cfg);
  ASSERT_TRUE(src.ok()) << src.error().message;
  UdpPacketSource& client = *src.value();
  const int tx = ::socket(AF_INET, SOCK_DGRAM, 0);
  ASSERT_GE(tx, 0);
  const auto send_to = [&](const std::vector<std::uint8_t>& p, std::uint16_t port) {
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(port);
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    return ::sendto(tx, p.data(), p.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to) == static_cast<ssize_t>(p.size());
  };
  std::vector<std::uint8_t> buf(kMaxPacketSize);
  std::size_t n = 0;
  TimeNs t = 0;
  EXPECT_EQ(client.next(buf, n, t), PacketKind::kNone);
  const LidarFrame* got = nullptr;
  int imu = 0;
  // Interleave as the capture does: two IMU packets among the lidar ones, the rest after.
  std::size_t next_imu = 0;
  for (std::size_t i = 0; i < cap.lidar.size() + cap.imu.size(); ++i) {
    const bool send_imu = next_imu < cap.imu.size() && (i % 7 == 1 || i >= cap.lidar.size() + next_imu);
    ASSERT_TRUE(send_imu ? send_to(cap.imu[next_imu++], client.imu_port()) : send_to(cap.lidar[i - next_imu], client.lidar_port()));
    PacketKind k = PacketKind::kNone;
    for (int tries = 0; tries < 100 && k == PacketKind::kNone; ++tries) {
      client.wait(100 * kNsPerMs);
      k = client.next(buf, n, t);
    }
    ASSERT_NE(k, PacketKind::kNone) << "packet " << i << " did not arrive";
    if (k == PacketKind::kImu) {
      ImuSample s;
      EXPECT_EQ(decode_imu(std::span(buf).first(n), s), DecodeStatus::kOk);
      ++imu;
      continue;
    }
    ASSERT_EQ(k, PacketKind::kLidar);
    ASSERT_EQ(fmt.decode_lidar(std::span(buf).first(n), pkt), DecodeStatus::kOk);
    if (auto* f = from_udp.add(pkt)) got = f;
  }
  ::close(tx);
  EXPECT_EQ(imu, 11);
  EXPECT_EQ(client.counters().lidar, 64u);
  EXPECT_EQ(client.counters().imu, 11u);
  ASSERT_NE(got, nullptr);
  EXPECT_TRUE(got->complete());
  EXPECT_TRUE(same_frame(*got, ref));
}

}  // namespace
}  // namespace ag::ouster
