// The two executors: real-time threads from the role table, and a deterministic lockstep one.
#pragma once

#include <atomic>
#include <barrier>
#include <cstddef>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "airground/platform/clock.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/role_instance.hpp"

namespace ag {

// Which clock measures a step: wall time on the robot (a preempted step is still late), thread CPU
// time in timing tests on shared machines.
enum class ExecTimer { kMonotonic, kThreadCpu };

struct Runnable {
  Stage* stage;
  StagePerf* perf;
  const char* name;
  TimeNs period;
  TimeNs budget;
  int priority;
  int cpu;
  TimeNs next_release{0};
  // Lockstep compute time: the robot's channels and this stage's index in its table (null channels: a
  // simulator stage, which costs nothing), when its thread is free again and when its held outputs show.
  ChannelRegistry* channels{nullptr};
  std::size_t stage_index{0};
  TimeNs busy_until{0};
  TimeNs finish{kNever};
  static constexpr TimeNs kNever = std::numeric_limits<TimeNs>::max();
};

// Measures one step and updates its counters; shared by both executors.
void run_measured(Runnable& r, TimeNs now, TimeNs lateness, ExecTimer timer) noexcept;

// Simulated clock, stages of all robots in (robot, table) order at each release time: the same inputs
// give the same trace, bit for bit, and it runs as fast as the CPU allows. Single thread by default;
// with set_parallel() the robots of one release time run side by side (see there).
class LockstepExecutor {
 public:
  using TraceFn = void (*)(void* user, TimeNs t, std::size_t runnable);
  using JobFn = void (*)(void* job_user, std::size_t job) noexcept;
  // Runs job(job_user, 0 .. jobs-1), possibly at once on several threads; returns when all are done.
  using ParallelFn = void (*)(void* user, std::size_t jobs, JobFn job, void* job_user);
  using AfterFn = void (*)(void* user);

  explicit LockstepExecutor(SimClock& clock, ExecTimer timer = ExecTimer::kThreadCpu) : clock_(clock), timer_(timer) {}
  void add(RoleInstance& robot);
  // A stage outside any role table (the simulator's world, sensors and vehicles). It runs before the
  // robots' stages that share its release time when added first. `perf` must outlive the executor.
  void add_stage(Stage& stage, StagePerf& perf, double rate_hz);
  void start(TimeNs t0) noexcept;
  // Run every release with time <= t_end, then leave the clock at t_end.
  void run_until(TimeNs t_end) noexcept;
  [[nodiscard]] TimeNs next_release() const noexcept;
  // A trace (tests) runs everything on the caller, in order.
  void set_trace(TraceFn fn, void* user) noexcept { trace_ = fn; trace_user_ = user; }
  // Robots in parallel: at each release time the stages of add_stage() run first, on the caller, in
  // the order added; then every robot with a stage due is one job of `run_jobs` (its due stages in
  // table order); then `after(user)` on the caller. The result equals the serial order's as long as the
  // robots share no mutable state during a release time: the caller defers what crosses between them
  // (radio sends, callbacks) to `after`, in robot order. Call before start(); nullptr run_jobs: serial.
  void set_parallel(ParallelFn run_jobs, AfterFn after, void* user) noexcept {
    parallel_ = run_jobs;
    after_ = after;
    parallel_user_ = user;
  }
  // Compute time (the simulator's model of the robot CPU): a robot stage's step takes
  // cost(user, runnable, work, measured) ns on the target CPU, where `work` is what the stage reported
  // (Stage::take_work) and `measured` its thread CPU time here. Its outputs stay invisible until that
  // time has passed, and its thread is busy until then: a later release starts late, and one a whole
  // period late is skipped (a slip), as the real-time executor does. The exec histogram and overruns
  // count the modelled time; exec_total stays this machine's CPU time. Every robot stage is its own
  // thread (the role tables give each its own priority), each on a core of its own. Call before start().
  using CostFn = TimeNs (*)(void* user, std::size_t runnable, double work, TimeNs measured) noexcept;
  void set_compute_time(CostFn cost, void* user) noexcept {
    cost_ = cost;
    cost_user_ = user;
  }
  [[nodiscard]] const std::vector<Runnable>& runnables() const noexcept { return runs_; }

 private:
  void run_lane(std::size_t lane, TimeNs t) noexcept;
  [[nodiscard]] TimeNs next_event() const noexcept;
  void release_finished(TimeNs t) noexcept;
  void run_lane_timed(std::size_t lane, TimeNs t) noexcept;
  void step_timed(std::size_t i, TimeNs t) noexcept;
  void run_until_timed(TimeNs t_end) noexcept;

  SimClock& clock_;
  ExecTimer timer_;
  std::vector<Runnable> runs_;
  std::vector<std::size_t> lane_of_;              // per runnable: 0 for add_stage(), robot k for the k-th add()
  std::size_t lanes_{0};                          // robots added
  std::vector<std::vector<std::size_t>> lane_runs_;  // built by start(): runnables of each lane, in order
  std::vector<std::size_t> due_;                  // scratch: lanes with a stage due now
  TimeNs batch_t_{0};
  TraceFn trace_{nullptr};
  void* trace_user_{nullptr};
  ParallelFn parallel_{nullptr};
  AfterFn after_{nullptr};
  void* parallel_user_{nullptr};
  CostFn cost_{nullptr};
  void* cost_user_{nullptr};
};

struct RealtimeOptions {
  bool realtime_priority = true;  // SCHED_FIFO when permitted
  bool lock_memory = true;        // mlockall when permitted
  bool pin_cpus = true;           // honour the table's CPU column
  TimeNs start_delay = 20 * kNsPerMs;  // all threads are released together this long after start()
  ExecTimer timer = ExecTimer::kMonotonic;
};

// What start() managed to apply; each refusal is also logged once, with how to grant it.
struct RealtimeReport {
  std::size_t threads{0};
  bool memory_locked{false};
  std::size_t fifo_threads{0};
  std::size_t pinned_threads{0};
  std::vector<std::string> warnings;
};

class RealtimeExecutor {
 public:
  explicit RealtimeExecutor(RealtimeOptions opts = {});
  RealtimeExecutor(const RealtimeExecutor&) = delete;
  RealtimeExecutor& operator=(const RealtimeExecutor&) = delete;
  ~RealtimeExecutor();

  void add(RoleInstance& robot);
  // Spawns one thread per (priority, cpu) group, applies priority/affinity, then releases all
  // threads at one absolute instant.
  Result<RealtimeReport> start();
  void request_stop() noexcept;
  void join() noexcept;
  // True when every thread has looped within max_silence (the watchdog is fed only then).
  [[nodiscard]] bool threads_alive(TimeNs now, TimeNs max_silence) const noexcept;
  [[nodiscard]] bool running() const noexcept { return !threads_.empty(); }

 private:
  struct Group;
  void thread_main(Group& g) noexcept;

  RealtimeOptions opts_;
  std::vector<Runnable> runs_;
  std::vector<std::unique_ptr<Group>> groups_;
  std::vector<std::thread> threads_;
  std::atomic<bool> stop_{false};
  std::atomic<TimeNs> t0_{0};
  std::unique_ptr<std::barrier<>> gate_;  // set-up done, then release; lives as long as the threads
};

}  // namespace ag
