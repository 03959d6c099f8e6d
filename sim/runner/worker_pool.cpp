// WorkerPool: a generation counter wakes the workers; jobs are claimed with an atomic index.
#include "worker_pool.hpp"

namespace ag::sim {

WorkerPool::WorkerPool(int threads) {
  for (int i = 1; i < threads; ++i) threads_.emplace_back([this] { work_loop(); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard lk(mu_);
    stop_ = true;
  }
  wake_.notify_all();
  for (auto& t : threads_) t.join();
}

void WorkerPool::drain() {
  for (;;) {
    const std::size_t j = next_.fetch_add(1, std::memory_order_relaxed);
    if (j >= jobs_) return;
    (*fn_)(j);
  }
}

void WorkerPool::work_loop() {
  std::uint64_t seen = 0;
  for (;;) {
    {
      std::unique_lock lk(mu_);
      wake_.wait(lk, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
      ++busy_;
    }
    drain();
    {
      std::lock_guard lk(mu_);
      --busy_;
    }
    done_.notify_all();
  }
}

void WorkerPool::run(std::size_t jobs, const std::function<void(std::size_t)>& fn) {
  if (jobs == 0) return;
  {
    std::lock_guard lk(mu_);
    fn_ = &fn;
    jobs_ = jobs;
    next_.store(0, std::memory_order_relaxed);
    ++generation_;
  }
  wake_.notify_all();
  drain();
  std::unique_lock lk(mu_);
  done_.wait(lk, [&] { return busy_ == 0 && next_.load(std::memory_order_relaxed) >= jobs_; });
  fn_ = nullptr;
}

}  // namespace ag::sim
