// The receiver's byte stream (UBX frames and NMEA sentences interleaved) cut into messages. Garbage,
// bad checksums and oversized frames are counted and the parser resynchronises on the byte after the
// failed frame's first sync byte, so a real frame hidden behind a false start is not lost. Fixed
// buffers, no allocation.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string_view>

namespace ag::ublox {

inline constexpr std::size_t kMaxUbxPayload = 2048;  // larger frames (none we decode) are skipped
inline constexpr std::size_t kMaxNmeaLength = 120;   // NMEA says 82; u-blox GSV/TXT stay under 100

struct StreamCounters {
  std::uint64_t ubx_frames{0}, nmea_sentences{0};
  std::uint64_t garbage_bytes{0};       // bytes outside any frame or sentence
  std::uint64_t ubx_bad_checksum{0}, ubx_oversize{0};
  std::uint64_t nmea_bad_checksum{0}, nmea_malformed{0};  // too long, control characters, no '*HH'
};

struct StreamMessage {
  enum class Kind : std::uint8_t { kNone, kUbx, kNmea } kind{Kind::kNone};
  std::uint8_t cls{0}, id{0};
  std::span<const std::uint8_t> payload;  // UBX: valid until the next feed()
  std::string_view sentence;               // NMEA, without CR/LF: valid until the next feed()
};

class StreamParser {
 public:
  // Consumes bytes until one message is complete (returned in `out`) or the input is used up; returns
  // how many bytes of `in` were consumed. Call again with the rest.
  std::size_t feed(std::span<const std::uint8_t> in, StreamMessage& out) noexcept;
  [[nodiscard]] const StreamCounters& counters() const noexcept { return c_; }

 private:
  enum class State : std::uint8_t { kHunt, kSync2, kClass, kId, kLen1, kLen2, kPayload, kCkA, kCkB, kNmea };
  bool step(std::uint8_t b, StreamMessage& out) noexcept;
  void fail() noexcept;  // rescan the frame after its first byte

  State st_{State::kHunt};
  std::array<std::uint8_t, kMaxUbxPayload + 8> buf_{};
  std::size_t n_{0}, len_{0};
  std::uint8_t ck_a_{0};
  // Bytes to rescan before new input. A failed frame that began in new input leaves nothing else
  // pending; one that began in pending bytes leaves fewer than were pending: one frame's size bounds it.
  std::array<std::uint8_t, kMaxUbxPayload + 8> pend_{};
  std::size_t pend_pos_{0}, pend_len_{0};
  StreamCounters c_;
};

}  // namespace ag::ublox
