// libFuzzer target: Ouster packets off the wire. The first byte picks what the rest is:
//   0  a lidar datagram, LEGACY profile (64 beams, 1024 columns), fed on into the frame assembler
//   1  a lidar datagram, RNG19_RFL8_SIG16_NIR16 (32 beams, 512 columns, a size the fuzzer can reach)
//   2  an IMU datagram
//   3  a capture file for the pcap/pcapng reader
#include <cstddef>
#include <cstdint>
#include <vector>

#include "airground/drivers/ouster/frame.hpp"
#include "airground/drivers/ouster/pcap_reader.hpp"
#include "airground/drivers/ouster/xyz_lut.hpp"

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
  explicit Rig(SensorInfo s) : info(s), fmt(s), assembler(s), lut(s), xyz(3 * static_cast<std::size_t>(s.mode.columns) * s.beam_altitude_deg.size()) {}
};
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static Rig legacy(info(64, 1024, UdpProfile::kLegacy));
  static Rig rng19(info(32, 512, UdpProfile::kRng19Rfl8Sig16Nir16));
  static LidarPacket pkt;
  if (size < 1) return 0;
  const std::span<const std::uint8_t> body(data + 1, size - 1);
  switch (data[0] % 4) {
    case 0:
    case 1: {
      Rig& r = data[0] % 4 == 0 ? legacy : rng19;
      int bad = 0;
      // The fuzzer rarely hits the exact size: also try the input padded or cut to it.
      std::vector<std::uint8_t> sized(body.begin(), body.end());
      sized.resize(r.fmt.lidar_packet_size(), 0);
      for (auto span : {body, std::span<const std::uint8_t>(sized)}) {
        if (r.fmt.decode_lidar(span, pkt, &bad) == DecodeStatus::kOk) {
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
