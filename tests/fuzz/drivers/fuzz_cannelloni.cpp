// libFuzzer target: cannelloni datagrams. Decoded frames are encoded again and must decode to the same
// frames; error frames go through the error-frame decoder and the bus-state tracker.
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "airground/drivers/can/can_error.hpp"
#include "airground/drivers/can/cannelloni.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace ag::can;
  static std::array<cannelloni::WireFrame, 64> out, again;
  static CanErrorTracker tracker;
  static CanBusCounters counters;
  cannelloni::Decoded d;
  (void)cannelloni::decode(std::span<const std::uint8_t>(data, size), out, d);
  std::array<CanFrame, 64> classic{};
  std::size_t n = 0;
  for (std::size_t i = 0; i < d.frames; ++i) {
    if (out[i].error) {
      tracker.apply(decode_error_frame(out[i].frame.id, out[i].frame.data), counters);
      char text[96];
      (void)describe(tracker.last(), text, sizeof text);
    } else if (!out[i].fd) {
      classic[n++] = out[i].frame;
    }
  }
  std::array<std::uint8_t, 64 * 13 + 5> buf{};
  const std::size_t len = cannelloni::encode(d.seq, std::span<const CanFrame>(classic.data(), n), buf);
  if (len == 0) std::abort();
  cannelloni::Decoded d2;
  if (cannelloni::decode(std::span<const std::uint8_t>(buf.data(), len), again, d2) != cannelloni::DecodeStatus::kOk || d2.frames != n) std::abort();
  for (std::size_t i = 0; i < n; ++i) {
    const CanFrame& a = classic[i];
    const CanFrame& b = again[i].frame;
    if (a.id != b.id || a.extended != b.extended || a.rtr != b.rtr || a.dlc != b.dlc) std::abort();
    for (std::size_t k = 0; k < (a.rtr ? 0u : a.dlc); ++k)
      if (a.data[k] != b.data[k]) std::abort();
  }
  return 0;
}
