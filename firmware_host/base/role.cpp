// The base role table: every stage once, with rate, budget, priority and CPU; checked at compile time.
#include "roles.hpp"

#include "airground/comms/stage.hpp"
#include "airground/base_station/web_stage.hpp"

#include "airground/platform/status_stage.hpp"

namespace ag {

namespace {
// name, factory, rate [Hz], budget [µs], SCHED_FIFO priority, CPU (-1 any), parameters, what it does
constexpr StageSpec kBaseStages[] = {
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters, once a second", {18.4, 0}},
    {"comms", &comms::CommsStage::make, 20.0, 5'000, 25, -1, comms::CommsStage::kParams,
     "gossip: the team's latest records (poses, map tiles, claims, failures) over the radio mesh", {10.0, 0}},
    {"web", &base_station::WebStage::make, 10.0, 2'000, 5, -1, base_station::WebStage::kParams,
     "live page (HTTP + WebSocket on its own thread) and the mission log: map, robots, regions, claims, comms", {4.8, 0}},
};
static_assert(role_table_ok(kBaseStages));
}  // namespace

const RoleDescription& base_role() {
  static const RoleDescription role{"base", "base station: listens, relays and records the team's mission", kBaseStages, {}};
  return role;
}

}  // namespace ag
