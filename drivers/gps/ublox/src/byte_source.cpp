// Serial port (termios) and replay file.
#include "airground/drivers/gps/ublox/byte_source.hpp"
#include "airground/platform/device_registry.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <iterator>
#include <poll.h>
#include <unistd.h>

#include "airground/drivers/serial/tty.hpp"

namespace ag::ublox {

Result<std::unique_ptr<SerialPort>> SerialPort::open(const std::string& device, int baud) {
  static constexpr int kBauds[] = {9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600};
  auto fd = serial::open_raw_tty(device, baud, serial::TtyOptions{"gps", kBauds, "9600..921600"});
  if (!fd) return fd.error();
  return std::unique_ptr<SerialPort>(new SerialPort(fd.value(), device));
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

class SimSerialSource final : public ByteSource {
 public:
  explicit SimSerialSource(SimSerialLink& l) : link_(l) {}
  [[nodiscard]] long read(std::span<std::uint8_t> buf) noexcept override { return static_cast<long>(link_.uart_.read(buf)); }
  bool wait(TimeNs) noexcept override { return link_.queued() > 0; }  // the world wrote before this step
  [[nodiscard]] const std::string& error() const noexcept override { return error_; }

 private:
  SimSerialLink& link_;
  std::string error_;
};

std::unique_ptr<ByteSource> SimSerialLink::open_source() { return std::make_unique<SimSerialSource>(*this); }

bool register_sim_gps(std::string_view robot, SimSerialLink* link) { return DeviceRegistry<SimSerialLink>::instance().add(robot, link); }
void unregister_sim_gps(std::string_view robot) { DeviceRegistry<SimSerialLink>::instance().remove(robot); }
SimSerialLink* find_sim_gps(std::string_view robot) { return DeviceRegistry<SimSerialLink>::instance().find(robot); }

}  // namespace ag::ublox
