// A byte stream (serial), datagrams (UDP) or log records (tlog) cut into checked MAVLink v1/v2 frames.
// A frame whose CRC fails, whose id is not in the table or whose incompat flags are unknown is counted
// and the parser rescans from the byte after its magic, so a real frame behind a false start is kept.
// One fixed buffer, no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "airground/drivers/autopilot/mavlink/mavlink.hpp"

namespace ag::mavlink {

struct ParserCounters {
  std::uint64_t frames{0}, v1_frames{0}, v2_frames{0};
  std::uint64_t signed_frames{0};      // v2 frames with a signature (skipped, not checked)
  std::uint64_t truncated_payloads{0}; // v2 frames shorter than their message (zero-extended: normal)
  std::uint64_t garbage_bytes{0};      // bytes before a magic byte
  std::uint64_t bad_crc{0};            // checksum mismatch: noise, or a false magic byte
  std::uint64_t unknown_id{0};         // a message of another dialect, or a false magic byte
  std::uint64_t bad_length{0};         // a CRC-valid frame longer than its message (or a v1 frame shorter)
  std::uint64_t truncated{0};          // a frame cut off by the end of its datagram / record
  std::uint64_t unsupported_flags{0};  // v2 incompat flags other than "signed"
  [[nodiscard]] std::uint64_t errors() const noexcept { return bad_crc + unknown_id + bad_length + truncated + unsupported_flags; }
};

struct Frame {
  FrameHeader header;
  std::span<const std::uint8_t> payload;    // as received (v2: maybe shorter than the message)
  std::span<const std::uint8_t> signature;  // 13 bytes when signed, else empty
  std::size_t wire_bytes{0};
};

class FrameParser {
 public:
  static constexpr std::size_t kCapacity = 4096;

  // Copies as many bytes of `in` as fit; returns how many. Call next() until false before feeding more.
  std::size_t feed(std::span<const std::uint8_t> in) noexcept;
  // The next whole, checked frame; false when more bytes are needed. Its spans stay valid until feed().
  [[nodiscard]] bool next(Frame& out) noexcept;
  // The bytes fed so far end a datagram or a log record: a frame still incomplete is counted truncated
  // (its bytes after the magic are rescanned by the next calls of next()). Call it at the end of a
  // recording too, so that a false magic byte still waiting for its length does not hold back the rest.
  void end_of_packet() noexcept;
  [[nodiscard]] const ParserCounters& counters() const noexcept { return c_; }
  [[nodiscard]] std::size_t buffered() const noexcept { return tail_ - head_; }

 private:
  std::array<std::uint8_t, kCapacity> buf_{};
  std::size_t head_{0}, tail_{0};
  std::size_t boundary_{0};  // end of the last whole packet; frames may not run past it (0: a stream)
  ParserCounters c_;
};

}  // namespace ag::mavlink
