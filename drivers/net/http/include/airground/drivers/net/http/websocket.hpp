// WebSocket framing (RFC 6455 §5): the server writes unmasked frames and reads the client's masked ones.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace ag::net::http {

enum class WsOpcode : std::uint8_t { kContinuation = 0, kText = 1, kBinary = 2, kClose = 8, kPing = 9, kPong = 10 };

inline constexpr std::size_t kWsMaxHeader = 14;

// Writes a final, unmasked frame header for `payload_len` bytes into hdr; returns its length (2, 4 or 10).
std::size_t ws_frame_header(std::uint8_t* hdr, WsOpcode op, std::uint64_t payload_len) noexcept;

struct WsFrame {
  bool fin{false};
  WsOpcode opcode{WsOpcode::kContinuation};
  bool masked{false};
  std::array<std::uint8_t, 4> mask{};
  std::size_t header_len{0};
  std::uint64_t payload_len{0};
};

enum class WsParse : std::uint8_t { kNeedMore, kOk, kError };

// Parses the header of the frame at the start of `in` (payload length is checked against
// max_payload). From a client every frame must be masked (§5.1); control frames ≤ 125 B and final
// (§5.5); reserved bits zero (no extension was negotiated); opcode known. `why` names the fault.
WsParse ws_parse_header(std::span<const std::uint8_t> in, std::uint64_t max_payload, bool require_mask, WsFrame& out,
                        const char** why) noexcept;

// Unmasks (or masks) payload in place; `offset` is the payload position of data[0].
void ws_apply_mask(std::span<std::uint8_t> data, const std::array<std::uint8_t, 4>& mask, std::size_t offset = 0) noexcept;

}  // namespace ag::net::http
