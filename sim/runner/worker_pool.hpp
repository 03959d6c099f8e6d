// The simulator's sensor workers: a platform WorkerGroup on normal threads (lockstep is not real time).
// Results stay deterministic because every job writes only its own output and the caller consumes them
// in a fixed order.
#pragma once

#include "airground/platform/worker_group.hpp"

namespace ag::sim {

using WorkerPool = WorkerGroup;

}  // namespace ag::sim
