// Status stage: reads the counters of every stage of its robot and publishes them.
#include "airground/platform/status_stage.hpp"

#include <algorithm>
#include <cstdio>

#include "airground/platform/log.hpp"

namespace ag {

Status StatusStage::init(StageContext& ctx) {
  perf_ = &ctx.perf;
  clock_ = &ctx.clock;
  cfg_ = load_params(ctx.params(), kStatusStageFields);
  auto w = ctx.channels.latest_writer(chan::kSchedulerStatus);
  if (!w) return w.error();
  out_ = w.value();
  return ok_status();
}

// A device stage's second line: what it received (rate, complete/incomplete, errors by kind, bytes).
void StatusStage::log_device(std::size_t i, const SchedulerStatus::StageLine& l) const noexcept {
  const DeviceCounters& d = perf_->at(i).device;
  char kinds[160] = "";
  int o = 0;
  for (std::size_t e = 0; e < DeviceCounters::kErrorKinds && o >= 0 && o < static_cast<int>(sizeof kinds); ++e)
    if (d.error_name[e][0] != '\0')
      o += std::snprintf(kinds + o, sizeof kinds - static_cast<std::size_t>(o), " %s=%llu", d.error_name[e].data(),
                         static_cast<unsigned long long>(d.errors[e].load(std::memory_order_relaxed)));
  log::write(log::Level::kInfo, "status", "device stage=%s %s_per_s=%.1f complete=%llu incomplete=%llu errors=%llu%s bytes=%llu",
             l.name.data(), l.device_unit.data(), static_cast<double>(l.device_rate_hz),
             static_cast<unsigned long long>(l.device_complete), static_cast<unsigned long long>(l.device_incomplete),
             static_cast<unsigned long long>(l.device_errors), kinds, static_cast<unsigned long long>(l.device_bytes));
}

void StatusStage::step(TimeNs now) noexcept {
  msg_.sample_time_ns = now;
  msg_.seq += 1;
  const std::size_t n = std::min(perf_->size(), SchedulerStatus::kMaxStages);
  msg_.stage_count = static_cast<std::uint32_t>(n);
  msg_.total_overruns = 0;
  msg_.total_slips = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const StagePerf& p = perf_->at(i);
    const StagePerfSnapshot s = snapshot(p);
    auto& line = msg_.stages[i];
    std::snprintf(line.name.data(), line.name.size(), "%s", p.name.c_str());
    line.runs = s.runs;
    line.overruns = s.overruns;
    line.slips = s.slips;
    line.exec_p50_us = static_cast<float>(to_us(s.exec_p50));
    line.exec_p99_us = static_cast<float>(to_us(s.exec_p99));
    line.exec_max_us = static_cast<float>(to_us(s.exec_max));
    line.late_p99_us = static_cast<float>(to_us(s.late_p99));
    line.budget_us = static_cast<float>(to_us(s.budget_ns));
    const DeviceCounters& d = p.device;
    if (d.active.load(std::memory_order_relaxed)) {
      line.device_unit = d.unit;
      line.device_complete = d.complete.load(std::memory_order_relaxed);
      line.device_incomplete = d.incomplete.load(std::memory_order_relaxed);
      line.device_errors = d.error_total();
      line.device_bytes = d.bytes.load(std::memory_order_relaxed);
      const std::uint64_t units = line.device_complete + line.device_incomplete;
      const TimeNs dt = now - prev_sample_;
      line.device_rate_hz = prev_sample_ != 0 && dt > 0 ? static_cast<float>(static_cast<double>(units - prev_units_[i]) * 1e9 / static_cast<double>(dt)) : 0.0f;
      prev_units_[i] = units;
    }
    msg_.total_overruns += s.overruns;
    msg_.total_slips += s.slips;
  }
  prev_sample_ = now;
  msg_.publish_time_ns = clock_->now();
  out_.publish(msg_);

  const bool trouble = msg_.total_overruns != reported_overruns_ || msg_.total_slips != reported_slips_;
  if (cfg_.log_counters && (trouble || (msg_.seq - 1) % static_cast<std::uint32_t>(cfg_.log_every) == 0)) {
    for (std::size_t i = 0; i < n; ++i) {
      const auto& l = msg_.stages[i];
      const log::Level lvl = (trouble && (l.overruns != 0 || l.slips != 0)) ? log::Level::kWarn : log::Level::kInfo;
      log::write(lvl, "status", "stage=%s runs=%llu exec_p50_us=%.1f exec_p99_us=%.1f exec_max_us=%.1f budget_us=%.0f late_p99_us=%.1f overruns=%llu slips=%llu",
                 l.name.data(), static_cast<unsigned long long>(l.runs), static_cast<double>(l.exec_p50_us),
                 static_cast<double>(l.exec_p99_us), static_cast<double>(l.exec_max_us), static_cast<double>(l.budget_us),
                 static_cast<double>(l.late_p99_us), static_cast<unsigned long long>(l.overruns),
                 static_cast<unsigned long long>(l.slips));
      if (l.device_unit[0] != '\0') log_device(i, l);
    }
  }
  reported_overruns_ = msg_.total_overruns;
  reported_slips_ = msg_.total_slips;
}

}  // namespace ag
