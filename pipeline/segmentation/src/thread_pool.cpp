// ErfNet's worker pool (see thread_pool.hpp).
#include "thread_pool.hpp"

namespace ag::seg::detail {

ThreadPool::ThreadPool(int threads) {
  for (int t = 1; t < threads; ++t) workers_.emplace_back([this, t] { work(t); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lk(m_);
    stop_ = true;
  }
  start_cv_.notify_all();
  for (auto& w : workers_) w.join();
}

void ThreadPool::drain(int thread) noexcept {
  for (int i = next_.fetch_add(1, std::memory_order_relaxed); i < items_; i = next_.fetch_add(1, std::memory_order_relaxed))
    fn_(ctx_, i, thread);
}

void ThreadPool::run(int items, ItemFn fn, void* ctx) noexcept {
  if (workers_.empty() || items <= 1) {
    for (int i = 0; i < items; ++i) fn(ctx, i, 0);
    return;
  }
  {
    std::lock_guard<std::mutex> lk(m_);
    fn_ = fn;
    ctx_ = ctx;
    items_ = items;
    next_.store(0, std::memory_order_relaxed);
    pending_ = static_cast<int>(workers_.size());
    ++generation_;
  }
  start_cv_.notify_all();
  drain(0);
  std::unique_lock<std::mutex> lk(m_);
  done_cv_.wait(lk, [this] { return pending_ == 0; });
}

void ThreadPool::work(int thread) noexcept {
  std::uint64_t seen = 0;
  for (;;) {
    {
      std::unique_lock<std::mutex> lk(m_);
      start_cv_.wait(lk, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
    }
    drain(thread);
    std::lock_guard<std::mutex> lk(m_);
    if (--pending_ == 0) done_cv_.notify_one();
  }
}

}  // namespace ag::seg::detail
