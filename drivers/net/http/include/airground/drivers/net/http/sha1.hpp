// SHA-1 (FIPS 180-4) and base64 (RFC 4648): what the WebSocket handshake needs (RFC 6455 §4.2.2).
// SHA-1 is used here only for the handshake's accept key, never for security.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace ag::net::http {

[[nodiscard]] std::array<std::uint8_t, 20> sha1(std::span<const std::uint8_t> data) noexcept;
[[nodiscard]] std::array<std::uint8_t, 20> sha1(std::string_view text) noexcept;
[[nodiscard]] std::string base64_encode(std::span<const std::uint8_t> data);
// The Sec-WebSocket-Accept value for a client's Sec-WebSocket-Key.
[[nodiscard]] std::string websocket_accept(std::string_view client_key);

}  // namespace ag::net::http
