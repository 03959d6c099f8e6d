// A fixed pool of worker threads for ErfNet's layers: run(n, fn, ctx) hands out items 0..n-1 to the
// caller and the workers and returns when all are done. Threads are started at construction; run()
// allocates nothing (a plain function pointer and context, no std::function).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace ag::seg::detail {

class ThreadPool {
 public:
  using ItemFn = void (*)(void* ctx, int item, int thread) noexcept;

  explicit ThreadPool(int threads);  // threads counts the caller: threads - 1 workers
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  [[nodiscard]] int threads() const noexcept { return static_cast<int>(workers_.size()) + 1; }
  void run(int items, ItemFn fn, void* ctx) noexcept;

 private:
  void work(int thread) noexcept;
  void drain(int thread) noexcept;

  std::vector<std::thread> workers_;
  std::mutex m_;
  std::condition_variable start_cv_, done_cv_;
  std::uint64_t generation_{0};
  int pending_{0};
  bool stop_{false};
  ItemFn fn_{nullptr};
  void* ctx_{nullptr};
  int items_{0};
  std::atomic<int> next_{0};
};

}  // namespace ag::seg::detail
