// The executors: lockstep runs are repeatable bit for bit; the real-time one counts overruns and slips.
#include "test_robot.hpp"
#include "airground/platform/executor.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"

namespace ag {
namespace {

// ------------------------------------------------------------------------------------------ test stages

struct TraceEntry {
  TimeNs t;
  std::string_view stage;
  std::int64_t value;
  bool operator==(const TraceEntry&) const = default;
};
using Trace = std::vector<TraceEntry>;

// Stages pick up the trace to write to in init(), so several robots built one after the other each
// keep their own.
Trace* g_trace = nullptr;

struct ImuSample {
  std::int64_t seq{0};
  TimeNs sample_time_ns{0};  // [ns]
};

Status take_trace(Trace*& out) {
  if (g_trace == nullptr) return Error::make(ErrorCode::kInternal, "test: no trace set");
  out = g_trace;
  return ok_status();
}

// 100 Hz: publishes a numbered sample (latest value) and its time (ring), records its sequence number.
class ImuStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<ImuStage>(); }
  Status init(StageContext& ctx) override {
    name_ = ctx.stage_name;
    auto w = ctx.channels.latest_writer<ImuSample>("imu");
    if (!w) return w.error();
    out_ = w.value();
    auto e = ctx.channels.ring_writer<TimeNs, 64>("imu_events");
    if (!e) return e.error();
    events_ = e.value();
    return take_trace(trace_);
  }
  void step(TimeNs now) noexcept override {
    ++seq_;
    out_.publish(ImuSample{seq_, now});
    (void)events_.push(now);
    trace_->push_back({now, name_, seq_});
  }

 private:
  std::string_view name_;
  LatestWriter<ImuSample> out_;
  RingWriter<TimeNs, 64> events_;
  std::int64_t seq_{0};
  Trace* trace_{nullptr};
};

// 25 Hz: reads the newest sample and drains the event ring; records seq * 1000 + events drained.
class EstimatorStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<EstimatorStage>(); }
  Status init(StageContext& ctx) override {
    name_ = ctx.stage_name;
    auto r = ctx.channels.latest_reader<ImuSample>("imu");
    if (!r) return r.error();
    in_ = r.value();
    auto e = ctx.channels.ring_reader<TimeNs, 64>("imu_events");
    if (!e) return e.error();
    events_ = e.value();
    auto w = ctx.channels.latest_writer<std::int64_t>("estimate");
    if (!w) return w.error();
    out_ = w.value();
    return take_trace(trace_);
  }
  void step(TimeNs now) noexcept override {
    std::int64_t drained = 0;
    while (events_.front() != nullptr) {
      events_.pop();
      ++drained;
    }
    const ImuSample& s = in_.read();
    const std::int64_t v = s.seq * 1000 + drained;
    out_.publish(v);
    trace_->push_back({now, name_, v});
  }

 private:
  std::string_view name_;
  LatestReader<ImuSample> in_;
  RingReader<TimeNs, 64> events_;
  LatestWriter<std::int64_t> out_;
  Trace* trace_{nullptr};
};

// 10 Hz: records the estimate it sees, and checks the clock it was given agrees with `now`.
class PlannerStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<PlannerStage>(); }
  Status init(StageContext& ctx) override {
    name_ = ctx.stage_name;
    clock_ = &ctx.clock;
    auto r = ctx.channels.latest_reader<std::int64_t>("estimate");
    if (!r) return r.error();
    in_ = r.value();
    return take_trace(trace_);
  }
  void step(TimeNs now) noexcept override {
    clock_mismatches_ += clock_->now() != now ? 1 : 0;
    trace_->push_back({now, name_, in_.read() + clock_mismatches_ * 1'000'000'000});
  }

 private:
  std::string_view name_;
  const Clock* clock_{nullptr};
  LatestReader<std::int64_t> in_;
  std::int64_t clock_mismatches_{0};
  Trace* trace_{nullptr};
};

// name, factory, rate [Hz], budget [µs], priority, CPU
constexpr StageSpec kLockstepStages[] = {
    {"imu", &ImuStage::make, 100.0, 500, 30, -1},
    {"estimator", &EstimatorStage::make, 25.0, 2'000, 20, -1},
    {"planner", &PlannerStage::make, 10.0, 5'000, 10, -1},
};
static_assert(role_table_ok(kLockstepStages));
const RoleDescription kLockstepRole{"test", "three stages at three rates sharing two channels", kLockstepStages};

using test::build;
using test::TestRobot;

struct Release {
  TimeNs t;
  std::size_t runnable;
  bool operator==(const Release&) const = default;
};
void record_release(void* user, TimeNs t, std::size_t runnable) {
  static_cast<std::vector<Release>*>(user)->push_back({t, runnable});
}

// One lockstep run: its own clock, robot, executor and traces.
struct LockstepRun {
  SimClock clock;
  Trace trace;
  std::vector<Release> releases;
  std::unique_ptr<TestRobot> built;
  LockstepExecutor ex{clock};

  LockstepRun() {
    trace.reserve(2000);
    g_trace = &trace;
    built = build(kLockstepRole, clock, "r");
    g_trace = nullptr;
    if (built) ex.add(*built->robot);
    ex.set_trace(&record_release, &releases);
    ex.start(0);
  }
};

testing::AssertionResult same_trace(const Trace& a, const Trace& b) {
  if (a.size() != b.size()) return testing::AssertionFailure() << "lengths " << a.size() << " vs " << b.size();
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!(a[i] == b[i]))
      return testing::AssertionFailure() << "entry " << i << ": (" << a[i].t << ", " << a[i].stage << ", " << a[i].value
                                         << ") vs (" << b[i].t << ", " << b[i].stage << ", " << b[i].value << ")";
  return testing::AssertionSuccess();
}

constexpr TimeNs kTenSeconds = 10 * kNsPerS;

// --------------------------------------------------------------------------------------------- lockstep

TEST(LockstepExecutor, TwoIndependentRunsGiveIdenticalTraces) {
  LockstepRun a;
  LockstepRun b;
  ASSERT_TRUE(a.built && b.built);
  // Interleaved in uneven chunks: neither run may depend on the other or on how it was chunked.
  b.ex.run_until(3 * kNsPerS + 7 * kNsPerMs);
  a.ex.run_until(kTenSeconds);
  b.ex.run_until(kTenSeconds);
  ASSERT_FALSE(a.trace.empty());
  EXPECT_TRUE(same_trace(a.trace, b.trace));
  EXPECT_EQ(a.releases, b.releases);
}

TEST(LockstepExecutor, EachStageIsReleasedRateTimesDurationPlusOneTimes) {
  LockstepRun run;
  ASSERT_TRUE(run.built);
  run.ex.run_until(kTenSeconds);
  auto& perf = run.built->robot->perf();
  ASSERT_EQ(perf.size(), 3u);
  EXPECT_EQ(perf.at(0).runs.load(), 1001u);  // 100 Hz for 10 s, plus the release at t0
  EXPECT_EQ(perf.at(1).runs.load(), 251u);
  EXPECT_EQ(perf.at(2).runs.load(), 101u);
  EXPECT_EQ(run.trace.size(), 1001u + 251u + 101u);
  EXPECT_EQ(run.releases.size(), run.trace.size());
  EXPECT_EQ(perf.at(0).exec.count(), 1001u);
  EXPECT_EQ(perf.at(0).slips.load(), 0u);
}

TEST(LockstepExecutor, StagesAtOneInstantRunInTableOrderAndTimeNeverGoesBack) {
  LockstepRun run;
  ASSERT_TRUE(run.built);
  run.ex.run_until(kTenSeconds);
  for (std::size_t i = 1; i < run.releases.size(); ++i) {
    const Release& p = run.releases[i - 1];
    const Release& c = run.releases[i];
    ASSERT_TRUE(c.t > p.t || (c.t == p.t && c.runnable > p.runnable)) << "release " << i;
  }
  EXPECT_EQ(run.releases.front(), (Release{0, 0}));
  EXPECT_EQ(run.releases.back().t, kTenSeconds);
}

TEST(LockstepExecutor, ReaderSeesWhatTheWriterPublishedEarlierInTheSameInstant) {
  LockstepRun run;
  ASSERT_TRUE(run.built);
  run.ex.run_until(kTenSeconds);
  int checked = 0;
  for (const TraceEntry& e : run.trace) {
    if (e.stage != "estimator") continue;
    const std::int64_t k = e.t / (40 * kNsPerMs);
    const std::int64_t imu_seq = 4 * k + 1;         // imu ran at 0, 10, ..., t ms, before the estimator
    const std::int64_t drained = k == 0 ? 1 : 4;    // the ring carried every sample since the last step
    ASSERT_EQ(e.value, imu_seq * 1000 + drained) << "t=" << e.t;
    ++checked;
  }
  EXPECT_EQ(checked, 251);
  // The planner (10 Hz) sees the estimator's latest estimate (from its last release at or before the
  // planner's instant), and the clock it was given matched `now` every time.
  for (const TraceEntry& e : run.trace) {
    if (e.stage != "planner") continue;
    const TimeNs te = e.t / (40 * kNsPerMs) * (40 * kNsPerMs);
    const std::int64_t imu_seq = te / (10 * kNsPerMs) + 1;
    const std::int64_t drained = te == 0 ? 1 : 4;
    ASSERT_EQ(e.value, imu_seq * 1000 + drained) << "t=" << e.t;
  }
}

TEST(LockstepExecutor, RunUntilLeavesTheClockAtTheEndAndTheNextReleasePending) {
  LockstepRun run;
  ASSERT_TRUE(run.built);
  run.ex.run_until(kTenSeconds + 5 * kNsPerMs);
  EXPECT_EQ(run.clock.now(), kTenSeconds + 5 * kNsPerMs);
  EXPECT_EQ(run.ex.next_release(), kTenSeconds + 10 * kNsPerMs);
  EXPECT_EQ(run.ex.runnables().size(), 3u);
}

// Robots side by side (set_parallel): each robot's trace is the serial run's, the jobs really run on
// other threads, and `after` follows every release time on the caller.
struct ThreadedJobs {
  std::size_t batches{0}, jobs{0}, afters{0};
  std::thread::id caller{std::this_thread::get_id()};
  bool after_off_caller{false};
};
void run_on_threads(void* user, std::size_t n, LockstepExecutor::JobFn job, void* job_user) {
  auto& u = *static_cast<ThreadedJobs*>(user);
  ++u.batches;
  u.jobs += n;
  std::vector<std::thread> ts;
  for (std::size_t j = n; j-- > 0;) ts.emplace_back([=] { job(job_user, j); });  // started in reverse order
  for (auto& t : ts) t.join();
}
void count_after(void* user) {
  auto& u = *static_cast<ThreadedJobs*>(user);
  ++u.afters;
  if (std::this_thread::get_id() != u.caller) u.after_off_caller = true;
}

TEST(LockstepExecutor, RobotsSideBySideGiveEachRobotsSerialTrace) {
  auto two = [](bool parallel, ThreadedJobs& jobs, Trace& ta, Trace& tb) {
    SimClock clock;
    ta.reserve(2000);
    tb.reserve(2000);
    g_trace = &ta;
    auto a = build(kLockstepRole, clock, "a");
    g_trace = &tb;
    auto b = build(kLockstepRole, clock, "b");
    g_trace = nullptr;
    EXPECT_TRUE(a && b);
    if (!a || !b) return;
    LockstepExecutor ex(clock);
    ex.add(*a->robot);
    ex.add(*b->robot);
    if (parallel) ex.set_parallel(&run_on_threads, &count_after, &jobs);
    ex.start(0);
    ex.run_until(2 * kNsPerS);
  };
  ThreadedJobs serial_jobs, par_jobs;
  Trace sa, sb, pa, pb;
  two(false, serial_jobs, sa, sb);
  two(true, par_jobs, pa, pb);
  ASSERT_EQ(sa.size(), 201u + 51u + 21u);
  EXPECT_TRUE(same_trace(sa, pa));
  EXPECT_TRUE(same_trace(sb, pb));
  EXPECT_TRUE(same_trace(sa, sb)) << "two copies of one robot";
  EXPECT_EQ(serial_jobs.batches, 0u);
  EXPECT_EQ(par_jobs.batches, 201u) << "one batch per release time (both robots due at every 100 Hz release)";
  EXPECT_EQ(par_jobs.jobs, 2u * 201u);
  EXPECT_EQ(par_jobs.afters, 201u);
  EXPECT_FALSE(par_jobs.after_off_caller);
}

TEST(LockstepExecutor, StartsAtAnyEpoch) {
  SimClock clock;
  Trace trace;
  g_trace = &trace;
  auto built = build(kLockstepRole, clock, "late");
  g_trace = nullptr;
  ASSERT_TRUE(built);
  LockstepExecutor ex(clock);
  ex.add(*built->robot);
  const TimeNs t0 = 1'700'000'000 * kNsPerS;
  ex.start(t0);
  ex.run_until(t0 + kNsPerS);
  EXPECT_EQ(built->robot->perf().at(0).runs.load(), 101u);
  EXPECT_EQ(trace.front().t, t0);
}

TEST(LockstepExecutor, SeveralRobotsRunInRobotThenTableOrder) {
  SimClock clock;
  Trace ta;
  Trace tb;
  g_trace = &ta;
  auto a = build(kLockstepRole, clock, "a");
  g_trace = &tb;
  auto b = build(kLockstepRole, clock, "b");
  g_trace = nullptr;
  ASSERT_TRUE(a && b);
  LockstepExecutor ex(clock);
  ex.add(*a->robot);
  ex.add(*b->robot);
  std::vector<Release> rel;
  ex.set_trace(&record_release, &rel);
  ex.start(0);
  ex.run_until(0);
  ASSERT_EQ(rel.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) EXPECT_EQ(rel[i].runnable, i);
  EXPECT_EQ(std::string(ex.runnables()[3].name), "imu");  // robot b's first stage comes after robot a's
  ex.run_until(kNsPerS);
  EXPECT_TRUE(same_trace(ta, tb));  // two robots with the same table, same inputs, same trace
}

// -------------------------------------------------------------------------------------------- real-time

// Spins on the monotonic clock: 20 ms of work every step, far over its 1 ms budget.
class BusyStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<BusyStage>(); }
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs) noexcept override {
    const TimeNs until = monotonic_now() + 20 * kNsPerMs;
    while (monotonic_now() < until) {
    }
  }
};

// Does nearly nothing.
class QuietStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<QuietStage>(); }
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs now) noexcept override { last_ = now; }

 private:
  TimeNs last_{0};
};

// Blocks for 250 ms, more than two periods at 10 Hz (sleeping, to leave the CPU to others).
class SlowStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<SlowStage>(); }
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs) noexcept override { MonotonicClock::sleep_until(monotonic_now() + 250 * kNsPerMs); }
};

constexpr StageSpec kOverrunStages[] = {
    {"busy", &BusyStage::make, 10.0, 1'000, 10, -1},
    {"quiet", &QuietStage::make, 10.0, 40'000, 10, -1},  // same thread, runs after busy
};
static_assert(role_table_ok(kOverrunStages));
const RoleDescription kOverrunRole{"overrun", "a stage far over budget beside a well-behaved one", kOverrunStages};

constexpr StageSpec kSlipStages[] = {
    {"slow", &SlowStage::make, 10.0, 1'000, 10, -1},
};
static_assert(role_table_ok(kSlipStages));
const RoleDescription kSlipRole{"slip", "a stage that takes more than two periods", kSlipStages};

constexpr StageSpec kTwoThreadStages[] = {
    {"fast", &QuietStage::make, 50.0, 1'000, 20, -1},
    {"medium", &QuietStage::make, 20.0, 1'000, 10, -1},
    {"slow", &QuietStage::make, 10.0, 1'000, 10, -1},
};
static_assert(role_table_ok(kTwoThreadStages));
const RoleDescription kTwoThreadRole{"two", "three quiet stages on two threads", kTwoThreadStages};

RealtimeOptions test_options() {
  RealtimeOptions o;
  o.realtime_priority = false;
  o.lock_memory = false;
  o.pin_cpus = false;
  o.start_delay = 5 * kNsPerMs;
  return o;
}

void run_for(RealtimeExecutor& ex, TimeNs duration) {
  auto rep = ex.start();
  ASSERT_TRUE(rep.ok()) << rep.error().message;
  std::this_thread::sleep_for(std::chrono::nanoseconds(duration));
  ex.request_stop();
  ex.join();
}

TEST(RealtimeExecutor, StageOverItsBudgetCountsOverrunsAndItsSiblingDoesNot) {
  MonotonicClock clock;
  auto built = build(kOverrunRole, clock, "rt");
  ASSERT_TRUE(built);
  RealtimeExecutor ex(test_options());
  ex.add(*built->robot);
  run_for(ex, 500 * kNsPerMs);
  const StagePerf& busy = built->robot->perf().at(0);
  const StagePerf& quiet = built->robot->perf().at(1);
  EXPECT_GE(busy.overruns.load(), 2u);
  EXPECT_EQ(busy.overruns.load(), busy.runs.load());  // every 20 ms step is over a 1 ms budget
  EXPECT_GE(busy.exec.min(), 20 * kNsPerMs);
  EXPECT_GT(quiet.runs.load(), 0u);
  EXPECT_EQ(quiet.overruns.load(), 0u);
}

TEST(RealtimeExecutor, StepLongerThanTwoPeriodsCountsSlips) {
  MonotonicClock clock;
  auto built = build(kSlipRole, clock, "rt");
  ASSERT_TRUE(built);
  RealtimeExecutor ex(test_options());
  ex.add(*built->robot);
  run_for(ex, 700 * kNsPerMs);
  const StagePerf& slow = built->robot->perf().at(0);
  EXPECT_GE(slow.runs.load(), 2u);
  EXPECT_GE(slow.slips.load(), 1u);
  EXPECT_EQ(slow.overruns.load(), slow.runs.load());
}

TEST(RealtimeExecutor, EveryStageOfEveryThreadRunsAndStopIsPrompt) {
  MonotonicClock clock;
  auto built = build(kTwoThreadRole, clock, "rt");
  ASSERT_TRUE(built);
  RealtimeExecutor ex(test_options());
  ex.add(*built->robot);
  auto rep = ex.start();
  ASSERT_TRUE(rep.ok()) << rep.error().message;
  EXPECT_EQ(rep.value().threads, 2u);  // one per (priority, CPU)
  EXPECT_EQ(rep.value().fifo_threads, 0u);
  EXPECT_FALSE(rep.value().memory_locked);
  EXPECT_TRUE(rep.value().warnings.empty());
  EXPECT_TRUE(ex.running());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_TRUE(ex.threads_alive(monotonic_now(), kNsPerS));
  const TimeNs asked = monotonic_now();
  ex.request_stop();
  ex.join();
  const TimeNs stopped = monotonic_now();
  EXPECT_FALSE(ex.running());
  // A hang check, not a performance one: threads sleep at most 100 ms between looks at the stop flag.
  EXPECT_LT(stopped - asked, 5 * kNsPerS);
  for (std::size_t i = 0; i < built->robot->perf().size(); ++i) {
    const StagePerf& p = built->robot->perf().at(i);
    EXPECT_GT(p.runs.load(), 0u) << p.name;
  }
}

TEST(RealtimeExecutor, StartRefusesAnEmptyExecutorAndASecondStart) {
  {
    RealtimeExecutor empty(test_options());
    auto rep = empty.start();
    ASSERT_FALSE(rep.ok());
    EXPECT_EQ(rep.error().code, ErrorCode::kInvalidArgument);
  }
  MonotonicClock clock;
  auto built = build(kTwoThreadRole, clock, "rt");
  ASSERT_TRUE(built);
  RealtimeExecutor ex(test_options());
  ex.add(*built->robot);
  ASSERT_TRUE(ex.start().ok());
  auto again = ex.start();
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, ErrorCode::kInvalidArgument);
  ex.request_stop();
  ex.join();
}

TEST(RealtimeExecutor, DestructorStopsRunningThreads) {
  MonotonicClock clock;
  auto built = build(kTwoThreadRole, clock, "rt");
  ASSERT_TRUE(built);
  {
    RealtimeExecutor ex(test_options());
    ex.add(*built->robot);
    ASSERT_TRUE(ex.start().ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }  // ~RealtimeExecutor requests stop and joins before the robot goes away
  SUCCEED();
}

}  // namespace
}  // namespace ag
