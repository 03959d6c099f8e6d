// CameraPrefetch: the next camera frame, rendered ahead (see camera_prefetch.hpp).
#include "camera_prefetch.hpp"

#include "airground/platform/clock.hpp"

namespace ag::sim {

CameraPrefetch::~CameraPrefetch() {
  stop_requested_.store(true, std::memory_order_relaxed);
  {
    std::lock_guard<std::mutex> lk(mu_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void CameraPrefetch::start(const Pose3& pose, TimeNs stamp) {
  {
    std::lock_guard<std::mutex> lk(mu_);
    pose_ = pose;
    stamp_ = stamp;
    done_ = 0;
    active_ = true;
    ++generation_;
    // Last, releasing: a thread still looping in help() from the frame before may take a band of this
    // one straight away, and then sees the pose and the prepared frame.
    next_.store(0, std::memory_order_release);
  }
  wake_.notify_all();
}

void CameraPrefetch::help() noexcept {
  for (int b = next_.fetch_add(1, std::memory_order_acq_rel); b < kBands; b = next_.fetch_add(1, std::memory_order_acq_rel)) {
    if (stop_requested_.load(std::memory_order_relaxed)) return;  // shutting down: the frame is dropped
    const TimeNs c0 = thread_cpu_now();
    const int h = frame_.rgb.rows;
    camera_.render_rows(pose_, h * b / kBands, h * (b + 1) / kBands, frame_);
    cpu_.fetch_add(thread_cpu_now() - c0, std::memory_order_relaxed);
    std::lock_guard<std::mutex> lk(mu_);
    if (++done_ == kBands) finished_.notify_all();
  }
}

void CameraPrefetch::finish() {
  help();
  std::unique_lock<std::mutex> lk(mu_);
  finished_.wait(lk, [&] { return done_ >= kBands; });
  active_ = false;
}

void CameraPrefetch::loop() {
  std::uint64_t seen = 0;
  for (;;) {
    {
      std::unique_lock<std::mutex> lk(mu_);
      wake_.wait(lk, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
    }
    help();
  }
}

}  // namespace ag::sim
