// cannelloni wire format and the CAN-over-UDP bus.
#include "airground/drivers/can/cannelloni.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "airground/platform/clock.hpp"

namespace ag::can::cannelloni {

const char* to_string(DecodeStatus s) noexcept {
  switch (s) {
    case DecodeStatus::kOk: return "ok";
    case DecodeStatus::kShort: return "shorter than the cannelloni header";
    case DecodeStatus::kBadVersion: return "not cannelloni version 2";
    case DecodeStatus::kNotData: return "not a DATA packet";
    case DecodeStatus::kTruncated: return "fewer frames than its count";
    case DecodeStatus::kBadLength: return "frame length out of range";
    case DecodeStatus::kTrailingBytes: return "bytes after the last frame";
  }
  return "?";
}

DecodeStatus decode(std::span<const std::uint8_t> in, std::span<WireFrame> out, Decoded& d) noexcept {
  d = Decoded{};
  if (in.size() < kHeaderSize) return DecodeStatus::kShort;
  if (in[0] != kVersion) return DecodeStatus::kBadVersion;
  d.seq = in[2];
  d.count = static_cast<std::uint16_t>((in[3] << 8) | in[4]);
  if (in[1] != kOpData) return DecodeStatus::kNotData;
  std::size_t pos = kHeaderSize;
  for (std::size_t i = 0; i < d.count; ++i) {
    if (in.size() - pos < 5) return DecodeStatus::kTruncated;
    const std::uint32_t id = (std::uint32_t{in[pos]} << 24) | (std::uint32_t{in[pos + 1]} << 16) | (std::uint32_t{in[pos + 2]} << 8) | in[pos + 3];
    const std::uint8_t len_byte = in[pos + 4];
    pos += 5;
    WireFrame w;
    w.fd = (len_byte & 0x80) != 0;
    std::size_t len = len_byte & 0x7F;
    if (w.fd) {
      if (len > 64) return DecodeStatus::kBadLength;
      if (in.size() - pos < 1) return DecodeStatus::kTruncated;
      ++pos;  // CAN FD flags
    } else if (len > 8) {
      return DecodeStatus::kBadLength;
    }
    const bool rtr = !w.fd && (id & kRtrFlag) != 0;
    const std::size_t data_len = rtr ? 0 : len;
    if (in.size() - pos < data_len) return DecodeStatus::kTruncated;
    w.error = (id & kErrFlag) != 0;
    w.frame.extended = (id & kEffFlag) != 0;
    w.frame.rtr = rtr;
    w.frame.id = w.error ? (id & 0x1FFFFFFFU) : id & (w.frame.extended ? kExtendedIdMask : kStandardIdMask);
    w.frame.dlc = static_cast<std::uint8_t>(w.fd ? 0 : len);
    if (!w.fd && data_len > 0) std::memcpy(w.frame.data.data(), in.data() + pos, data_len);
    pos += data_len;
    if (d.frames < out.size()) out[d.frames++] = w;
  }
  return pos == in.size() ? DecodeStatus::kOk : DecodeStatus::kTrailingBytes;
}

std::size_t encode(std::uint8_t seq, std::span<const CanFrame> frames, std::span<std::uint8_t> out) noexcept {
  std::size_t need = kHeaderSize;
  for (const CanFrame& f : frames) need += encoded_size(f);
  if (out.size() < need || frames.size() > 0xFFFF) return 0;
  out[0] = kVersion;
  out[1] = kOpData;
  out[2] = seq;
  out[3] = static_cast<std::uint8_t>(frames.size() >> 8);
  out[4] = static_cast<std::uint8_t>(frames.size() & 0xFF);
  std::size_t pos = kHeaderSize;
  for (const CanFrame& f : frames) {
    const std::uint32_t id = f.id | (f.extended ? kEffFlag : 0U) | (f.rtr ? kRtrFlag : 0U);
    out[pos] = static_cast<std::uint8_t>(id >> 24);
    out[pos + 1] = static_cast<std::uint8_t>(id >> 16);
    out[pos + 2] = static_cast<std::uint8_t>(id >> 8);
    out[pos + 3] = static_cast<std::uint8_t>(id);
    out[pos + 4] = f.dlc;
    pos += 5;
    if (!f.rtr) {
      std::memcpy(out.data() + pos, f.data.data(), f.dlc);
      pos += f.dlc;
    }
  }
  return pos;
}

}  // namespace ag::can::cannelloni

namespace ag::can {

Result<std::unique_ptr<CannelloniBus>> CannelloniBus::open(const CannelloniConfig& cfg) {
  in_addr remote{};
  if (::inet_pton(AF_INET, cfg.remote_address.c_str(), &remote) != 1)
    return Error::make(ErrorCode::kConfig, "cannelloni: remote address '" + cfg.remote_address + "' is not IPv4");
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return Error::make(ErrorCode::kIo, std::string("cannelloni: socket: ") + std::strerror(errno));
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(cfg.local_port);
  if (::inet_pton(AF_INET, cfg.bind_address.c_str(), &sa.sin_addr) != 1) {
    ::close(fd);
    return Error::make(ErrorCode::kConfig, "cannelloni: bind address '" + cfg.bind_address + "' is not IPv4");
  }
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&sa), sizeof sa) != 0) {
    const int e = errno;
    ::close(fd);
    return Error::make(ErrorCode::kIo, "cannelloni: bind " + cfg.bind_address + ":" + std::to_string(cfg.local_port) + ": " + std::strerror(e));
  }
  socklen_t len = sizeof sa;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
  return std::unique_ptr<CannelloniBus>(new CannelloniBus(fd, ntohs(sa.sin_port), ntohl(remote.s_addr), cfg.remote_port, cfg.learn_remote));
}

CannelloniBus::~CannelloniBus() {
  if (fd_ >= 0) ::close(fd_);
}

CanResult CannelloniBus::send_batch(std::span<const CanFrame> frames, std::span<const std::uint32_t> raw_ids) noexcept {
  std::uint8_t buf[1472];
  std::size_t n = cannelloni::encode(tx_seq_, frames, buf);
  if (n == 0) return CanResult::kInvalid;
  // raw_ids: identifiers with linux/can.h flags written as they are (error frames from a simulator).
  std::size_t pos = cannelloni::kHeaderSize;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (i < raw_ids.size() && raw_ids[i] != 0) {
      buf[pos] = static_cast<std::uint8_t>(raw_ids[i] >> 24);
      buf[pos + 1] = static_cast<std::uint8_t>(raw_ids[i] >> 16);
      buf[pos + 2] = static_cast<std::uint8_t>(raw_ids[i] >> 8);
      buf[pos + 3] = static_cast<std::uint8_t>(raw_ids[i]);
    }
    pos += cannelloni::encoded_size(frames[i]);
  }
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(remote_port_);
  to.sin_addr.s_addr = htonl(remote_ip_);
  const ssize_t w = ::sendto(fd_, buf, n, MSG_DONTWAIT, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  if (w != static_cast<ssize_t>(n)) {
    c_.tx_dropped += frames.size();
    return errno == EAGAIN || errno == ENOBUFS ? CanResult::kWouldBlock : CanResult::kDown;
  }
  ++tx_seq_;
  ++b_.datagrams_tx;
  c_.tx += frames.size();
  return CanResult::kOk;
}

CanResult CannelloniBus::send(const CanFrame& f) noexcept {
  if (!valid(f)) return CanResult::kInvalid;
  return send_batch(std::span<const CanFrame>(&f, 1));
}

void CannelloniBus::pump() noexcept {
  std::uint8_t buf[4096];  // cannelloni keeps datagrams under the MTU
  for (int k = 0; k < 16 && size_ < kQueue; ++k) {
    sockaddr_in from{};
    socklen_t flen = sizeof from;
    const ssize_t n = ::recvfrom(fd_, buf, sizeof buf, MSG_DONTWAIT, reinterpret_cast<sockaddr*>(&from), &flen);
    if (n < 0) return;
    ++b_.datagrams_rx;
    if (learn_) {
      remote_ip_ = ntohl(from.sin_addr.s_addr);
      remote_port_ = ntohs(from.sin_port);
    }
    cannelloni::Decoded d;
    const auto st = cannelloni::decode(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n)), scratch_, d);
    if (st != cannelloni::DecodeStatus::kOk) {
      ++b_.decode_errors;
      ++c_.rx_errors;
      if (st == cannelloni::DecodeStatus::kShort || st == cannelloni::DecodeStatus::kBadVersion || st == cannelloni::DecodeStatus::kNotData) continue;
    }
    if (rx_seq_known_ && d.seq != rx_seq_) ++b_.sequence_gaps;
    rx_seq_ = static_cast<std::uint8_t>(d.seq + 1);
    rx_seq_known_ = true;
    const TimeNs now = monotonic_now();
    for (std::size_t i = 0; i < d.frames; ++i) {
      const cannelloni::WireFrame& w = scratch_[i];
      if (w.fd) {
        ++b_.fd_frames;
        ++c_.rx_errors;
        continue;
      }
      if (w.error) {
        errors_.apply(decode_error_frame(w.frame.id, w.frame.data), c_);
        ++c_.rx_errors;
        continue;
      }
      if (!accepts(w.frame)) {
        ++c_.rx_filtered;
        continue;
      }
      if (size_ == kQueue) {
        ++b_.queue_overflow;
        continue;
      }
      CanFrame& slot = q_[(head_ + size_) % kQueue];
      slot = w.frame;
      slot.stamp = now;
      ++size_;
    }
  }
}

CanResult CannelloniBus::receive(CanFrame& out) noexcept {
  if (size_ == 0) pump();
  if (size_ == 0) return CanResult::kWouldBlock;
  out = q_[head_];
  head_ = (head_ + 1) % kQueue;
  --size_;
  ++c_.rx;
  if (errors_.state() == CanBusState::kBusOff) errors_.reset();
  return CanResult::kOk;
}

}  // namespace ag::can
