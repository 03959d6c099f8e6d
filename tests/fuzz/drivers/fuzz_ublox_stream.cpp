// libFuzzer target: a GNSS receiver's byte stream (UBX and NMEA interleaved) through the resynchronising
// parser, in pieces whose sizes the first byte picks; every UBX frame goes to the NAV-PVT decoder and
// every sentence to the GGA and RMC parsers.
#include <cstddef>
#include <cstdint>

#include "airground/drivers/gps/ublox/nmea.hpp"
#include "airground/drivers/gps/ublox/stream_parser.hpp"
#include "airground/drivers/gps/ublox/ubx.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace ag::ublox;
  if (size < 1) return 0;
  const std::size_t chunk = 1 + data[0] % 64;
  StreamParser p;
  std::span<const std::uint8_t> in(data + 1, size - 1);
  StreamMessage m;
  auto handle = [&] {
    if (m.kind == StreamMessage::Kind::kUbx) {
      NavPvt pvt;
      (void)decode_nav_pvt(m.payload, pvt);
    } else if (m.kind == StreamMessage::Kind::kNmea) {
      GgaFix g;
      RmcFix r;
      (void)parse_gga(m.sentence, g);
      (void)parse_rmc(m.sentence, r);
    }
  };
  while (!in.empty()) {
    auto piece = in.first(std::min(chunk, in.size()));
    in = in.subspan(piece.size());
    while (!piece.empty()) {
      const std::size_t used = p.feed(piece, m);
      piece = piece.subspan(used);
      handle();
    }
  }
  do {
    (void)p.feed({}, m);
    handle();
  } while (m.kind != StreamMessage::Kind::kNone);
  return 0;
}
