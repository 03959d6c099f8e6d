// The quadrotor's next camera frame rendered ahead on a thread of its own (the lockstep team runner).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>

#include "airground/messages/geometry.hpp"
#include "airground/platform/time.hpp"
#include "airground/sim/camera.hpp"

namespace ag::sim {

// The quadrotor's next camera frame, rendered ahead on a thread of its own. The survey flight takes no
// input from the robots, so a copy of the vehicle stepped like the world stage steps it gives the pose
// of the next exposure bit for bit; the frame renders while the robots' stages and the LiDAR run, and
// fills the core a long keyframe step leaves idle. When the frame is due, whatever bands are left are
// rendered by whoever gets there (the world stage's pool jobs), so it is never later than rendering
// it then; the pose is checked before use, and the image is the one a render at that instant gives.
class CameraPrefetch {
 public:
  static constexpr int kBands = 25;  // 16 rows each at 640x400: fine enough to share out at the end

  CameraPrefetch(const CameraRenderer& camera, CameraFrame& frame) : camera_(camera), frame_(frame), thread_([this] { loop(); }) {}
  ~CameraPrefetch();
  CameraPrefetch(const CameraPrefetch&) = delete;
  CameraPrefetch& operator=(const CameraPrefetch&) = delete;

  // Starts the frame of `pose` at `stamp` (the caller has prepared frame_ for it; the last one finished).
  void start(const Pose3& pose, TimeNs stamp);
  [[nodiscard]] bool active() const noexcept { return active_; }
  [[nodiscard]] bool matches(const Pose3& pose, TimeNs stamp) const noexcept {
    return active_ && stamp == stamp_ && pose.x == pose_.x && pose.y == pose_.y && pose.z == pose_.z && pose.roll == pose_.roll &&
           pose.pitch == pose_.pitch && pose.yaw == pose_.yaw;
  }
  // Renders bands nobody has taken yet, on the calling thread.
  void help() noexcept;
  // Helps, then waits for the bands others are still rendering: the frame is complete on return.
  void finish();
  [[nodiscard]] TimeNs cpu_ns() const noexcept { return cpu_.load(std::memory_order_relaxed); }

 private:
  void loop();

  const CameraRenderer& camera_;
  CameraFrame& frame_;
  std::mutex mu_;
  std::condition_variable wake_, finished_;
  Pose3 pose_;
  TimeNs stamp_{0};
  std::atomic<int> next_{kBands};
  int done_{kBands};
  bool active_{false};
  bool stop_{false};
  std::atomic<bool> stop_requested_{false};
  std::uint64_t generation_{0};
  std::atomic<TimeNs> cpu_{0};
  std::thread thread_;  // last: starts once everything above exists
};

}  // namespace ag::sim
