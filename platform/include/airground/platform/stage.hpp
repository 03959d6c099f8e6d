// The stage interface: init() wires and allocates, step(now) computes within its budget.
#pragma once

#include <string_view>

#include "airground/platform/channels.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/perf_counters.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/time.hpp"
#include "airground/platform/worker_group.hpp"

namespace ag {

// What a stage may use while it starts: its parameters, the channels of its robot, the clock and
// (read-only) the scheduler's counters. Nothing here is valid to re-look-up inside step().
struct StageContext {
  const Config& config;
  ChannelRegistry& channels;
  const Clock& clock;
  const PerfRegistry& perf;
  std::string_view instance;  // the robot this stage belongs to ("uav", "ugv1", ...)
  std::string_view stage_name;
  DeviceCounters* device{nullptr};  // this stage's own device counters (a device stage describes and fills them)
  WorkerPlacement placement{};      // for the workers it starts: its thread's priority and CPU, when real time

  [[nodiscard]] SectionView params() const { return SectionView(config, stage_name); }
};

class Stage {
 public:
  Stage() = default;
  Stage(const Stage&) = delete;
  Stage& operator=(const Stage&) = delete;
  virtual ~Stage() = default;

  // Start-up: read parameters, subscribe and advertise channels, allocate every buffer. An error
  // here stops the robot before it runs, with the message shown to the operator.
  virtual Status init(StageContext& ctx) = 0;
  // One release: must not allocate, must not block, must return within the budget.
  virtual void step(TimeNs now) noexcept = 0;
  // Shutdown, after the last step(): flush what must survive a restart.
  virtual void stop() noexcept {}

  // The work reported since the last call, in the stage's own unit (a frame segmented, a particle
  // update, a keyframe fused): what the simulator's compute-time model charges for a step
  // (docs/simulator.md, "Compute time"). The executor takes it after every step.
  [[nodiscard]] double take_work() noexcept {
    const double w = work_;
    work_ = 0;
    return w;
  }

 protected:
  // step(): this step did `units` of the work its compute-time row counts.
  void add_work(double units) noexcept { work_ += units; }

 private:
  double work_{0};
};

}  // namespace ag
