// Living as a boot service: the sd_notify datagram protocol (spoken directly, since the binaries are
// static and Debian ships libsystemd only shared), watchdog timing and shutdown signals.
#pragma once

#include <string>
#include <string_view>

#include "airground/platform/time.hpp"

namespace ag {

class ServiceNotifier {
 public:
  // Reads NOTIFY_SOCKET, WATCHDOG_USEC and WATCHDOG_PID; disabled when not run by systemd.
  static ServiceNotifier from_environment();
  ServiceNotifier() = default;

  [[nodiscard]] bool enabled() const noexcept { return !socket_path_.empty(); }
  // 0 when the unit has no WatchdogSec.
  [[nodiscard]] TimeNs watchdog_interval() const noexcept { return watchdog_ns_; }
  bool notify(std::string_view state) const noexcept;  // e.g. "READY=1\nSTATUS=running"
  bool ready(std::string_view status) const;
  bool watchdog() const noexcept { return notify("WATCHDOG=1"); }
  bool stopping() const noexcept { return notify("STOPPING=1"); }

 private:
  std::string socket_path_;  // '@' first for the abstract namespace
  TimeNs watchdog_ns_{0};
};

// Blocks SIGINT and SIGTERM in the calling thread (call before spawning threads, so every thread
// inherits the mask) so they are taken only by wait_for_shutdown_signal().
void block_shutdown_signals() noexcept;
// Waits up to `timeout` for SIGINT/SIGTERM; returns the signal number, or 0 on timeout.
int wait_for_shutdown_signal(TimeNs timeout) noexcept;

}  // namespace ag
