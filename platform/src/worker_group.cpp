// WorkerGroup: workers apply their placement at start, then wait for a run's generation and claim items.
#include "airground/platform/worker_group.hpp"

#include <pthread.h>
#include <sched.h>

#include <atomic>
#include <cerrno>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

namespace ag {

struct WorkerGroup::Shared {
  explicit Shared(WorkerPlacement p) : want(p) {}
  void work(int thread) noexcept;
  void drain(int thread) noexcept;

  const WorkerPlacement want;
  std::vector<std::thread> workers;
  std::mutex m;
  std::condition_variable start_cv, done_cv;
  // Set-up, under m: workers that have applied their placement, how many got each part, the last refusal.
  int ready{0}, fifo{0}, pinned{0}, sched_rc{0}, affinity_rc{0};
  // One run, under m: its generation, workers not yet done with it, what it runs.
  std::uint64_t generation{0};
  int pending{0};
  bool stop{false};
  ItemFn fn{nullptr};
  void* ctx{nullptr};
  int items{0};
  std::atomic<int> next{0};  // the next unclaimed item
};

WorkerGroup::WorkerGroup(int threads, WorkerPlacement placement)
    : threads_(threads > 1 ? threads : 1), s_(std::make_unique<Shared>(placement)) {
  const int n = threads_ - 1;
  s_->workers.reserve(static_cast<std::size_t>(n));
  for (int t = 1; t <= n; ++t) s_->workers.emplace_back([s = s_.get(), t] { s->work(t); });
  std::unique_lock<std::mutex> lk(s_->m);
  s_->start_cv.wait(lk, [&] { return s_->ready == n; });
  const bool fifo_asked = placement.priority != 0, pin_asked = placement.cpu >= 0;
  report_.fifo_applied = fifo_asked && s_->fifo == n;
  report_.pinned = pin_asked && s_->pinned == n;
  if (fifo_asked && !report_.fifo_applied)
    report_.warning = "workers without real-time priority (SCHED_FIFO " + std::to_string(placement.priority) + ": " +
                      std::strerror(s_->sched_rc) + "): grant CAP_SYS_NICE or LimitRTPRIO=98";
  if (pin_asked && !report_.pinned)
    report_.warning += std::string(report_.warning.empty() ? "" : "; ") + "workers not pinned to CPU " +
                       std::to_string(placement.cpu) + " (" + std::strerror(s_->affinity_rc) + ")";
}

WorkerGroup::~WorkerGroup() {
  {
    std::lock_guard<std::mutex> lk(s_->m);
    s_->stop = true;
  }
  s_->start_cv.notify_all();
  for (auto& w : s_->workers) w.join();
}

void WorkerGroup::run(int items, ItemFn fn, void* ctx) noexcept {
  Shared& s = *s_;
  if (s.workers.empty() || items <= 1) {
    for (int i = 0; i < items; ++i) fn(ctx, i, 0);
    return;
  }
  {
    std::lock_guard<std::mutex> lk(s.m);
    s.fn = fn;
    s.ctx = ctx;
    s.items = items;
    s.next.store(0, std::memory_order_relaxed);
    s.pending = static_cast<int>(s.workers.size());
    ++s.generation;
  }
  s.start_cv.notify_all();
  s.drain(0);
  std::unique_lock<std::mutex> lk(s.m);
  s.done_cv.wait(lk, [&] { return s.pending == 0; });
}

void WorkerGroup::Shared::drain(int thread) noexcept {
  for (int i = next.fetch_add(1, std::memory_order_relaxed); i < items; i = next.fetch_add(1, std::memory_order_relaxed))
    fn(ctx, i, thread);
}

void WorkerGroup::Shared::work(int thread) noexcept {
  char name[16];
  std::snprintf(name, sizeof name, "ag-w%d-p%d", thread % 100, want.priority % 100);
  pthread_setname_np(pthread_self(), name);
  int a_rc = 0, s_rc = 0;
  if (want.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    if (want.cpu < CPU_SETSIZE) CPU_SET(static_cast<std::size_t>(want.cpu), &set);
    a_rc = want.cpu < CPU_SETSIZE ? pthread_setaffinity_np(pthread_self(), sizeof set, &set) : EINVAL;
  }
  if (want.priority != 0) {
    sched_param sp{};
    sp.sched_priority = want.priority;
    s_rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  }
  {
    std::lock_guard<std::mutex> lk(m);
    if (want.cpu >= 0 && a_rc == 0) ++pinned;
    if (want.priority != 0 && s_rc == 0) ++fifo;
    if (a_rc != 0) affinity_rc = a_rc;
    if (s_rc != 0) sched_rc = s_rc;
    ++ready;
  }
  start_cv.notify_all();  // the constructor waits for every worker's placement
  std::uint64_t seen = 0;
  for (;;) {
    {
      std::unique_lock<std::mutex> lk(m);
      start_cv.wait(lk, [&] { return stop || generation != seen; });
      if (stop) return;
      seen = generation;
    }
    drain(thread);
    std::lock_guard<std::mutex> lk(m);
    if (--pending == 0) done_cv.notify_one();
  }
}

}  // namespace ag
