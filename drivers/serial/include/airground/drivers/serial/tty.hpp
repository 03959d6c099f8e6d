// A serial port opened raw (termios): 8N1, no flow control, non-blocking, no line discipline. The
// GNSS receivers and autopilots we talk to expect that (u-blox UART1, PX4 TELEM ports); the ublox and
// mavlink drivers open their ports through here.
#pragma once

#include <span>
#include <string>
#include <string_view>

#include "airground/platform/result.hpp"

namespace ag::serial {

struct TtyOptions {
  std::string_view who;         // the driver, first word of every error ("gps", "autopilot")
  std::span<const int> bauds;   // the rates the device supports
  std::string_view bauds_text;  // how the error lists them ("9600..921600")
};

// Opens `device` at `baud`, raw 8N1 without flow control, non-blocking and close-on-exec, input flushed.
// Returns the descriptor (the caller closes it). Errors name the driver, the device and the system's reason.
Result<int> open_raw_tty(const std::string& device, int baud, const TtyOptions& options);

}  // namespace ag::serial
