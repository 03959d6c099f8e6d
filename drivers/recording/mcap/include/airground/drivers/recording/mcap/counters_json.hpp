// airground's own JSON schema for the scheduler's counters ("airground.SchedulerCounters"), where Foxglove
// publishes none (foxglove.Log is text a Plot panel cannot draw), and its message encoder: one
// definition for the robots' recorder stage and the simulator's recording, so one Foxglove layout plots both.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace ag::foxglove {

inline constexpr std::string_view kSchedulerCountersSchema = "airground.SchedulerCounters";

// One stage's counters (cumulative) as a message carries them.
struct StageCounters {
  std::string_view robot, stage;
  std::uint64_t runs{0}, overruns{0}, slips{0};
  double exec_p50_us{0}, exec_p99_us{0}, exec_max_us{0}, budget_us{0};  // [us]
};

// The JSON Schema text of airground.SchedulerCounters (encoding "jsonschema").
[[nodiscard]] const std::string& scheduler_counters_schema();
// A JSON title + $comment + properties object of our own schemas: `props` is "\"key\":{...},..." text.
[[nodiscard]] std::string own_schema(std::string_view title, std::string_view description, std::string_view props);
// The message: {"timestamp":{sec,nsec},"stages":[...]} for log time t_ns.
[[nodiscard]] std::string scheduler_counters_json(std::uint64_t t_ns, std::span<const StageCounters> stages);

}  // namespace ag::foxglove
