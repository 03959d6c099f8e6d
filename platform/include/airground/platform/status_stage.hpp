// The status stage: once a period, publishes the scheduler's counters for this robot and logs them.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>

#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"

namespace ag {

// Published on the latest-value channel "scheduler_status"; the gossip stage will carry it to the team.
struct SchedulerStatus {
  static constexpr std::size_t kMaxStages = 32;
  struct StageLine {
    std::array<char, 24> name{};
    std::uint64_t runs{0};
    std::uint64_t overruns{0};
    std::uint64_t slips{0};
    float exec_p50_us{0}, exec_p99_us{0}, exec_max_us{0};  // [µs]
    float late_p99_us{0};                                   // [µs] wake-up lateness
    float budget_us{0};                                     // [µs]
    // A device stage's own counters (device_unit empty for the others).
    std::array<char, 20> device_unit{};                     // "frames", "fixes", "images", "samples"
    float device_rate_hz{0};                                // [1/s] units over the last report period
    std::uint64_t device_complete{0}, device_incomplete{0};
    std::uint64_t device_errors{0};                         // decode errors, all kinds
    std::uint64_t device_bytes{0};
  };
  TimeNs sample_time_ns{0};   // [ns] when the counters were read
  TimeNs publish_time_ns{0};  // [ns]
  std::uint32_t seq{0};
  std::uint32_t stage_count{0};
  std::uint64_t total_overruns{0};
  std::uint64_t total_slips{0};
  std::array<StageLine, kMaxStages> stages{};
};

namespace chan {
// status stage -> the recorder (declared here, not in messages/channels.hpp: platform sees nothing above).
inline constexpr LatestTopic<SchedulerStatus> kSchedulerStatus{"scheduler_status"};
}  // namespace chan

struct StatusSettings {
  bool log_counters{true};
  std::int64_t log_every{10};  // [reports]
};
inline constexpr ParamField<StatusSettings> kStatusStageFields[] = {
    field::boolean("log_counters", &StatusSettings::log_counters, "write one line per stage on every report"),
    field::integer("log_every", &StatusSettings::log_every, 1, 3600, "reports", "log the full table every N reports; problems are logged at once"),
};
inline constexpr auto kStatusStageParams = param_specs(kStatusStageFields);

class StatusStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kStatusStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<StatusStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  [[nodiscard]] const SchedulerStatus& last() const noexcept { return msg_; }

 private:
  void log_device(std::size_t i, const SchedulerStatus::StageLine& l) const noexcept;
  const PerfRegistry* perf_{nullptr};
  const Clock* clock_{nullptr};
  LatestWriter<SchedulerStatus> out_;
  SchedulerStatus msg_{};
  StatusSettings cfg_{};
  std::uint64_t reported_overruns_{0};
  std::uint64_t reported_slips_{0};
  std::array<std::uint64_t, SchedulerStatus::kMaxStages> prev_units_{};
  TimeNs prev_sample_{0};
};

}  // namespace ag
