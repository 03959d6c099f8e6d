// The quadrotor's mapping output recorded once and replayed into its comms stage (docs/simulator.md,
// "Quadrotor replay"). The quadrotor's flight and mapping take no input from the ground robots, so a
// study's missions on one world, seed and altitude share one recording: each replayed mission flies the
// quadrotor (its radio moves) and runs its comms stage, which gets at each step exactly the map tiles and
// region batches the live mapping stages had made visible to it by then.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/comms/messages.hpp"
#include "airground/messages/messages.hpp"
#include "airground/mission/messages.hpp"
#include "airground/platform/channels.hpp"
#include "airground/platform/stage.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/world.hpp"

namespace ag::sim {

// The cache key of a run's quadrotor: this executable, the world's layers and every option that reaches
// the quadrotor's flight, sensors and stages. Two runs with one key map identically.
[[nodiscard]] std::uint64_t uav_replay_key(const RunOptions& opt, const World& w);

class UavRecordReader;

// The replayed quadrotor's mapping stages, in its table just before its comms stage and at its rate:
// at each step it writes every recorded message that was visible to comms at that step. Its regions
// (as the regions stage's published()) serve the mission's observer.
class UavReplayStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<UavReplayStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  // Set by the runner before the first step.
  void attach(UavRecordReader* reader) noexcept { reader_ = reader; }
  [[nodiscard]] const mission::RegionsMsg& published() const noexcept { return *regions_; }
  // The recorded run's final ortho-map (the quadrotor's map for the report and its class accuracy).
  [[nodiscard]] Result<mapping::MapRaster> final_map() const;
  [[nodiscard]] std::uint64_t tiles_written() const noexcept { return tiles_; }
  [[nodiscard]] std::uint64_t batches_written() const noexcept { return batches_; }
  [[nodiscard]] std::uint64_t ring_full() const noexcept { return ring_full_; }  // steps a full ring held a record back

 private:
  UavRecordReader* reader_{nullptr};
  RingWriter<MapTileMsg, kMapTileRing> tiles_out_{};
  RingWriter<comms::GossipPublishMsg, comms::kGossipRing> gossip_out_{};
  std::unique_ptr<MapTileMsg> tile_{};                  // scratch: one record's body
  std::unique_ptr<comms::GossipPublishMsg> gossip_{};
  std::unique_ptr<mission::RegionsMsg> regions_{std::make_unique<mission::RegionsMsg>()};
  std::uint64_t tiles_{0}, batches_{0}, ring_full_{0};
};

}  // namespace ag::sim
