// The simulator's camera (the camera stage's `source: sim`): the simulated camera's frames handed to the
// robot's camera stage in-process, as 640x400 RGB images (the classes only in the labels oracle). The
// simulator's world stage fills a slot and commits it; the stage takes frames in order; the lockstep
// executor never runs the two at once.
//
// Invariants: the slots are allocated once, at construction; begin_frame(), commit(), front() and pop()
// never allocate or block; a frame that finds every slot taken is dropped and counted, as a V4L2 driver
// drops a frame no buffer is queued for.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "airground/messages/messages.hpp"

namespace ag::camera {

class SimCameraLink {
 public:
  explicit SimCameraLink(std::size_t capacity = 2);
  SimCameraLink(const SimCameraLink&) = delete;
  SimCameraLink& operator=(const SimCameraLink&) = delete;
  // The camera's side: the slot to fill with the next frame, or null when all are taken (counted).
  [[nodiscard]] CameraImageMsg* begin_frame() noexcept;
  // The slot begin_frame() gave is a frame now.
  void commit() noexcept;
  // The stage's side: the oldest frame, or null; pop() releases it.
  [[nodiscard]] const CameraImageMsg* front() const noexcept;
  void pop() noexcept;
  [[nodiscard]] std::uint64_t frames() const noexcept { return frames_; }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_; }

 private:
  std::vector<std::unique_ptr<CameraImageMsg>> slots_;
  std::size_t head_{0}, size_{0};
  bool open_{false};  // begin_frame() handed out the slot after the queued ones
  std::uint64_t frames_{0}, dropped_{0};
};

// Links the simulator provides for its robots' camera stages, by robot name; false when taken.
[[nodiscard]] bool register_sim_camera(std::string_view robot, SimCameraLink* link);
void unregister_sim_camera(std::string_view robot);
[[nodiscard]] SimCameraLink* find_sim_camera(std::string_view robot);

}  // namespace ag::camera
