// The simulator's CAN bus: two endpoints joined in-process, each side's sends queued (fixed capacity)
// for the other side's receive, stamped with the shared clock when sent. Single-threaded (the lockstep
// executor runs the robot's stages and the simulated base on one thread).
#pragma once

#include <array>
#include <cstddef>
#include <string_view>

#include "airground/drivers/can/can_bus.hpp"
#include "airground/platform/clock.hpp"

namespace ag::can {

class InProcessCanLink {
 public:
  static constexpr std::size_t kCapacity = 512;  // frames in flight per direction

  explicit InProcessCanLink(const Clock& clock) : a_(*this, 0), b_(*this, 1), clock_(clock) {}
  InProcessCanLink(const InProcessCanLink&) = delete;
  InProcessCanLink& operator=(const InProcessCanLink&) = delete;

  class Endpoint final : public CanBus {
   public:
    Endpoint(InProcessCanLink& link, int side) : link_(link), side_(side) {}
    [[nodiscard]] CanResult send(const CanFrame& f) noexcept override;
    [[nodiscard]] CanResult receive(CanFrame& out) noexcept override;
    [[nodiscard]] const CanBusCounters& counters() const noexcept override { return c_; }
    void set_down(bool down) noexcept { down_ = down; }  // a cut cable: sends fail, nothing arrives

   private:
    friend class InProcessCanLink;
    InProcessCanLink& link_;
    int side_;
    bool down_{false};
    CanBusCounters c_;
  };

  Endpoint& robot() noexcept { return a_; }   // the driver's side
  Endpoint& device() noexcept { return b_; }  // the simulated controllers' side

 private:
  struct Queue {
    std::array<CanFrame, kCapacity> frames{};
    std::size_t head{0}, size{0};
  };
  Endpoint a_, b_;
  const Clock& clock_;
  std::array<Queue, 2> q_{};  // q_[s]: frames waiting for side s
};

// Links the simulator provides for a robot's base stage (can_backend: sim), by robot name.
void register_inprocess_link(std::string_view robot, InProcessCanLink* link);
void unregister_inprocess_link(std::string_view robot);
[[nodiscard]] InProcessCanLink* find_inprocess_link(std::string_view robot);

}  // namespace ag::can
