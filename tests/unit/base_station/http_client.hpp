// A blocking loopback TCP client for the server tests (raw bytes, so malformed requests can be sent).
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace ag::base_station::test {

class Client {
 public:
  explicit Client(int port, int rcvbuf = 0) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    if (rcvbuf > 0) ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_port = htons(static_cast<std::uint16_t>(port));
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ok_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&sa), sizeof sa) == 0;
  }
  ~Client() {
    if (fd_ >= 0) ::close(fd_);
  }
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;
  [[nodiscard]] bool ok() const { return ok_; }
  void send(const std::string& s) { [[maybe_unused]] auto n = ::send(fd_, s.data(), s.size(), MSG_NOSIGNAL); }
  void send(const std::vector<std::uint8_t>& s) { [[maybe_unused]] auto n = ::send(fd_, s.data(), s.size(), MSG_NOSIGNAL); }
  // Reads until `pred(buffer)` holds, the peer closes or timeout_s passes. Returns whether pred held.
  template <typename P>
  bool read_until(P pred, double timeout_s = 2.0) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<int>(timeout_s * 1000));
    while (!pred(buf)) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now()).count();
      if (left <= 0) return false;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left)) <= 0) continue;
      char b[65536];
      const ssize_t n = ::recv(fd_, b, sizeof b, 0);
      if (n <= 0) {
        closed = true;
        return pred(buf);
      }
      buf.append(b, static_cast<std::size_t>(n));
    }
    return true;
  }
  bool read_contains(const std::string& s, double timeout_s = 2.0) {
    return read_until([&](const std::string& b) { return b.find(s) != std::string::npos; }, timeout_s);
  }
  // Until the peer closes (or the timeout).
  bool read_to_close(double timeout_s = 2.0) {
    read_until([&](const std::string&) { return closed; }, timeout_s);
    return closed;
  }
  std::string buf;
  bool closed{false};

 private:
  int fd_{-1};
  bool ok_{false};
};

inline std::string get_request(const std::string& path, bool close = true) {
  return "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + (close ? "Connection: close\r\n" : "") + "\r\n";
}
inline std::string ws_upgrade(const std::string& key = "dGhlIHNhbXBsZSBub25jZQ==") {
  return "GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: " + key +
         "\r\nSec-WebSocket-Version: 13\r\n\r\n";
}

// Frames in a server -> client byte stream after the HTTP head (unmasked).
struct Frame {
  std::uint8_t opcode{0};
  std::string payload;
};
inline std::vector<Frame> ws_frames(const std::string& stream) {
  std::vector<Frame> out;
  std::size_t pos = stream.find("\r\n\r\n");
  if (pos == std::string::npos) return out;
  pos += 4;
  while (pos + 2 <= stream.size()) {
    const auto b0 = static_cast<std::uint8_t>(stream[pos]), b1 = static_cast<std::uint8_t>(stream[pos + 1]);
    std::uint64_t n = b1 & 0x7Fu;
    std::size_t h = 2;
    if (n == 126) {
      if (pos + 4 > stream.size()) break;
      n = (std::uint64_t{static_cast<std::uint8_t>(stream[pos + 2])} << 8) | static_cast<std::uint8_t>(stream[pos + 3]);
      h = 4;
    } else if (n == 127) {
      if (pos + 10 > stream.size()) break;
      n = 0;
      for (std::size_t i = 0; i < 8; ++i) n = (n << 8) | static_cast<std::uint8_t>(stream[pos + 2 + i]);
      h = 10;
    }
    if (pos + h + n > stream.size()) break;
    out.push_back(Frame{static_cast<std::uint8_t>(b0 & 0x0Fu), stream.substr(pos + h, static_cast<std::size_t>(n))});
    pos += h + static_cast<std::size_t>(n);
  }
  return out;
}
// A masked client frame.
inline std::vector<std::uint8_t> client_frame(std::uint8_t opcode, const std::string& payload, bool masked = true) {
  std::vector<std::uint8_t> f{static_cast<std::uint8_t>(0x80u | opcode)};
  const std::uint8_t mask[4] = {0x37, 0xfa, 0x21, 0x3d};
  f.push_back(static_cast<std::uint8_t>((masked ? 0x80u : 0u) | payload.size()));
  if (masked)
    for (std::uint8_t m : mask) f.push_back(m);
  for (std::size_t i = 0; i < payload.size(); ++i)
    f.push_back(static_cast<std::uint8_t>(static_cast<std::uint8_t>(payload[i]) ^ (masked ? mask[i % 4] : 0)));
  return f;
}

}  // namespace ag::base_station::test
