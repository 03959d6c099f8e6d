#include "airground/drivers/net/http/websocket.hpp"

namespace ag::net::http {

std::size_t ws_frame_header(std::uint8_t* hdr, WsOpcode op, std::uint64_t n) noexcept {
  hdr[0] = static_cast<std::uint8_t>(0x80u | static_cast<std::uint8_t>(op));
  if (n < 126) {
    hdr[1] = static_cast<std::uint8_t>(n);
    return 2;
  }
  if (n <= 0xFFFF) {
    hdr[1] = 126;
    hdr[2] = static_cast<std::uint8_t>(n >> 8);
    hdr[3] = static_cast<std::uint8_t>(n);
    return 4;
  }
  hdr[1] = 127;
  for (int i = 0; i < 8; ++i) hdr[2 + i] = static_cast<std::uint8_t>(n >> (56 - 8 * i));
  return 10;
}

WsParse ws_parse_header(std::span<const std::uint8_t> in, std::uint64_t max_payload, bool require_mask, WsFrame& f,
                        const char** why) noexcept {
  *why = "";
  if (in.size() < 2) return WsParse::kNeedMore;
  f.fin = (in[0] & 0x80u) != 0;
  if ((in[0] & 0x70u) != 0) {
    *why = "reserved bits set";
    return WsParse::kError;
  }
  const std::uint8_t op = in[0] & 0x0Fu;
  if (op != 0 && op != 1 && op != 2 && op != 8 && op != 9 && op != 10) {
    *why = "unknown opcode";
    return WsParse::kError;
  }
  f.opcode = static_cast<WsOpcode>(op);
  f.masked = (in[1] & 0x80u) != 0;
  if (require_mask && !f.masked) {
    *why = "client frame not masked";
    return WsParse::kError;
  }
  std::uint64_t n = in[1] & 0x7Fu;
  std::size_t pos = 2;
  if (n == 126) {
    if (in.size() < 4) return WsParse::kNeedMore;
    n = (std::uint64_t{in[2]} << 8) | in[3];
    pos = 4;
  } else if (n == 127) {
    if (in.size() < 10) return WsParse::kNeedMore;
    n = 0;
    for (int i = 0; i < 8; ++i) n = (n << 8) | in[2 + static_cast<std::size_t>(i)];
    if ((n >> 63) != 0) {
      *why = "length with the top bit set";
      return WsParse::kError;
    }
    pos = 10;
  }
  if (op >= 8 && (n > 125 || !f.fin)) {
    *why = "control frame too long or fragmented";
    return WsParse::kError;
  }
  if (n > max_payload) {
    *why = "frame larger than the server accepts";
    return WsParse::kError;
  }
  if (f.masked) {
    if (in.size() < pos + 4) return WsParse::kNeedMore;
    for (int i = 0; i < 4; ++i) f.mask[static_cast<std::size_t>(i)] = in[pos + static_cast<std::size_t>(i)];
    pos += 4;
  }
  f.header_len = pos;
  f.payload_len = n;
  return WsParse::kOk;
}

void ws_apply_mask(std::span<std::uint8_t> data, const std::array<std::uint8_t, 4>& mask, std::size_t offset) noexcept {
  for (std::size_t i = 0; i < data.size(); ++i) data[i] ^= mask[(i + offset) & 3u];
}

}  // namespace ag::net::http
