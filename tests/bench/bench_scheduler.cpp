// bench_scheduler: wake-up lateness of ag::RealtimeExecutor at 10 Hz and 100 Hz, read from the stage's
// own StagePerf histogram, next to a plain clock_nanosleep(TIMER_ABSTIME) loop measured the same way
// (same rate, duration, priority and histogram, at the same time), so the figure is relative to what
// the kernel gives.
#include <pthread.h>
#include <sched.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/perf_counters.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/stage.hpp"
#include "airground/platform/time.hpp"
#include "bench_common.hpp"

namespace {

using ag::TimeNs;

constexpr int kPriority = 50;  // SCHED_FIFO priority of the stage thread and of the reference loop
constexpr TimeNs kStartDelay = 20 * ag::kNsPerMs;
constexpr double kGoalP99Us = 1000.0;

// The trivial stage: remembers the release time, nothing else.
class TickStage final : public ag::Stage {
 public:
  ag::Status init(ag::StageContext& /*ctx*/) override { return ag::ok_status(); }
  void step(TimeNs now) noexcept override {
    last_ = now;
    steps_ = steps_ + 1;
  }
  static std::unique_ptr<ag::Stage> make() { return std::make_unique<TickStage>(); }

 private:
  TimeNs last_{0};
  volatile std::uint64_t steps_{0};
};

// name, factory, rate [Hz], budget [µs], SCHED_FIFO priority, CPU (-1 any), parameters, what it does
constexpr ag::StageSpec kTick10Hz[] = {
    {"tick", &TickStage::make, 10.0, 100, kPriority, -1, {}, "does nothing, 10 times a second"},
};
constexpr ag::StageSpec kTick100Hz[] = {
    {"tick", &TickStage::make, 100.0, 100, kPriority, -1, {}, "does nothing, 100 times a second"},
};
static_assert(ag::role_table_ok(kTick10Hz));
static_assert(ag::role_table_ok(kTick100Hz));

const ag::RoleDescription kRole10Hz{"bench10", "scheduler bench: one trivial stage at 10 Hz", kTick10Hz, {}};
const ag::RoleDescription kRole100Hz{"bench100", "scheduler bench: one trivial stage at 100 Hz", kTick100Hz, {}};

struct Lateness {
  TimeNs p50{0}, p99{0}, max{0};
  std::uint64_t count{0};
  std::uint64_t slips{0};
  bool fifo{false};
  bool mlocked{false};
  bool ok{false};
};

Lateness summarise(const ag::DurationHistogram& h) {
  Lateness l;
  l.p50 = h.quantile(0.5);
  l.p99 = h.quantile(0.99);
  l.max = h.max();
  l.count = h.count();
  l.ok = true;
  return l;
}

// The reference: a thread sleeping to absolute deadlines with clock_nanosleep, nothing else. Same
// priority request, same histogram, same policy for whole missed periods as the executor.
class RawLoop {
 public:
  RawLoop(double rate_hz, TimeNs t0, double seconds) : period_(ag::period_from_hz(rate_hz)), t0_(t0),
                                                       end_(t0 + ag::from_seconds(seconds)) {
    thread_ = std::thread([this] { run(); });
  }
  RawLoop(const RawLoop&) = delete;
  RawLoop& operator=(const RawLoop&) = delete;
  ~RawLoop() {
    if (thread_.joinable()) thread_.join();
  }
  Lateness finish(bool mlocked) {
    thread_.join();
    Lateness out = summarise(*hist_);
    out.slips = slips_;
    out.fifo = fifo_;
    out.mlocked = mlocked;
    return out;
  }

 private:
  void run() noexcept {
    sched_param sp{};
    sp.sched_priority = kPriority;
    fifo_ = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
    for (TimeNs next = t0_; next < end_;) {
      ag::MonotonicClock::sleep_until(next);  // clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)
      const TimeNs now = ag::monotonic_now();
      TimeNs late = now - next;
      if (late >= period_) {  // count whole missed periods, serve the newest
        const TimeNs missed = late / period_;
        slips_ += static_cast<std::uint64_t>(missed);
        next += missed * period_;
        late = now - next;
      }
      hist_->record(late);
      next += period_;
    }
  }

  TimeNs period_, t0_, end_;
  std::unique_ptr<ag::DurationHistogram> hist_ = std::make_unique<ag::DurationHistogram>();
  std::uint64_t slips_{0};
  bool fifo_{false};
  std::thread thread_;
};

struct Pair {
  Lateness executor;
  Lateness raw;
};

// The executor with the bench role at the role's rate for `seconds`, and the reference loop at the same
// time, its releases half a period after the executor's: both see the same spell of machine noise, and
// their wake-ups do not coincide.
Pair run_pair(const ag::RoleDescription& role, double seconds) {
  Pair out;
  const ag::Config config = ag::Config::defaults(ag::role_schema(role));
  ag::MonotonicClock clock;
  auto robot = ag::RoleInstance::create(role, config, clock, "bench");
  if (!robot) {
    std::fprintf(stderr, "bench_scheduler: %s\n", robot.error().message.c_str());
    return out;
  }
  ag::RealtimeOptions opts;
  opts.realtime_priority = true;
  opts.lock_memory = true;
  opts.start_delay = kStartDelay;
  ag::RealtimeExecutor exec(opts);
  exec.add(*robot.value());
  const TimeNs period = ag::period_from_hz(role.stages[0].rate_hz);
  const TimeNs before = ag::monotonic_now();  // the executor's first release is kStartDelay after start()
  auto started = exec.start();
  if (!started) {
    std::fprintf(stderr, "bench_scheduler: executor did not start: %s\n", started.error().message.c_str());
    return out;
  }
  const ag::RealtimeReport& rep = started.value();
  RawLoop raw(role.stages[0].rate_hz, before + kStartDelay + period / 2, seconds);
  // Releases happen at t0, t0 + P, ...; stop half a period before the one after the last counted.
  std::this_thread::sleep_for(std::chrono::nanoseconds(kStartDelay + ag::from_seconds(seconds) - period / 2));
  exec.request_stop();
  exec.join();
  robot.value()->stop_all();

  const ag::StagePerf& perf = *robot.value()->stages()[0].perf;
  out.executor = summarise(perf.lateness);
  out.executor.slips = perf.slips.load(std::memory_order_relaxed);
  out.executor.fifo = rep.threads > 0 && rep.fifo_threads == rep.threads;
  out.executor.mlocked = rep.memory_locked;
  out.raw = raw.finish(rep.memory_locked);
  return out;
}

const char* yes_no(bool b) { return b ? "yes" : "no"; }

void report(double rate_hz, double seconds, const Lateness& ex, const Lateness& raw) {
  const int hz = static_cast<int>(rate_hz);
  if (!ex.ok) {
    std::printf("scheduler wake-up lateness at %d Hz: not measured (executor failed)\n", hz);
    return;
  }
  std::printf("scheduler wake-up lateness at %d Hz: p50 %.1f us, p99 %.1f us, max %.1f us (%llu releases; "
              "SCHED_FIFO %s, mlockall %s) goal p99 < %.0f us%s\n",
              hz, ag::to_us(ex.p50), ag::to_us(ex.p99), ag::to_us(ex.max), static_cast<unsigned long long>(ex.count),
              yes_no(ex.fifo), yes_no(ex.mlocked), kGoalP99Us, ag::to_us(ex.p99) < kGoalP99Us ? " [met]" : " [NOT met]");
  if (ex.slips != 0) std::printf("  executor slips (whole periods missed): %llu\n", static_cast<unsigned long long>(ex.slips));
  const double ratio = raw.p99 > 0 ? static_cast<double>(ex.p99) / static_cast<double>(raw.p99) : 0.0;
  std::printf("  reference clock_nanosleep(TIMER_ABSTIME) loop at %d Hz, same %.1f s: p50 %.1f us, p99 %.1f us, max %.1f us "
              "(%llu wake-ups; SCHED_FIFO %s, mlockall %s)%s; executor p99 / raw p99 = %.2f\n",
              hz, seconds, ag::to_us(raw.p50), ag::to_us(raw.p99), ag::to_us(raw.max),
              static_cast<unsigned long long>(raw.count), yes_no(raw.fifo), yes_no(raw.mlocked),
              raw.slips != 0 ? (", " + std::to_string(raw.slips) + " slips").c_str() : "", ratio);
  std::fflush(stdout);

  char line[512];
  std::snprintf(line, sizeof line,
                "{\"bench\":\"scheduler\",\"rate_hz\":%d,\"seconds\":%.2f,\"releases\":%llu,\"p50_us\":%.2f,"
                "\"p99_us\":%.2f,\"max_us\":%.2f,\"slips\":%llu,\"sched_fifo\":%s,\"mlockall\":%s,"
                "\"raw_p50_us\":%.2f,\"raw_p99_us\":%.2f,\"raw_max_us\":%.2f,\"raw_sched_fifo\":%s,"
                "\"p99_ratio_to_raw\":%.3f}",
                hz, seconds, static_cast<unsigned long long>(ex.count), ag::to_us(ex.p50), ag::to_us(ex.p99),
                ag::to_us(ex.max), static_cast<unsigned long long>(ex.slips), ex.fifo ? "true" : "false",
                ex.mlocked ? "true" : "false", ag::to_us(raw.p50), ag::to_us(raw.p99), ag::to_us(raw.max),
                raw.fifo ? "true" : "false", ratio);
  const std::string out = ag::bench::append_result_line(line);
  if (!out.empty()) std::printf("  appended to %s\n", out.c_str());
}

void usage(const char* argv0) {
  std::printf(
      "usage: %s [--seconds S] [--quick] [--help]\n"
      "  Runs ag::RealtimeExecutor with one trivial stage at 10 Hz, then at 100 Hz, and prints the\n"
      "  stage's wake-up lateness (release to start of step) p50/p99/max from its StagePerf histogram;\n"
      "  alongside each, a plain clock_nanosleep(TIMER_ABSTIME) loop on its own thread at the same rate,\n"
      "  for the same time (releases offset by half a period), as an in-process reference. SCHED_FIFO\n"
      "  (priority %d) and mlockall are requested and used when permitted (CAP_SYS_NICE /\n"
      "  CAP_IPC_LOCK, or LimitRTPRIO / LimitMEMLOCK); otherwise it warns and runs without them.\n"
      "  --seconds S   run each measurement S seconds (default 10 s at 10 Hz, 3 s at 100 Hz)\n"
      "  --quick       halve the durations\n"
      "  AG_BENCH_OUT=<file> appends one JSON line per rate.\n",
      argv0, kPriority);
}

}  // namespace

int main(int argc, char** argv) {
  double s10 = 10.0;
  double s100 = 3.0;
  bool quick = false;
  for (int i = 1; i < argc; ++i) {
    const std::string_view a = argv[i];
    if (a == "--help" || a == "-h") {
      usage(argv[0]);
      return 0;
    }
    if (a == "--quick") {
      quick = true;
    } else if (a == "--seconds") {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "--seconds needs a value\n");
        return 2;
      }
      char* end = nullptr;
      const double s = std::strtod(argv[++i], &end);
      if (end == argv[i] || *end != '\0' || !(s > 0.0 && s <= 3600.0)) {
        std::fprintf(stderr, "--seconds: expected a number of seconds in (0, 3600], got '%s'\n", argv[i]);
        return 2;
      }
      s10 = s100 = s;
    } else {
      std::fprintf(stderr, "unknown argument '%s'\n", argv[i]);
      usage(argv[0]);
      return 2;
    }
  }
  if (quick) {
    s10 *= 0.5;
    s100 *= 0.5;
  }
  std::printf("scheduler bench: %.1f s at 10 Hz, then %.1f s at 100 Hz; a raw clock_nanosleep loop runs alongside "
              "each (releases offset by half a period); %zu CPUs available, threads unpinned\n",
              s10, s100, ag::bench::allowed_cpus().size());
  std::fflush(stdout);

  int rc = 0;
  {
    const Pair p = run_pair(kRole10Hz, s10);
    report(10.0, s10, p.executor, p.raw);
    if (!p.executor.ok) rc = 1;
  }
  {
    const Pair p = run_pair(kRole100Hz, s100);
    report(100.0, s100, p.executor, p.raw);
    if (!p.executor.ok) rc = 1;
  }
  return rc;
}
