// Executors: the real-time thread groups and the lockstep loop share run_measured().
#include "airground/platform/executor.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <barrier>
#include <cstring>
#include <limits>

#include "airground/platform/log.hpp"

namespace ag {

namespace {
TimeNs timer_now(ExecTimer t) noexcept { return t == ExecTimer::kThreadCpu ? thread_cpu_now() : monotonic_now(); }

void append(std::vector<Runnable>& runs, RoleInstance& robot) {
  for (std::size_t i = 0; i < robot.stages().size(); ++i) {
    StageSlot& slot = robot.stages()[i];
    Runnable r{slot.stage.get(), slot.perf, slot.perf->name.c_str(), period_from_hz(slot.spec->rate_hz),
               static_cast<TimeNs>(slot.spec->budget_us) * kNsPerUs, slot.spec->priority, slot.spec->cpu};
    r.channels = &robot.channels();
    r.stage_index = i;
    runs.push_back(r);
  }
}

// One step's counters: `exec` is what the budget is held to, `host` this machine's time for it.
void record_step(Runnable& r, TimeNs exec, TimeNs host, TimeNs lateness) noexcept {
  StagePerf& p = *r.perf;
  p.exec.record(exec);
  p.exec_total.store(p.exec_total.load(std::memory_order_relaxed) + host, std::memory_order_relaxed);
  p.lateness.record(lateness);
  p.count(p.runs);
  if (exec > r.budget) p.count(p.overruns);
}
}  // namespace

void run_measured(Runnable& r, TimeNs now, TimeNs lateness, ExecTimer timer) noexcept {
  const TimeNs a = timer_now(timer);
  r.stage->step(now);
  const TimeNs exec = timer_now(timer) - a;
  (void)r.stage->take_work();  // only the lockstep compute-time model reads it
  record_step(r, exec, exec, lateness);
}

// ---------------------------------------------------------------------------------------------- lockstep

void LockstepExecutor::add(RoleInstance& robot) {
  append(runs_, robot);
  ++lanes_;
  lane_of_.resize(runs_.size(), lanes_);
}

void LockstepExecutor::add_stage(Stage& stage, StagePerf& perf, double rate_hz) {
  perf.period_ns = period_from_hz(rate_hz);
  if (perf.budget_ns <= 0) perf.budget_ns = perf.period_ns;
  runs_.push_back(Runnable{&stage, &perf, perf.name.c_str(), perf.period_ns, perf.budget_ns, 0, -1});
  lane_of_.push_back(0);
}

void LockstepExecutor::start(TimeNs t0) noexcept {
  clock_.set(t0);
  for (auto& r : runs_) {
    r.next_release = t0;
    r.busy_until = t0;
    r.finish = Runnable::kNever;
  }
  lane_runs_.assign(lanes_ + 1, {});
  for (std::size_t i = 0; i < runs_.size(); ++i) lane_runs_[lane_of_[i]].push_back(i);
  due_.reserve(lanes_);
}

void LockstepExecutor::run_lane(std::size_t lane, TimeNs t) noexcept {
  for (const std::size_t i : lane_runs_[lane]) {
    Runnable& r = runs_[i];
    if (r.next_release != t) continue;
    run_measured(r, t, 0, timer_);
    r.next_release += r.period;
  }
}

TimeNs LockstepExecutor::next_release() const noexcept {
  TimeNs t = std::numeric_limits<TimeNs>::max();
  for (const auto& r : runs_) t = std::min(t, r.next_release);
  return t;
}

void LockstepExecutor::run_until(TimeNs t_end) noexcept {
  if (cost_ != nullptr) {
    run_until_timed(t_end);
    return;
  }
  const bool parallel = parallel_ != nullptr && trace_ == nullptr && lane_runs_.size() == lanes_ + 1;
  for (;;) {
    const TimeNs t = next_release();
    if (t > t_end) break;
    clock_.set(t);
    if (parallel) {
      run_lane(0, t);
      due_.clear();
      for (std::size_t lane = 1; lane <= lanes_; ++lane)
        for (const std::size_t i : lane_runs_[lane])
          if (runs_[i].next_release == t) {
            due_.push_back(lane);
            break;
          }
      batch_t_ = t;
      if (due_.size() == 1) {
        run_lane(due_[0], t);
      } else if (!due_.empty()) {
        parallel_(parallel_user_, due_.size(), [](void* self, std::size_t job) noexcept {
          auto* ex = static_cast<LockstepExecutor*>(self);
          ex->run_lane(ex->due_[job], ex->batch_t_);
        }, this);
      }
      if (after_ != nullptr) after_(parallel_user_);
      continue;
    }
    for (std::size_t i = 0; i < runs_.size(); ++i) {
      Runnable& r = runs_[i];
      if (r.next_release != t) continue;
      if (trace_ != nullptr) trace_(trace_user_, t, i);
      run_measured(r, t, 0, timer_);
      r.next_release += r.period;
    }
  }
  clock_.set(t_end);
}

// ------------------------------------------------------------------------------- lockstep, compute time

TimeNs LockstepExecutor::next_event() const noexcept {
  TimeNs t = Runnable::kNever;
  for (const auto& r : runs_) t = std::min({t, std::max(r.next_release, r.busy_until), r.finish});
  return t;
}

void LockstepExecutor::release_finished(TimeNs t) noexcept {
  for (auto& r : runs_) {
    if (r.finish > t) continue;
    r.channels->release_outputs(r.stage_index);
    r.finish = Runnable::kNever;
  }
}

void LockstepExecutor::step_timed(std::size_t i, TimeNs t) noexcept {
  Runnable& r = runs_[i];
  TimeNs late = t - r.next_release;
  if (late >= r.period) {  // whole releases missed while the thread was busy: count them, serve the newest
    const TimeNs missed = late / r.period;
    r.perf->count(r.perf->slips, static_cast<std::uint64_t>(missed));
    r.next_release += missed * r.period;
    late = t - r.next_release;
  }
  const bool robot = r.channels != nullptr;
  if (robot) r.channels->hold_outputs(r.stage_index);
  const TimeNs a = timer_now(timer_);
  r.stage->step(t);
  const TimeNs host = timer_now(timer_) - a;
  const double work = r.stage->take_work();
  const TimeNs cost = robot ? std::max<TimeNs>(0, cost_(cost_user_, i, work, host)) : 0;
  record_step(r, robot ? cost : host, host, late);
  r.busy_until = t + cost;
  if (robot) {
    if (cost == 0) r.channels->release_outputs(r.stage_index);
    else r.finish = t + cost;
  }
  r.next_release += r.period;
}

void LockstepExecutor::run_lane_timed(std::size_t lane, TimeNs t) noexcept {
  for (const std::size_t i : lane_runs_[lane])
    if (std::max(runs_[i].next_release, runs_[i].busy_until) == t) step_timed(i, t);
}

void LockstepExecutor::run_until_timed(TimeNs t_end) noexcept {
  const bool parallel = parallel_ != nullptr && trace_ == nullptr && lane_runs_.size() == lanes_ + 1;
  for (;;) {
    const TimeNs t = next_event();
    if (t > t_end) break;
    clock_.set(t);
    release_finished(t);  // what finished now is visible to everything that starts now
    if (!parallel) {
      for (std::size_t i = 0; i < runs_.size(); ++i) {
        if (std::max(runs_[i].next_release, runs_[i].busy_until) != t) continue;
        if (trace_ != nullptr) trace_(trace_user_, t, i);
        step_timed(i, t);
      }
      continue;
    }
    run_lane_timed(0, t);
    due_.clear();
    for (std::size_t lane = 1; lane <= lanes_; ++lane)
      for (const std::size_t i : lane_runs_[lane])
        if (std::max(runs_[i].next_release, runs_[i].busy_until) == t) {
          due_.push_back(lane);
          break;
        }
    batch_t_ = t;
    if (due_.size() == 1) {
      run_lane_timed(due_[0], t);
    } else if (!due_.empty()) {
      parallel_(parallel_user_, due_.size(), [](void* self, std::size_t job) noexcept {
        auto* ex = static_cast<LockstepExecutor*>(self);
        ex->run_lane_timed(ex->due_[job], ex->batch_t_);
      }, this);
    }
    if (after_ != nullptr) after_(parallel_user_);
  }
  clock_.set(t_end);
}

// --------------------------------------------------------------------------------------------- real-time

struct RealtimeExecutor::Group {
  int priority;
  int cpu;
  std::vector<std::size_t> members;  // indices into runs_, table order
  char thread_name[16]{};
  std::atomic<TimeNs> heartbeat{0};
  int sched_rc{0};
  int affinity_rc{0};
  bool fifo{false};
  bool pinned{false};
  std::barrier<>* gate{nullptr};
};

RealtimeExecutor::RealtimeExecutor(RealtimeOptions opts) : opts_(opts) {}

RealtimeExecutor::~RealtimeExecutor() {
  request_stop();
  join();
}

void RealtimeExecutor::add(RoleInstance& robot) { append(runs_, robot); }

void RealtimeExecutor::thread_main(Group& g) noexcept {
  pthread_setname_np(pthread_self(), g.thread_name);
  if (opts_.pin_cpus && g.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<std::size_t>(g.cpu), &set);
    g.affinity_rc = g.cpu < CPU_SETSIZE ? pthread_setaffinity_np(pthread_self(), sizeof set, &set) : EINVAL;
    g.pinned = g.affinity_rc == 0;
  }
  if (opts_.realtime_priority) {
    sched_param sp{};
    sp.sched_priority = g.priority;
    g.sched_rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    g.fifo = g.sched_rc == 0;
  }
  {
    // Touch the stack the stages will use so that, with mlockall, no page fault happens in step().
    volatile char prefault[64 * 1024];
    for (std::size_t i = 0; i < sizeof prefault; i += 4096) prefault[i] = 0;
  }
  g.gate->arrive_and_wait();  // set-up done
  g.gate->arrive_and_wait();  // released
  const TimeNs t0 = t0_.load(std::memory_order_acquire);
  for (std::size_t idx : g.members) runs_[idx].next_release = t0;
  g.heartbeat.store(t0, std::memory_order_relaxed);
  MonotonicClock::sleep_until(t0);

  constexpr TimeNs kMaxSleep = 100 * kNsPerMs;  // bounded so a stop request is seen promptly
  while (!stop_.load(std::memory_order_acquire)) {
    TimeNs now = monotonic_now();
    TimeNs earliest = std::numeric_limits<TimeNs>::max();
    for (std::size_t idx : g.members) {
      Runnable& r = runs_[idx];
      if (now >= r.next_release) {
        TimeNs late = now - r.next_release;
        if (late >= r.period) {  // whole releases missed: count them and serve the newest
          const TimeNs missed = late / r.period;
          r.perf->count(r.perf->slips, static_cast<std::uint64_t>(missed));
          r.next_release += missed * r.period;
          late = now - r.next_release;
        }
        run_measured(r, now, late, opts_.timer);
        r.next_release += r.period;
        now = monotonic_now();
      }
      earliest = std::min(earliest, r.next_release);
    }
    g.heartbeat.store(now, std::memory_order_relaxed);
    MonotonicClock::sleep_until(std::min(earliest, now + kMaxSleep));
  }
}

Result<RealtimeReport> RealtimeExecutor::start() {
  if (!threads_.empty()) return Error::make(ErrorCode::kInvalidArgument, "executor already started");
  if (runs_.empty()) return Error::make(ErrorCode::kInvalidArgument, "executor has no stages to run");
  RealtimeReport rep;
  if (opts_.lock_memory) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      rep.memory_locked = true;
    } else {
      rep.warnings.push_back(std::string("memory not locked (mlockall: ") + std::strerror(errno) +
                             "): page faults may add latency; grant CAP_IPC_LOCK or LimitMEMLOCK=infinity");
    }
  }
  for (std::size_t i = 0; i < runs_.size(); ++i) {
    const Runnable& r = runs_[i];
    auto it = std::find_if(groups_.begin(), groups_.end(),
                           [&](const auto& g) { return g->priority == r.priority && g->cpu == r.cpu; });
    if (it == groups_.end()) {
      auto g = std::make_unique<Group>();
      g->priority = r.priority;
      g->cpu = r.cpu;
      char name[40]{};
      if (r.cpu >= 0) std::snprintf(name, sizeof name, "ag-p%d-c%d", r.priority, r.cpu);
      else std::snprintf(name, sizeof name, "ag-p%d", r.priority);
      std::memcpy(g->thread_name, name, sizeof g->thread_name - 1);  // the kernel keeps 15 characters
      groups_.push_back(std::move(g));
      it = groups_.end() - 1;
    }
    (*it)->members.push_back(i);
  }
  const long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
  gate_ = std::make_unique<std::barrier<>>(static_cast<std::ptrdiff_t>(groups_.size() + 1));
  for (auto& g : groups_) {
    g->gate = gate_.get();
    if (opts_.pin_cpus && g->cpu >= ncpu)
      rep.warnings.push_back("thread " + std::string(g->thread_name) + ": CPU " + std::to_string(g->cpu) +
                             " is not online (this machine has " + std::to_string(ncpu) + "); left unpinned");
    threads_.emplace_back([this, gp = g.get()] { thread_main(*gp); });
  }
  gate_->arrive_and_wait();
  rep.threads = groups_.size();
  int sched_err = 0;
  for (const auto& g : groups_) {
    if (g->fifo) ++rep.fifo_threads;
    else if (opts_.realtime_priority) sched_err = g->sched_rc;
    if (g->pinned) ++rep.pinned_threads;
  }
  if (opts_.realtime_priority && rep.fifo_threads < groups_.size())
    rep.warnings.push_back(std::string("running without real-time priority (SCHED_FIFO: ") + std::strerror(sched_err) +
                           "): deadlines may slip under load; grant CAP_SYS_NICE or LimitRTPRIO=98");
  t0_.store(monotonic_now() + opts_.start_delay, std::memory_order_release);
  gate_->arrive_and_wait();
  for (const auto& w : rep.warnings) AG_LOG_WARN("scheduler", "%s", w.c_str());
  return rep;
}

void RealtimeExecutor::request_stop() noexcept { stop_.store(true, std::memory_order_release); }

void RealtimeExecutor::join() noexcept {
  for (auto& t : threads_)
    if (t.joinable()) t.join();
  threads_.clear();
}

bool RealtimeExecutor::threads_alive(TimeNs now, TimeNs max_silence) const noexcept {
  for (const auto& g : groups_)
    if (now - g->heartbeat.load(std::memory_order_relaxed) > max_silence) return false;
  return true;
}

}  // namespace ag
