// recording.mcap's counter channels: the radio's traffic (/radio) and the scheduler's stage counters
// (/scheduler), in JSON with JSON schemas of our own ("airground.RadioTraffic",
// "airground.SchedulerCounters"): Foxglove publishes no schema for counters (foxglove.Log is text and
// cannot be plotted), and a jsonschema channel of our own is what its Plot and Raw Messages panels read
// with no plugin. Same encoding as the foxglove schemas (jsonschema + json).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "airground/sim/radio.hpp"

namespace ag {
class RoleInstance;
}

namespace ag::sim {

// The JSON Schema text of a schema the recording uses: Foxglove's published ones (foxglove_json.hpp)
// and our own counter schemas above; empty for an unknown name.
[[nodiscard]] const std::string& recording_schema(std::string_view name);

// One robot's radio traffic as its comms stage counts it.
struct RobotTraffic {
  std::string robot;
  std::uint64_t datagrams_out{0}, bytes_out{0}, datagrams_in{0}, bytes_in{0}, records_out{0}, records_in{0}, send_failures{0};
};

// airground.RadioTraffic: the simulated radio's totals (`link`, zeros without a radio) and per robot.
[[nodiscard]] std::string radio_traffic(std::uint64_t t_ns, const LinkStats* link, const std::vector<RobotTraffic>& robots);
// The comms stage's counters of each role (roles without one are left out).
[[nodiscard]] std::vector<RobotTraffic> robot_traffic(const std::vector<std::pair<std::string, RoleInstance*>>& roles);

// airground.SchedulerCounters: every stage of every role (runs, overruns, slips, step time p50/p99/max).
[[nodiscard]] std::string scheduler_counters(std::uint64_t t_ns, const std::vector<std::pair<std::string, RoleInstance*>>& roles);

}  // namespace ag::sim
