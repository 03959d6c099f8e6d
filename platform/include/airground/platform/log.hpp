// Structured logging that real-time threads may call: records go through a lock-free queue to a
// writer thread, so a log call never blocks on stderr or journald and never allocates.
#pragma once

#include <atomic>
#include <cstdarg>
#include <cstdint>
#include <string_view>

namespace ag::log {

enum class Level : std::uint8_t { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3 };

// Lines look like: 2026-11-22T10:11:12.345Z info  status: stage=camera p99_us=812 overruns=0
// Fields after the message are logfmt (key=value). Under systemd (JOURNAL_STREAM set) each line
// carries the <N> syslog prefix so journald keeps the level.
void write(Level level, const char* component, const char* fmt, ...) noexcept __attribute__((format(printf, 3, 4)));
void vwrite(Level level, const char* component, const char* fmt, va_list ap) noexcept;

void set_level(Level level) noexcept;
[[nodiscard]] Level level() noexcept;
bool parse_level(std::string_view text, Level& out) noexcept;

// Start the writer thread (call once at start-up). Without it, lines are written synchronously,
// which is what tools and tests want.
void start_writer();
// Drain what is queued and stop the writer thread.
void stop_writer() noexcept;
// Write out everything queued so far (from the calling thread).
void flush() noexcept;
[[nodiscard]] std::uint64_t dropped() noexcept;
// Redirect output (tests): a file descriptor, default 2.
void set_fd(int fd) noexcept;

}  // namespace ag::log

#define AG_LOG_DEBUG(comp, ...) ::ag::log::write(::ag::log::Level::kDebug, comp, __VA_ARGS__)
#define AG_LOG_INFO(comp, ...) ::ag::log::write(::ag::log::Level::kInfo, comp, __VA_ARGS__)
#define AG_LOG_WARN(comp, ...) ::ag::log::write(::ag::log::Level::kWarn, comp, __VA_ARGS__)
#define AG_LOG_ERROR(comp, ...) ::ag::log::write(::ag::log::Level::kError, comp, __VA_ARGS__)
