// The ugv role table: every stage once, with rate, budget, priority and CPU; checked at compile time.
#include "roles.hpp"

#include "airground/platform/status_stage.hpp"

namespace ag {

namespace {
// name, factory, rate [Hz], budget [µs], SCHED_FIFO priority, CPU (-1 any), parameters, what it does
constexpr StageSpec kUgvStages[] = {
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters, once a second"},
};
static_assert(role_table_ok(kUgvStages));
}  // namespace

const RoleDescription& ugv_role() {
  static const RoleDescription role{"ugv", "ground robot: semantic localization in the aerial map, planning, drive over CAN", kUgvStages, {}};
  return role;
}

}  // namespace ag
