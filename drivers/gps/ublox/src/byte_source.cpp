// Serial port (termios) and replay file.
#include "airground/drivers/ublox/byte_source.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <iterator>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

namespace ag::ublox {

namespace {
bool baud_constant(int baud, speed_t& out) noexcept {
  switch (baud) {
    case 9600: out = B9600; return true;
    case 19200: out = B19200; return true;
    case 38400: out = B38400; return true;
    case 57600: out = B57600; return true;
    case 115200: out = B115200; return true;
    case 230400: out = B230400; return true;
    case 460800: out = B460800; return true;
    case 921600: out = B921600; return true;
    default: return false;
  }
}
}  // namespace

Result<std::unique_ptr<SerialPort>> SerialPort::open(const std::string& device, int baud) {
  speed_t speed{};
  if (!baud_constant(baud, speed))
    return Error::make(ErrorCode::kConfig, "gps: baud " + std::to_string(baud) + " for " + device + " is not one of 9600..921600");
  const int fd = ::open(device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return Error::make(ErrorCode::kIo, "gps: cannot open " + device + ": " + std::strerror(errno));
  termios t{};
  if (::tcgetattr(fd, &t) != 0) {
    const int e = errno;
    ::close(fd);
    return Error::make(ErrorCode::kIo, "gps: " + device + " is not a terminal: " + std::strerror(e));
  }
  ::cfmakeraw(&t);
  t.c_cflag |= CLOCAL | CREAD;
  t.c_cflag &= ~static_cast<tcflag_t>(CSTOPB | PARENB | CRTSCTS);
  t.c_cc[VMIN] = 0;
  t.c_cc[VTIME] = 0;
  ::cfsetispeed(&t, speed);
  ::cfsetospeed(&t, speed);
  if (::tcsetattr(fd, TCSANOW, &t) != 0) {
    const int e = errno;
    ::close(fd);
    return Error::make(ErrorCode::kIo, "gps: cannot configure " + device + ": " + std::strerror(e));
  }
  ::tcflush(fd, TCIFLUSH);
  return std::unique_ptr<SerialPort>(new SerialPort(fd, device));
}

SerialPort::~SerialPort() {
  if (fd_ >= 0) ::close(fd_);
}

long SerialPort::read(std::span<std::uint8_t> buf) noexcept {
  const ssize_t n = ::read(fd_, buf.data(), buf.size());
  if (n >= 0) return n;
  if (errno == EAGAIN || errno == EINTR) return 0;
  if (error_.empty()) error_ = "gps: read " + device_ + ": " + std::strerror(errno);
  return -1;
}

long SerialPort::write(std::span<const std::uint8_t> bytes) noexcept {
  const ssize_t n = ::write(fd_, bytes.data(), bytes.size());
  if (n >= 0) return n;
  if (errno == EAGAIN) return 0;
  return -1;
}

bool SerialPort::wait(TimeNs timeout) noexcept {
  pollfd p{fd_, POLLIN, 0};
  const int ms = timeout <= 0 ? 0 : static_cast<int>((timeout + kNsPerMs - 1) / kNsPerMs);
  return ::poll(&p, 1, ms) > 0;
}

ReplayFile::ReplayFile(std::vector<std::uint8_t> d, std::size_t chunk) : data_(std::move(d)), chunk_(chunk == 0 ? 1 : chunk) {
  // gpsd test logs: '#' lines before the stream.
  while (start_ < data_.size() && data_[start_] == '#') {
    const auto nl = std::find(data_.begin() + static_cast<long>(start_), data_.end(), std::uint8_t{'\n'});
    start_ = nl == data_.end() ? data_.size() : static_cast<std::size_t>(nl - data_.begin()) + 1;
  }
  pos_ = start_;
}

Result<std::unique_ptr<ReplayFile>> ReplayFile::open(const std::string& path, std::size_t chunk) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error::make(ErrorCode::kIo, "gps: cannot open replay file " + path);
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return from_bytes(std::move(bytes), chunk);
}

std::unique_ptr<ReplayFile> ReplayFile::from_bytes(std::vector<std::uint8_t> bytes, std::size_t chunk) {
  return std::unique_ptr<ReplayFile>(new ReplayFile(std::move(bytes), chunk));
}

long ReplayFile::read(std::span<std::uint8_t> buf) noexcept {
  if (pos_ >= data_.size()) return -1;
  const std::size_t n = std::min({buf.size(), chunk_, data_.size() - pos_});
  std::memcpy(buf.data(), data_.data() + pos_, n);
  pos_ += n;
  return static_cast<long>(n);
}

}  // namespace ag::ublox
