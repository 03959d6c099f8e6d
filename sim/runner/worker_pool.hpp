// A small pool of worker threads for the simulator's sensor jobs; results stay deterministic because
// every job writes only its own output and the caller consumes them in a fixed order.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace ag::sim {

class WorkerPool {
 public:
  explicit WorkerPool(int threads);  // threads <= 1: everything runs on the caller
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;
  // Runs fn(0..jobs-1) across the workers and the calling thread; returns when all are done.
  void run(std::size_t jobs, const std::function<void(std::size_t)>& fn);
  [[nodiscard]] int size() const noexcept { return static_cast<int>(threads_.size()) + 1; }

 private:
  void work_loop();
  void drain();
  std::vector<std::thread> threads_;
  std::mutex mu_;
  std::condition_variable wake_, done_;
  const std::function<void(std::size_t)>* fn_{nullptr};
  std::size_t jobs_{0};
  std::atomic<std::size_t> next_{0};
  std::size_t busy_{0};
  std::uint64_t generation_{0};
  bool stop_{false};
};

}  // namespace ag::sim
