// Serial port (termios), UDP socket and tlog replay.
#include "airground/drivers/autopilot/mavlink/link.hpp"
#include "airground/platform/device_registry.hpp"


#include <arpa/inet.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>

#include "airground/drivers/autopilot/mavlink/mavlink.hpp"
#include "airground/drivers/serial/tty.hpp"

namespace ag::mavlink {

namespace {

bool poll_in(int fd, TimeNs timeout) noexcept {
  pollfd p{fd, POLLIN, 0};
  const int ms = timeout <= 0 ? 0 : static_cast<int>((timeout + kNsPerMs - 1) / kNsPerMs);
  return ::poll(&p, 1, ms) > 0;
}
}  // namespace

Result<std::unique_ptr<SerialLink>> SerialLink::open(const std::string& device, int baud) {
  static constexpr int kBauds[] = {57600, 115200, 230400, 460800, 500000, 921600, 1000000, 1500000, 2000000, 3000000};
  auto fd = serial::open_raw_tty(device, baud, serial::TtyOptions{"autopilot", kBauds, "57600, 115200, 230400, 460800, 500000, 921600, 1000000, 1500000, 2000000, 3000000"});
  if (!fd) return fd.error();
  return std::unique_ptr<SerialLink>(new SerialLink(fd.value(), device));
}

SerialLink::~SerialLink() {
  if (fd_ >= 0) ::close(fd_);
}

long SerialLink::read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept {
  recorded_ns = -1;
  const ssize_t n = ::read(fd_, buf.data(), buf.size());
  if (n >= 0) return n;
  if (errno == EAGAIN || errno == EINTR) return 0;
  if (error_.empty()) error_ = "autopilot: read " + device_ + ": " + std::strerror(errno);
  return -1;
}

long SerialLink::write(std::span<const std::uint8_t> bytes) noexcept {
  const ssize_t n = ::write(fd_, bytes.data(), bytes.size());
  if (n >= 0) return n;
  return errno == EAGAIN ? 0 : -1;
}

bool SerialLink::wait(TimeNs timeout) noexcept { return poll_in(fd_, timeout); }

Result<std::unique_ptr<UdpLink>> UdpLink::open(const std::string& bind_address, int port) {
  if (port < 0 || port > 65535) return Error::make(ErrorCode::kConfig, "autopilot: UDP port " + std::to_string(port) + " is not in [0, 65535]");
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::inet_pton(AF_INET, bind_address.c_str(), &a.sin_addr) != 1)
    return Error::make(ErrorCode::kConfig, "autopilot: '" + bind_address + "' is not an IPv4 address");
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return Error::make(ErrorCode::kIo, std::string("autopilot: socket: ") + std::strerror(errno));
  const int one = 1;
  (void)::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) {
    const int e = errno;
    ::close(fd);
    return Error::make(ErrorCode::kIo, "autopilot: cannot bind UDP " + bind_address + ":" + std::to_string(port) + ": " + std::strerror(e));
  }
  socklen_t len = sizeof a;
  (void)::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  return std::unique_ptr<UdpLink>(new UdpLink(fd, ntohs(a.sin_port)));
}

UdpLink::~UdpLink() {
  if (fd_ >= 0) ::close(fd_);
}

long UdpLink::read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept {
  recorded_ns = -1;
  sockaddr_in from{};
  socklen_t flen = sizeof from;
  const ssize_t n = ::recvfrom(fd_, buf.data(), buf.size(), MSG_TRUNC, reinterpret_cast<sockaddr*>(&from), &flen);
  if (n < 0) {
    if (errno == EAGAIN || errno == EINTR) return 0;
    if (error_.empty()) error_ = std::string("autopilot: recvfrom: ") + std::strerror(errno);
    return -1;
  }
  peer_ = from;
  have_peer_ = true;
  if (static_cast<std::size_t>(n) > buf.size()) {
    ++cut_;  // the parser counts the frame cut off at the buffer's end
    return static_cast<long>(buf.size());
  }
  return n;
}

long UdpLink::write(std::span<const std::uint8_t> bytes) noexcept {
  if (!have_peer_) return 0;  // the autopilot has not spoken yet
  const ssize_t n = ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&peer_), sizeof peer_);
  if (n >= 0) return n;
  return errno == EAGAIN ? 0 : -1;
}

bool UdpLink::wait(TimeNs timeout) noexcept { return poll_in(fd_, timeout); }

Result<std::unique_ptr<TlogReplay>> TlogReplay::open(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kIo, "autopilot: cannot open tlog " + path);
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (bytes.empty()) return Error::make(ErrorCode::kIo, "autopilot: tlog " + path + " is empty");
  return from_bytes(std::move(bytes));
}

std::unique_ptr<TlogReplay> TlogReplay::from_bytes(std::vector<std::uint8_t> bytes) {
  return std::unique_ptr<TlogReplay>(new TlogReplay(std::move(bytes)));
}

std::size_t TlogReplay::record_size(std::size_t at) const noexcept {
  if (at + 10 > data_.size()) return 0;
  const std::uint8_t magic = data_[at + 8], len = data_[at + 9];
  if (magic == kMagicV1) return 8 + kHeaderV1 + len + kChecksumBytes;
  if (magic != kMagicV2 || at + 11 > data_.size()) return 0;
  return 8 + kHeaderV2 + len + kChecksumBytes + ((data_[at + 10] & kIncompatSigned) != 0 ? kSignatureBytes : 0);
}

TimeNs TlogReplay::next_recorded() const noexcept {
  std::size_t at = pos_;
  while (at < data_.size() && record_size(at) == 0) ++at;
  if (at + 8 > data_.size()) return -1;
  std::uint64_t us = 0;
  for (std::size_t i = 0; i < 8; ++i) us = us << 8 | data_[at + i];
  return static_cast<TimeNs>(us) * kNsPerUs;
}

long TlogReplay::read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept {
  recorded_ns = -1;
  // A corrupt stretch (no frame where a record should start) is skipped a byte at a time, counted.
  while (pos_ < data_.size() && record_size(pos_) == 0) {
    if (data_.size() - pos_ < 10) {  // a record cut at the end of the file: too short to be anything
      bad_ += data_.size() - pos_;
      pos_ = data_.size();
      break;
    }
    ++bad_;
    ++pos_;
  }
  if (pos_ >= data_.size()) return -1;
  recorded_ns = next_recorded();
  const std::size_t size = std::min(record_size(pos_), data_.size() - pos_);  // the last may be cut short
  const std::size_t n = std::min(size - 8, buf.size());
  std::memcpy(buf.data(), data_.data() + pos_ + 8, n);
  pos_ += size;
  ++records_;
  return static_cast<long>(n);
}

void append_tlog_record(std::vector<std::uint8_t>& out, std::uint64_t unix_us, std::span<const std::uint8_t> frame) {
  for (int i = 7; i >= 0; --i) out.push_back(static_cast<std::uint8_t>(unix_us >> (8 * i)));
  out.insert(out.end(), frame.begin(), frame.end());
}

namespace {

class SimLink final : public Link {
 public:
  explicit SimLink(SimAutopilotLink& l) : link_(l) {}
  [[nodiscard]] long read(std::span<std::uint8_t> buf, TimeNs& recorded_ns) noexcept override {
    recorded_ns = -1;
    return static_cast<long>(link_.to_robot.read(buf));
  }
  [[nodiscard]] bool packetized() const noexcept override { return false; }
  long write(std::span<const std::uint8_t> bytes) noexcept override { return static_cast<long>(link_.from_robot.write(bytes)); }
  bool wait(TimeNs) noexcept override { return link_.to_robot.size() > 0; }  // the world wrote before this step
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }

 private:
  SimAutopilotLink& link_;
  std::string error_;
};


}  // namespace

std::unique_ptr<Link> SimAutopilotLink::open_link() { return std::make_unique<SimLink>(*this); }

bool register_sim_autopilot(std::string_view robot, SimAutopilotLink* link) { return DeviceRegistry<SimAutopilotLink>::instance().add(robot, link); }
void unregister_sim_autopilot(std::string_view robot) { DeviceRegistry<SimAutopilotLink>::instance().remove(robot); }
SimAutopilotLink* find_sim_autopilot(std::string_view robot) { return DeviceRegistry<SimAutopilotLink>::instance().find(robot); }

}  // namespace ag::mavlink
