// The simulator's world as a stage of the lockstep executor: it runs first at each release time and
// writes what the robots' devices would (world_stage.cpp).
#pragma once

#include "airground/platform/stage.hpp"
#include "team.hpp"

namespace ag::sim::lockstep {

// The world side of the lockstep tick: vehicles, odometry, GPS, VO, camera, LiDAR, radio, recording.
class SimWorldStage final : public Stage {
 public:
  explicit SimWorldStage(Team& t) : t_(t) {}
  Status init(StageContext&) override { return ok_status(); }
  void step(TimeNs now) noexcept override;

 private:
  Team& t_;
  TimeNs last_{-1};
};

}  // namespace ag::sim::lockstep
