// The worker threads a stage (or the simulator) shares its loops with: run(n, fn, ctx) hands items
// 0..n-1 to the caller and the workers and returns when all are done.
#pragma once

#include <cassert>
#include <climits>
#include <cstddef>
#include <memory>
#include <string>
#include <type_traits>

namespace ag {

// Where the workers run: the owning stage's table row when the real-time executor runs it, else {0, -1}.
struct WorkerPlacement {
  int priority{0};  // SCHED_FIFO 1..98; 0 = normal scheduling
  int cpu{-1};      // CPU to pin to; -1 = any (a pinned stage's workers share its CPU: priority, no parallelism)
};

// What the workers applied of their placement; a refusal is reported, never an error.
struct WorkerPlacementReport {
  bool fifo_applied{false};  // every worker runs SCHED_FIFO at the placement's priority (false when none asked)
  bool pinned{false};        // every worker is pinned to the placement's CPU (false when none asked)
  std::string warning;       // empty, or what was refused and how to grant it
};

// Thread 0 is the caller of run(), threads 1..size()-1 the workers. Items are claimed one at a time
// from a shared counter, so which thread runs an item varies from run to run: fn must compute the same
// result on any thread (per-thread scratch indexed by `thread` is fine). Workers start and take their
// placement in the constructor, which waits for them; run() allocates nothing, has one caller at a time
// and, with no workers or one item, runs everything on the caller.
class WorkerGroup {
 public:
  using ItemFn = void (*)(void* ctx, int item, int thread) noexcept;

  // `threads` counts the caller: threads - 1 workers (none for threads <= 1).
  explicit WorkerGroup(int threads, WorkerPlacement placement = {});
  ~WorkerGroup();
  WorkerGroup(const WorkerGroup&) = delete;
  WorkerGroup& operator=(const WorkerGroup&) = delete;

  // Threads that run items, the caller included.
  [[nodiscard]] int size() const noexcept { return threads_; }
  // What the constructor's workers applied of the placement.
  [[nodiscard]] const WorkerPlacementReport& placement() const noexcept { return report_; }

  // fn(ctx, item, thread) once for each item in 0..items-1; returns when all are done.
  void run(int items, ItemFn fn, void* ctx) noexcept;
  // The same for a callable fn(std::size_t item) or fn(std::size_t item, int thread), used in place.
  template <class F>
  void run(std::size_t items, F&& fn) noexcept {
    assert(items <= static_cast<std::size_t>(INT_MAX));
    using Fn = std::remove_reference_t<F>;
    const ItemFn call = [](void* ctx, int item, int thread) noexcept {
      Fn& f = *static_cast<Fn*>(ctx);
      if constexpr (std::is_invocable_v<Fn&, std::size_t, int>) f(static_cast<std::size_t>(item), thread);
      else f(static_cast<std::size_t>(item));
    };
    run(static_cast<int>(items), call, const_cast<void*>(static_cast<const void*>(std::addressof(fn))));
  }

 private:
  struct Shared;  // the workers, their wake-up and the current run

  int threads_;
  WorkerPlacementReport report_;
  std::unique_ptr<Shared> s_;
};

}  // namespace ag
