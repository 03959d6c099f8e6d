// The raw serial port (tty.hpp).
#include "airground/drivers/serial/tty.hpp"

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace ag::serial {

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
    case 500000: out = B500000; return true;
    case 921600: out = B921600; return true;
    case 1000000: out = B1000000; return true;
    case 1500000: out = B1500000; return true;
    case 2000000: out = B2000000; return true;
    case 3000000: out = B3000000; return true;
    default: return false;
  }
}
}  // namespace

Result<int> open_raw_tty(const std::string& device, int baud, const TtyOptions& o) {
  const std::string who(o.who);
  speed_t speed{};
  if (std::find(o.bauds.begin(), o.bauds.end(), baud) == o.bauds.end() || !baud_constant(baud, speed))
    return Error::make(ErrorCode::kConfig, who + ": baud " + std::to_string(baud) + " for " + device + " is not one of " + std::string(o.bauds_text));
  const int fd = ::open(device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return Error::make(ErrorCode::kIo, who + ": cannot open " + device + ": " + std::strerror(errno));
  termios t{};
  if (::tcgetattr(fd, &t) != 0) {
    const int e = errno;
    ::close(fd);
    return Error::make(ErrorCode::kIo, who + ": " + device + " is not a terminal: " + std::strerror(e));
  }
  ::cfmakeraw(&t);
  t.c_cflag |= CLOCAL | CREAD;
  // PX4's TELEM ports and u-blox UARTs default to flow control off (no CTS/RTS wired on many cables).
  t.c_cflag &= ~static_cast<tcflag_t>(CSTOPB | PARENB | CRTSCTS);
  t.c_cc[VMIN] = 0;
  t.c_cc[VTIME] = 0;
  ::cfsetispeed(&t, speed);
  ::cfsetospeed(&t, speed);
  if (::tcsetattr(fd, TCSANOW, &t) != 0) {
    const int e = errno;
    ::close(fd);
    return Error::make(ErrorCode::kIo, who + ": cannot configure " + device + ": " + std::strerror(e));
  }
  ::tcflush(fd, TCIFLUSH);
  return fd;
}

}  // namespace ag::serial
