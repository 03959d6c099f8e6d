// airground.SchedulerCounters: schema and message (see counters_json.hpp).
#include "airground/drivers/recording/mcap/counters_json.hpp"

#include "airground/drivers/recording/mcap/foxglove_json.hpp"

namespace ag::foxglove {
namespace {
std::string counter(std::string_view d) { return "{\"type\":\"integer\",\"minimum\":0,\"description\":\"" + std::string(d) + "\"}"; }
std::string number(std::string_view d) { return "{\"type\":\"number\",\"description\":\"" + std::string(d) + "\"}"; }
std::string text(std::string_view d) { return "{\"type\":\"string\",\"description\":\"" + std::string(d) + "\"}"; }
}  // namespace

std::string own_schema(std::string_view title, std::string_view description, std::string_view props) {
  return "{\"title\":\"" + std::string(title) + "\",\"$comment\":\"airground's own schema: Foxglove publishes none for counters\","
         "\"type\":\"object\",\"description\":\"" + std::string(description) + "\",\"properties\":{" + std::string(props) + "}}";
}

const std::string& scheduler_counters_schema() {
  static const std::string s = [] {
    const std::string stage = "{\"type\":\"object\",\"description\":\"One real-time stage\",\"properties\":{\"robot\":" + text("Robot name") +
                              ",\"stage\":" + text("Stage name") + ",\"runs\":" + counter("Steps run") + ",\"overruns\":" +
                              counter("Steps longer than the budget") + ",\"slips\":" + counter("Releases that started late") +
                              ",\"exec_p50_us\":" + number("Step time median [us] (CPU time: not repeatable)") +
                              ",\"exec_p99_us\":" + number("Step time 99th percentile [us]") + ",\"exec_max_us\":" + number("Longest step [us]") +
                              ",\"budget_us\":" + number("Step budget [us]") + "}}";
    return own_schema(kSchedulerCountersSchema, "The scheduler's counters of the robots' stages (cumulative)",
                      "\"timestamp\":{\"type\":\"object\",\"title\":\"time\",\"properties\":{\"sec\":{\"type\":\"integer\",\"minimum\":0},"
                      "\"nsec\":{\"type\":\"integer\",\"minimum\":0,\"maximum\":999999999}},\"description\":\"When the counters were read\"},"
                      "\"stages\":{\"type\":\"array\",\"items\":" + stage + ",\"description\":\"Per robot and stage\"}");
  }();
  return s;
}

std::string scheduler_counters_json(std::uint64_t t_ns, std::span<const StageCounters> stages) {
  std::string s = "{\"timestamp\":{\"sec\":" + std::to_string(t_ns / 1'000'000'000u) + ",\"nsec\":" + std::to_string(t_ns % 1'000'000'000u) +
                  "},\"stages\":[";
  for (std::size_t k = 0; k < stages.size(); ++k) {
    const StageCounters& c = stages[k];
    s += (k == 0 ? "{\"robot\":" : ",{\"robot\":") + json_string(c.robot) + ",\"stage\":" + json_string(c.stage) + ",\"runs\":" +
         std::to_string(c.runs) + ",\"overruns\":" + std::to_string(c.overruns) + ",\"slips\":" + std::to_string(c.slips) +
         ",\"exec_p50_us\":" + json_number(c.exec_p50_us) + ",\"exec_p99_us\":" + json_number(c.exec_p99_us) + ",\"exec_max_us\":" +
         json_number(c.exec_max_us) + ",\"budget_us\":" + json_number(c.budget_us) + "}";
  }
  return s + "]}";
}

}  // namespace ag::foxglove
