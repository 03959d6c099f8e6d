// libFuzzer target: Ouster packets off the wire. The first byte picks what the rest is:
//   0  a lidar datagram, LEGACY profile (64 beams, 1024 columns), fed on into the frame assembler
//   1  a lidar datagram, RNG19_RFL8_SIG16_NIR16 (32 beams, 512 columns, a size the fuzzer can reach)
//   2  an IMU datagram
//   3  a capture file for the pcap/pcapng reader
//   4  a lidar datagram, RNG15_RFL8_NIR8 (128 beams, 1024 columns: the OS-0-128 capture's)
//   5  a lidar datagram, RNG19_RFL8_SIG16_NIR16_DUAL (32 beams, 1024 columns: the OS-0-32 capture's)
// Every decoded packet is also encoded again and must decode to the same columns.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/pcap_reader.hpp"
#include "airground/drivers/lidar/ouster/xyz_lut.hpp"

namespace {
using namespace ag::ouster;

SensorInfo info(int beams, int columns, UdpProfile p) {
  SensorInfo s;
  s.mode = {columns, 10};
  s.profile = p;
  s.pixels_per_column = beams;
  s.column_window_last = columns - 1;
  for (int i = 0; i < beams; ++i) {
    s.beam_altitude_deg.push_back(16.0 - i);
    s.beam_azimuth_deg.push_back(i % 4 - 1.5);
  }
  s.beam_to_lidar = kIdentity4;
  s.beam_to_lidar[3] = s.lidar_origin_to_beam_origin_mm;
  return s;
}

struct Rig {
  SensorInfo info;
  PacketFormat fmt;
  FrameAssembler assembler;
  XyzLut lut;
  std::vector<float> xyz;
  LidarFrame scratch;  // for the re-encode check
  explicit Rig(SensorInfo s)
      : info(s), fmt(s), assembler(s), lut(s), xyz(3 * static_cast<std::size_t>(s.mode.columns) * s.beam_altitude_deg.size()),
        scratch(s.mode.columns, static_cast<int>(s.beam_altitude_deg.size()), has_second_return(s.profile)) {}
};
// A decoded packet's valid columns, written into a frame and encoded again, decode to the same pixels.
void round_trip(Rig& r, const LidarPacket& p) {
  static LidarPacket again;
  LidarFrame& f = r.scratch;
  const int cols = r.fmt.columns_per_packet();
  const int first = p.column[0].measurement_id;
  if (first + cols > f.width) return;
  for (int c = 0; c < cols; ++c)
    if (!p.column[static_cast<std::size_t>(c)].valid || p.column[static_cast<std::size_t>(c)].measurement_id != first + c) return;
  f.frame_id = p.frame_id;
  f.packet_header = p.header;
  f.packet_footer = p.footer;
  for (int c = 0; c < cols; ++c) {
    const Column& col = p.column[static_cast<std::size_t>(c)];
    f.column_valid[static_cast<std::size_t>(first + c)] = 1;
    f.column_timestamp_ns[static_cast<std::size_t>(first + c)] = col.timestamp_ns;
    for (int row = 0; row < f.height; ++row) {
      const std::size_t k = f.index(row, first + c);
      const Pixel& q = col.pixels[static_cast<std::size_t>(row)];
      f.range_mm[k] = q.range_mm;
      f.reflectivity[k] = q.reflectivity;
      f.signal[k] = q.signal;
      f.nir[k] = q.nir;
      f.flags[k] = q.flags;
      if (f.has_second_return()) {
        f.range2_mm[k] = q.range2_mm;
        f.signal2[k] = q.signal2;
        f.reflectivity2[k] = q.reflectivity2;
        f.flags2[k] = q.flags2;
      }
    }
  }
  std::vector<std::uint8_t> out(r.fmt.lidar_packet_size());
  if (encode_lidar_packet(r.fmt, f, first, out) != out.size()) std::abort();
  if (r.fmt.decode_lidar(out, again) != DecodeStatus::kOk) std::abort();
  for (int c = 0; c < cols; ++c)
    for (int row = 0; row < f.height; ++row) {
      const Pixel& a = p.column[static_cast<std::size_t>(c)].pixels[static_cast<std::size_t>(row)];
      const Pixel& b = again.column[static_cast<std::size_t>(c)].pixels[static_cast<std::size_t>(row)];
      if (a.range_mm != b.range_mm || a.reflectivity != b.reflectivity || a.flags != b.flags || a.nir != b.nir) std::abort();
      // Second-return fields are the dual profile's only (the packet buffers are shared between rigs).
      if (f.has_second_return() && (a.range2_mm != b.range2_mm || a.signal2 != b.signal2 || a.flags2 != b.flags2)) std::abort();
    }
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static Rig legacy(info(64, 1024, UdpProfile::kLegacy));
  static Rig rng19(info(32, 512, UdpProfile::kRng19Rfl8Sig16Nir16));
  static Rig rng15(info(128, 1024, UdpProfile::kRng15Rfl8Nir8));
  static Rig dual(info(32, 1024, UdpProfile::kRng19Rfl8Sig16Nir16Dual));
  static LidarPacket pkt;
  if (size < 1) return 0;
  const std::span<const std::uint8_t> body(data + 1, size - 1);
  const int which = data[0] % 6;
  switch (which) {
    case 0:
    case 1:
    case 4:
    case 5: {
      Rig& r = which == 0 ? legacy : which == 1 ? rng19 : which == 4 ? rng15 : dual;
      int bad = 0;
      // The fuzzer rarely hits the exact size: also try the input padded or cut to it.
      std::vector<std::uint8_t> sized(body.begin(), body.end());
      sized.resize(r.fmt.lidar_packet_size(), 0);
      for (auto span : {body, std::span<const std::uint8_t>(sized)}) {
        if (r.fmt.decode_lidar(span, pkt, &bad) == DecodeStatus::kOk) {
          round_trip(r, pkt);
          if (const LidarFrame* f = r.assembler.add(pkt)) r.lut.cartesian(*f, r.xyz.data());
        }
      }
      break;
    }
    case 2: {
      ImuSample s;
      (void)decode_imu(body, s);
      break;
    }
    case 3: {
      auto rd = PcapReader::from_bytes(std::vector<std::uint8_t>(body.begin(), body.end()), "fuzz");
      if (rd.ok()) {
        UdpDatagram d;
        for (int i = 0; i < 1000 && rd.value().next(d); ++i) {
        }
      }
      break;
    }
  }
  return 0;
}
