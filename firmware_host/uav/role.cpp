// The uav role table: every stage once, with rate, budget, priority and CPU; checked at compile time.
#include "roles.hpp"

#include "airground/platform/status_stage.hpp"

namespace ag {

namespace {
// name, factory, rate [Hz], budget [µs], SCHED_FIFO priority, CPU (-1 any), parameters, what it does
constexpr StageSpec kUavStages[] = {
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters, once a second"},
};
static_assert(role_table_ok(kUavStages));
}  // namespace

const RoleDescription& uav_role() {
  static const RoleDescription role{"uav", "quadrotor: semantic ortho-mapping and the regions of interest it finds", kUavStages, {}};
  return role;
}

}  // namespace ag
