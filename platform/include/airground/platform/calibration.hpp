// The calibration workload: a fixed CPU job timed in the same process as a timing test, to say how
// this machine compares with the robot CPU the stage budgets are written for.
#pragma once

#include <cstdint>

#include "airground/platform/time.hpp"

namespace ag {

// Thread CPU time of one run of the workload on the reference robot CPU. Recorded on the project's
// build machines (x86-64 server cores of a single-thread speed comparable with the NUC i7-10710U);
// replace with a figure measured on the NUC itself when one is on the bench (tests/timing/README).
inline constexpr TimeNs kCalibrationReferenceNs = 6'000'000;

// Runs the workload once and returns its result (so the work cannot be optimised away).
std::uint64_t calibration_workload() noexcept;

struct Calibration {
  TimeNs median_ns;   // thread CPU time of one workload run here
  double scale;       // median_ns / kCalibrationReferenceNs: multiply robot budgets by this
};
// Median of `runs` runs, in thread CPU time.
Calibration calibrate(int runs = 7) noexcept;

}  // namespace ag
