// The two executors: real-time threads from the role table, and a deterministic lockstep one.
#pragma once

#include <atomic>
#include <barrier>
#include <cstddef>
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
};

// Measures one step and updates its counters; shared by both executors.
void run_measured(Runnable& r, TimeNs now, TimeNs lateness, ExecTimer timer) noexcept;

// Single thread, simulated clock, stages of all robots in (robot, table) order at each release time:
// the same inputs give the same trace, bit for bit, and it runs as fast as the CPU allows.
class LockstepExecutor {
 public:
  using TraceFn = void (*)(void* user, TimeNs t, std::size_t runnable);

  explicit LockstepExecutor(SimClock& clock, ExecTimer timer = ExecTimer::kThreadCpu) : clock_(clock), timer_(timer) {}
  void add(RoleInstance& robot);
  // A stage outside any role table (the simulator's world, sensors and vehicles). It runs before the
  // robots' stages that share its release time when added first. `perf` must outlive the executor.
  void add_stage(Stage& stage, StagePerf& perf, double rate_hz);
  void start(TimeNs t0) noexcept;
  // Run every release with time <= t_end, then leave the clock at t_end.
  void run_until(TimeNs t_end) noexcept;
  [[nodiscard]] TimeNs next_release() const noexcept;
  void set_trace(TraceFn fn, void* user) noexcept { trace_ = fn; trace_user_ = user; }
  [[nodiscard]] const std::vector<Runnable>& runnables() const noexcept { return runs_; }

 private:
  SimClock& clock_;
  ExecTimer timer_;
  std::vector<Runnable> runs_;
  TraceFn trace_{nullptr};
  void* trace_user_{nullptr};
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
