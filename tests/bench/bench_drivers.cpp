// Driver decode costs on the real captures, each against a plain copy of the same bytes in the same
// process (the least any driver must do): Ouster frame (64 packets decoded, assembled, XYZ) against the
// 10 Hz frame period; the u-blox stream parser; cannelloni datagrams; V4L2 pixel conversion at 720p.
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "airground/drivers/can/cannelloni.hpp"
#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/packet_source.hpp"
#include "airground/drivers/lidar/ouster/xyz_lut.hpp"
#include "airground/drivers/gps/ublox/byte_source.hpp"
#include "airground/drivers/gps/ublox/stream_parser.hpp"
#include "airground/drivers/gps/ublox/ubx.hpp"
#include "airground/drivers/camera/v4l2/camera.hpp"
#include "bench_common.hpp"

namespace {
using Clock = std::chrono::steady_clock;

template <typename F>
double best_of(int reps, F&& f) {  // [s] fastest of reps runs
  double best = 1e30;
  for (int i = 0; i < reps; ++i) {
    const auto t0 = Clock::now();
    f();
    best = std::min(best, std::chrono::duration<double>(Clock::now() - t0).count());
  }
  return best;
}

volatile std::uint64_t g_sink = 0;

void copy_ref(const std::vector<std::vector<std::uint8_t>>& in, std::vector<std::uint8_t>& dst) {
  std::size_t o = 0;
  for (const auto& p : in) {
    std::memcpy(dst.data() + o, p.data(), p.size());
    o += p.size();
  }
  g_sink = g_sink + dst[o / 2];
}
}  // namespace

int main() {
  using namespace ag;
  const std::string data = AG_BENCH_DATA_DIR;
  // Ouster.
  auto info = ouster::read_metadata_file(data + "/ouster/OS-1-64_sensor_config_reduced.json");
  auto src = ouster::PcapPacketSource::open(data + "/ouster/OS-1-64_1024x10_fw20.pcap");
  if (!info.ok() || !src.ok()) {
    std::fprintf(stderr, "bench_drivers: fixtures missing under %s\n", data.c_str());
    return 1;
  }
  std::vector<std::vector<std::uint8_t>> lidar;
  std::vector<std::uint8_t> buf(ouster::kMaxPacketSize);
  for (;;) {
    std::size_t n = 0;
    TimeNs t = 0;
    const auto k = src.value()->next(buf, n, t);
    if (k == ouster::PacketKind::kEnd) break;
    if (k == ouster::PacketKind::kLidar) lidar.emplace_back(buf.begin(), buf.begin() + static_cast<long>(n));
  }
  const ouster::PacketFormat fmt(info.value());
  ouster::FrameAssembler assembler(info.value());
  const ouster::XyzLut lut(info.value());
  std::vector<float> xyz(3 * 1024 * 64);
  auto pkt = std::make_unique<ouster::LidarPacket>();
  std::vector<std::uint8_t> flat(lidar.size() * 12608);
  std::uint16_t fid = 0;
  const double t_frame = best_of(20, [&] {
    ++fid;  // a new frame each run
    for (auto& p : lidar) {
      for (int c = 0; c < 16; ++c) std::memcpy(p.data() + c * 788 + 10, &fid, 2);
      (void)fmt.decode_lidar(p, *pkt);
      if (const auto* f = assembler.add(*pkt)) lut.cartesian(*f, xyz.data());
    }
  });
  const double t_copy = best_of(20, [&] { copy_ref(lidar, flat); });
  std::printf("ouster  one 64x1024 frame (decode + assemble + XYZ): %.0f us = %.2f %% of the 100 ms period; copy of its 64 packets %.0f us (ratio %.1f)\n",
              t_frame * 1e6, t_frame / 0.1 * 100, t_copy * 1e6, t_frame / t_copy);

  // Every profile on the same 64x1024 scene: the capture's frame encoded in each profile, then decoded,
  // assembled and converted as above; the cost against LEGACY measured in this run.
  ouster::LidarFrame scene;
  {
    ouster::FrameAssembler a(info.value());
    for (const auto& p : lidar) {
      (void)fmt.decode_lidar(p, *pkt);
      if (const auto* f = a.add(*pkt)) scene = *f;
    }
  }
  std::string profile_json;
  double t_legacy = 0;
  for (ouster::UdpProfile prof : ouster::kSupportedProfiles) {
    ouster::SensorInfo si = info.value();
    si.profile = prof;
    const ouster::PacketFormat pf(si);
    ouster::FrameAssembler pa(si);
    std::vector<std::vector<std::uint8_t>> packets;
    for (int c = 0; c < 1024; c += 16) {
      packets.emplace_back(pf.lidar_packet_size());
      (void)ouster::encode_lidar_packet(pf, scene, c, packets.back());
    }
    const bool legacy = prof == ouster::UdpProfile::kLegacy;
    const double t = best_of(20, [&] {
      ++fid;
      for (auto& p : packets) {
        if (legacy)
          for (int c = 0; c < 16; ++c) std::memcpy(p.data() + static_cast<std::size_t>(c) * pf.column_size() + 10, &fid, 2);
        else std::memcpy(p.data() + 2, &fid, 2);
        (void)pf.decode_lidar(p, *pkt);
        if (const auto* f = pa.add(*pkt)) lut.cartesian(*f, xyz.data());
      }
    });
    if (legacy) t_legacy = t;
    std::printf("ouster  64x1024 frame, %-28s %5zu B packets: %.0f us (%.2fx LEGACY)\n", ouster::to_string(prof), pf.lidar_packet_size(), t * 1e6,
                t / t_legacy);
    profile_json += ",\"ouster_frame_us_" + std::string(ouster::to_string(prof)) + "\":" + std::to_string(t * 1e6);
  }

  // u-blox.
  std::ifstream in(data + "/gps/ublox-zed-f9p-rtk.log", std::ios::binary);
  std::vector<std::uint8_t> log((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::uint8_t> stream;
  for (int i = 0; i < 100; ++i) stream.insert(stream.end(), log.begin(), log.end());
  int fixes = 0;
  const double t_ubx = best_of(5, [&] {
    ublox::StreamParser p;
    std::span<const std::uint8_t> s(stream);
    while (!s.empty()) {
      ublox::StreamMessage m;
      s = s.subspan(p.feed(s, m));
      ublox::NavPvt pvt;
      if (m.kind == ublox::StreamMessage::Kind::kUbx && m.id == ublox::kIdNavPvt) fixes += ublox::decode_nav_pvt(m.payload, pvt);
    }
  });
  std::vector<std::uint8_t> dst(stream.size());
  const double t_ucopy = best_of(5, [&] {
    std::memcpy(dst.data(), stream.data(), stream.size());
    g_sink = g_sink + dst[dst.size() / 2];
  });
  std::printf("ublox   stream parser %.0f MB/s (%zu kB, %d fixes); copy %.0f MB/s (ratio %.1f); a 921600 Bd port delivers 0.09 MB/s\n",
              static_cast<double>(stream.size()) / t_ubx * 1e-6, stream.size() / 1000, fixes / 5,
              static_cast<double>(stream.size()) / t_ucopy * 1e-6, t_ubx / t_ucopy);

  // cannelloni.
  std::vector<can::CanFrame> frames(100);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    frames[i].id = static_cast<std::uint32_t>(i);
    frames[i].dlc = 8;
  }
  std::uint8_t dg[1400];
  const std::size_t dn = can::cannelloni::encode(0, frames, dg);
  std::array<can::cannelloni::WireFrame, 128> out{};
  const int kDg = 20000;
  const double t_can = best_of(5, [&] {
    for (int i = 0; i < kDg; ++i) {
      can::cannelloni::Decoded d;
      (void)can::cannelloni::decode(std::span<const std::uint8_t>(dg, dn), out, d);
      g_sink = g_sink + d.frames;
    }
  });
  std::uint8_t cp[1400];
  const double t_ccopy = best_of(5, [&] {
    for (int i = 0; i < kDg; ++i) {
      std::memcpy(cp, dg, dn);
      g_sink = g_sink + cp[static_cast<std::size_t>(i) % dn];
    }
  });
  std::printf("can     cannelloni decode %.1f M frames/s; copy of the datagrams ratio %.1f (a 1 Mbit/s bus carries ~8,000 frames/s)\n",
              kDg * 100.0 / t_can * 1e-6, t_can / t_ccopy);

  // V4L2 conversion at 1280x720.
  const std::uint32_t w = 1280, h = 720;
  std::vector<std::uint8_t> raw(static_cast<std::size_t>(w) * h * 2), bgr(static_cast<std::size_t>(w) * h * 3);
  for (std::size_t i = 0; i < raw.size(); ++i) raw[i] = static_cast<std::uint8_t>(i * 7);
  v4l2::Frame f;
  f.data = raw;
  f.width = w;
  f.height = h;
  for (auto [fmt_px, stride, name] : {std::tuple{v4l2::PixelFormat::kYuyv, 2 * w, "YUYV"}, std::tuple{v4l2::PixelFormat::kBayerRggb8, w, "RGGB8"}}) {
    f.format = fmt_px;
    f.stride = stride;
    const double t_conv = best_of(5, [&] { v4l2::to_bgr(f, bgr.data()); });
    const double t_vcopy = best_of(5, [&] {
      std::memcpy(bgr.data(), raw.data(), static_cast<std::size_t>(stride) * h);
      g_sink = g_sink + bgr[7];
    });
    std::printf("v4l2    %s 1280x720 to BGR %.2f ms (%.1f %% of a 30 fps period); copy %.2f ms (ratio %.1f)\n", name, t_conv * 1e3,
                t_conv / (1.0 / 30) * 100, t_vcopy * 1e3, t_conv / t_vcopy);
  }
  ag::bench::append_result_line("{\"bench\":\"drivers\",\"ouster_frame_us\":" + std::to_string(t_frame * 1e6) + profile_json +
                                ",\"ublox_mb_s\":" + std::to_string(static_cast<double>(stream.size()) / t_ubx * 1e-6) + "}");
  return 0;
}
