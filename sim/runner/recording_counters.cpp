// recording.mcap's counter channels (/radio, /scheduler) and their JSON schemas of our own.
#include "recording_counters.hpp"

#include <map>

#include "airground/comms/stage.hpp"
#include "airground/drivers/recording/mcap/counters_json.hpp"
#include "airground/drivers/recording/mcap/foxglove_json.hpp"
#include "airground/platform/perf_counters.hpp"
#include "airground/platform/role_instance.hpp"

namespace ag::sim {
namespace fg = ag::foxglove;

namespace {

std::string counter(std::string_view d) { return "{\"type\":\"integer\",\"minimum\":0,\"description\":\"" + std::string(d) + "\"}"; }
std::string text(std::string_view d) { return "{\"type\":\"string\",\"description\":\"" + std::string(d) + "\"}"; }
std::string object(std::string_view d, const std::vector<std::pair<std::string, std::string>>& props) {
  std::string s = "{\"type\":\"object\",\"description\":\"" + std::string(d) + "\",\"properties\":{";
  for (std::size_t i = 0; i < props.size(); ++i) s += (i ? ",\"" : "\"") + props[i].first + "\":" + props[i].second;
  return s + "}}";
}
std::string top(std::string_view title, std::string_view d, const std::vector<std::pair<std::string, std::string>>& props) {
  std::string p;
  for (std::size_t i = 0; i < props.size(); ++i) p += (i ? ",\"" : "\"") + props[i].first + "\":" + props[i].second;
  return fg::own_schema(title, d, p);
}
const std::string kTime =
    "{\"type\":\"object\",\"title\":\"time\",\"properties\":{\"sec\":{\"type\":\"integer\",\"minimum\":0},"
    "\"nsec\":{\"type\":\"integer\",\"minimum\":0,\"maximum\":999999999}},\"description\":\"Simulated time of the counters\"}";

std::map<std::string, std::string, std::less<>> own_schemas() {
  std::map<std::string, std::string, std::less<>> m;
  const std::string link = object("The simulated radio's totals over every receiver",
                                  {{"sent", counter("Datagrams offered to a receiver")},
                                   {"delivered", counter("Datagrams delivered")},
                                   {"dropped_range", counter("Dropped: out of range")},
                                   {"dropped_loss", counter("Dropped: path loss, shadowing, loss probability")},
                                   {"dropped_queue", counter("Dropped: sender's queue full or oversize")},
                                   {"dropped_collision", counter("Dropped: overlapped by another transmission")},
                                   {"bytes_sent", counter("Payload bytes offered")},
                                   {"bytes_delivered", counter("Payload bytes delivered")}});
  const std::string robot = object("One robot's comms stage counters",
                                   {{"robot", text("Robot name (uav, ugv1, ..., base)")},
                                    {"datagrams_out", counter("Datagrams sent")},
                                    {"bytes_out", counter("Bytes sent")},
                                    {"datagrams_in", counter("Datagrams received")},
                                    {"bytes_in", counter("Bytes received")},
                                    {"records_out", counter("Gossip records sent")},
                                    {"records_in", counter("Gossip records received")},
                                    {"send_failures", counter("Link send failures")}});
  m["airground.RadioTraffic"] =
      top("airground.RadioTraffic", "Radio traffic of a team run: the radio's totals and each robot's comms counters (cumulative)",
          {{"timestamp", kTime}, {"link", link}, {"robots", "{\"type\":\"array\",\"items\":" + robot + ",\"description\":\"Per robot\"}"}});
  m[std::string(fg::kSchedulerCountersSchema)] = fg::scheduler_counters_schema();
  return m;
}

std::string ts(std::uint64_t t_ns) {
  return "{\"sec\":" + std::to_string(t_ns / 1000000000u) + ",\"nsec\":" + std::to_string(t_ns % 1000000000u) + "}";
}

}  // namespace

const std::string& recording_schema(std::string_view name) {
  static const std::map<std::string, std::string, std::less<>> own = own_schemas();
  const auto it = own.find(name);
  return it != own.end() ? it->second : fg::schema(name);
}

std::vector<RobotTraffic> robot_traffic(const std::vector<std::pair<std::string, RoleInstance*>>& roles) {
  std::vector<RobotTraffic> out;
  for (const auto& [name, role] : roles) {
    const auto* c = role != nullptr ? find_stage<const comms::CommsStage>(role) : nullptr;
    if (c == nullptr) continue;
    const comms::CommsStatsMsg& s = c->stats();
    out.push_back(RobotTraffic{name, s.datagrams_out, s.bytes_out, s.datagrams_in, s.bytes_in, s.records_out, s.records_in, s.link_send_failures});
  }
  return out;
}

std::string radio_traffic(std::uint64_t t_ns, const LinkStats* link, const std::vector<RobotTraffic>& robots) {
  const LinkStats l = link != nullptr ? *link : LinkStats{};
  std::string s = "{\"timestamp\":" + ts(t_ns) + ",\"link\":{\"sent\":" + std::to_string(l.sent) + ",\"delivered\":" + std::to_string(l.delivered) +
                  ",\"dropped_range\":" + std::to_string(l.dropped_range) + ",\"dropped_loss\":" + std::to_string(l.dropped_loss) +
                  ",\"dropped_queue\":" + std::to_string(l.dropped_queue) + ",\"dropped_collision\":" + std::to_string(l.dropped_collision) +
                  ",\"bytes_sent\":" + std::to_string(l.bytes_sent) + ",\"bytes_delivered\":" + std::to_string(l.bytes_delivered) + "},\"robots\":[";
  for (std::size_t i = 0; i < robots.size(); ++i) {
    const RobotTraffic& r = robots[i];
    s += (i ? ",{\"robot\":" : "{\"robot\":") + fg::json_string(r.robot) + ",\"datagrams_out\":" + std::to_string(r.datagrams_out) +
         ",\"bytes_out\":" + std::to_string(r.bytes_out) + ",\"datagrams_in\":" + std::to_string(r.datagrams_in) + ",\"bytes_in\":" +
         std::to_string(r.bytes_in) + ",\"records_out\":" + std::to_string(r.records_out) + ",\"records_in\":" + std::to_string(r.records_in) +
         ",\"send_failures\":" + std::to_string(r.send_failures) + "}";
  }
  return s + "]}";
}

std::string scheduler_counters(std::uint64_t t_ns, const std::vector<std::pair<std::string, RoleInstance*>>& roles) {
  std::vector<fg::StageCounters> stages;
  for (const auto& [robot, role] : roles) {
    if (role == nullptr) continue;
    for (std::size_t k = 0; k < role->perf().size(); ++k) {
      const StagePerfSnapshot p = snapshot(role->perf().at(k));
      const auto us = [](std::int64_t ns) { return static_cast<double>(ns) * 1e-3; };
      stages.push_back(fg::StageCounters{robot, role->perf().at(k).name, p.runs, p.overruns, p.slips, us(p.exec_p50), us(p.exec_p99),
                                         us(p.exec_max), us(p.budget_ns)});
    }
  }
  return fg::scheduler_counters_json(t_ns, stages);
}

}  // namespace ag::sim
