// Logging: a bounded multi-producer queue (Vyukov) of fixed-size records and one writer thread.
#include "airground/platform/log.hpp"

#include <unistd.h>

#include <array>
#include <cerrno>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <mutex>
#include <thread>

#include "airground/platform/cacheline.hpp"

namespace ag::log {
namespace {

struct Record {
  std::int64_t wall_ns;
  Level level;
  char component[23];
  char text[224];
};

// Bounded MPMC queue: each cell carries a sequence number that says whose turn it is.
class RecordQueue {
 public:
  static constexpr std::size_t kCapacity = 1024;
  RecordQueue() {
    for (std::size_t i = 0; i < kCapacity; ++i) cells_[i].seq.store(i, std::memory_order_relaxed);
  }
  bool push(const Record& r) noexcept {
    std::size_t pos = enq_.load(std::memory_order_relaxed);
    for (;;) {
      Cell& c = cells_[pos & (kCapacity - 1)];
      const std::size_t seq = c.seq.load(std::memory_order_acquire);
      const auto diff = static_cast<std::ptrdiff_t>(seq) - static_cast<std::ptrdiff_t>(pos);
      if (diff == 0) {
        if (enq_.compare_exchange_weak(pos, pos + 1, std::memory_order_relaxed)) {
          c.rec = r;
          c.seq.store(pos + 1, std::memory_order_release);
          return true;
        }
      } else if (diff < 0) {
        return false;
      } else {
        pos = enq_.load(std::memory_order_relaxed);
      }
    }
  }
  bool pop(Record& out) noexcept {
    std::size_t pos = deq_.load(std::memory_order_relaxed);
    for (;;) {
      Cell& c = cells_[pos & (kCapacity - 1)];
      const std::size_t seq = c.seq.load(std::memory_order_acquire);
      const auto diff = static_cast<std::ptrdiff_t>(seq) - static_cast<std::ptrdiff_t>(pos + 1);
      if (diff == 0) {
        if (deq_.compare_exchange_weak(pos, pos + 1, std::memory_order_relaxed)) {
          out = c.rec;
          c.seq.store(pos + kCapacity, std::memory_order_release);
          return true;
        }
      } else if (diff < 0) {
        return false;
      } else {
        pos = deq_.load(std::memory_order_relaxed);
      }
    }
  }

 private:
  struct Cell {
    std::atomic<std::size_t> seq;
    Record rec;
  };
  std::array<Cell, kCapacity> cells_;
  alignas(kFalseSharingRange) std::atomic<std::size_t> enq_{0};
  alignas(kFalseSharingRange) std::atomic<std::size_t> deq_{0};
};

struct State {
  RecordQueue queue;
  std::atomic<Level> level{Level::kInfo};
  std::atomic<bool> async{false};
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> dropped{0};
  std::atomic<int> fd{2};
  bool journal = std::getenv("JOURNAL_STREAM") != nullptr;
  std::mutex write_mu;  // only the writer side takes it, never a real-time caller
  std::mutex wake_mu;
  std::condition_variable wake;
  std::thread writer;
};

State& state() {
  static State s;
  return s;
}

const char* level_name(Level l) {
  switch (l) {
    case Level::kDebug: return "debug";
    case Level::kInfo: return "info ";
    case Level::kWarn: return "warn ";
    case Level::kError: return "error";
  }
  return "?";
}
int syslog_prio(Level l) {
  switch (l) {
    case Level::kDebug: return 7;
    case Level::kInfo: return 6;
    case Level::kWarn: return 4;
    case Level::kError: return 3;
  }
  return 6;
}

void emit(const Record& r) {
  State& s = state();
  char line[320];
  const std::time_t secs = static_cast<std::time_t>(r.wall_ns / 1'000'000'000);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  int n = 0;
  if (s.journal) n = std::snprintf(line, sizeof line, "<%d>", syslog_prio(r.level));
  n += std::snprintf(line + n, sizeof line - static_cast<std::size_t>(n),
                     "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ %s %s: %s\n", tm.tm_year + 1900, tm.tm_mon + 1,
                     tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                     static_cast<int>((r.wall_ns / 1'000'000) % 1000), level_name(r.level), r.component, r.text);
  if (n > static_cast<int>(sizeof line) - 1) {
    n = static_cast<int>(sizeof line) - 1;
    line[n - 1] = '\n';
  }
  const int fd = s.fd.load(std::memory_order_relaxed);
  std::size_t off = 0;
  while (off < static_cast<std::size_t>(n)) {
    const ssize_t w = ::write(fd, line + off, static_cast<std::size_t>(n) - off);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) break;
    off += static_cast<std::size_t>(w);
  }
}

void drain() {
  State& s = state();
  std::lock_guard lk(s.write_mu);
  Record r;
  while (s.queue.pop(r)) emit(r);
  const std::uint64_t d = s.dropped.exchange(0, std::memory_order_relaxed);
  if (d != 0) {
    Record note{};
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    note.wall_ns = ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
    note.level = Level::kWarn;
    std::snprintf(note.component, sizeof note.component, "log");
    std::snprintf(note.text, sizeof note.text, "queue full: dropped=%llu lines", static_cast<unsigned long long>(d));
    emit(note);
  }
}

std::atomic<std::uint64_t> g_total_dropped{0};

}  // namespace

void vwrite(Level level, const char* component, const char* fmt, va_list ap) noexcept {
  State& s = state();
  if (level < s.level.load(std::memory_order_relaxed)) return;
  Record r;
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  r.wall_ns = ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
  r.level = level;
  std::snprintf(r.component, sizeof r.component, "%s", component);
  std::vsnprintf(r.text, sizeof r.text, fmt, ap);
  if (!s.async.load(std::memory_order_acquire)) {
    std::lock_guard lk(s.write_mu);
    emit(r);
    return;
  }
  if (!s.queue.push(r)) {
    s.dropped.fetch_add(1, std::memory_order_relaxed);
    g_total_dropped.fetch_add(1, std::memory_order_relaxed);
  }
  if (level >= Level::kWarn) s.wake.notify_one();
}

void write(Level level, const char* component, const char* fmt, ...) noexcept {
  va_list ap;
  va_start(ap, fmt);
  vwrite(level, component, fmt, ap);
  va_end(ap);
}

void set_level(Level l) noexcept { state().level.store(l, std::memory_order_relaxed); }
Level level() noexcept { return state().level.load(std::memory_order_relaxed); }
bool parse_level(std::string_view t, Level& out) noexcept {
  if (t == "debug") out = Level::kDebug;
  else if (t == "info") out = Level::kInfo;
  else if (t == "warn") out = Level::kWarn;
  else if (t == "error") out = Level::kError;
  else return false;
  return true;
}

void start_writer() {
  State& s = state();
  if (s.writer.joinable()) return;
  s.stop.store(false);
  s.async.store(true, std::memory_order_release);
  s.writer = std::thread([&s] {
    while (!s.stop.load(std::memory_order_acquire)) {
      {
        std::unique_lock lk(s.wake_mu);
        s.wake.wait_for(lk, std::chrono::milliseconds(50));
      }
      drain();
    }
    drain();
  });
}

void stop_writer() noexcept {
  State& s = state();
  if (!s.writer.joinable()) return;
  s.stop.store(true, std::memory_order_release);
  s.wake.notify_one();
  s.writer.join();
  s.async.store(false, std::memory_order_release);
  drain();
}

void flush() noexcept { drain(); }
std::uint64_t dropped() noexcept { return g_total_dropped.load(std::memory_order_relaxed); }
void set_fd(int fd) noexcept { state().fd.store(fd, std::memory_order_relaxed); }

}  // namespace ag::log
