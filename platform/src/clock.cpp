// Clock implementations on clock_gettime/clock_nanosleep.
#include "airground/platform/clock.hpp"

#include <cerrno>
#include <ctime>

namespace ag {

namespace {
TimeNs read_clock(clockid_t id) noexcept {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerS + ts.tv_nsec;
}
}  // namespace

TimeNs monotonic_now() noexcept { return read_clock(CLOCK_MONOTONIC); }
TimeNs thread_cpu_now() noexcept { return read_clock(CLOCK_THREAD_CPUTIME_ID); }
TimeNs MonotonicClock::now() const noexcept { return monotonic_now(); }

void MonotonicClock::sleep_until(TimeNs deadline) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline / kNsPerS);
  ts.tv_nsec = static_cast<long>(deadline % kNsPerS);
  clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

}  // namespace ag
