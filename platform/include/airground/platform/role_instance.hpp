// One robot's running role: its stages built from the table, their counters and their channels.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "airground/platform/channels.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/perf_counters.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/role_table.hpp"

namespace ag {

// The sections every role has (robot, scheduler, log), then the role's own, then one per stage.
[[nodiscard]] std::vector<ParamSection> role_schema(const RoleDescription& role);

struct StageSlot {
  const StageSpec* spec;
  std::unique_ptr<Stage> stage;
  StagePerf* perf;
};

// Which executor will run the stages. Under kRealtime each stage's context carries its row's priority and
// CPU (as scheduler.realtime and scheduler.pin_cpus allow) for the workers it starts; under kLockstep
// (the simulator, tests) {0, -1}: normal threads.
enum class StageThreads { kLockstep, kRealtime };

class RoleInstance {
 public:
  // Builds and initialises every stage in table order; the first failing init() is the error.
  static Result<std::unique_ptr<RoleInstance>> create(const RoleDescription& role, const Config& config,
                                                      const Clock& clock, std::string instance_name,
                                                      StageThreads threads = StageThreads::kLockstep);
  RoleInstance(const RoleInstance&) = delete;
  RoleInstance& operator=(const RoleInstance&) = delete;
  ~RoleInstance();

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] std::vector<StageSlot>& stages() noexcept { return stages_; }
  [[nodiscard]] PerfRegistry& perf() noexcept { return perf_; }
  [[nodiscard]] ChannelRegistry& channels() noexcept { return channels_; }
  void stop_all() noexcept;

 private:
  RoleInstance() = default;
  std::string name_;
  PerfRegistry perf_;
  ChannelRegistry channels_;
  std::vector<StageSlot> stages_;
  bool stopped_{false};
};

// The first stage of type S in a robot's table (tests, evaluations, the simulator's observers); null
// when the role is null or has none.
template <class S>
S* find_stage(RoleInstance* role) noexcept {
  if (role == nullptr) return nullptr;
  for (auto& slot : role->stages())
    if (auto* s = dynamic_cast<S*>(slot.stage.get())) return s;
  return nullptr;
}

}  // namespace ag
