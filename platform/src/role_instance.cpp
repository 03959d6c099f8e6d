// Building a robot's stages from its role table.
#include "airground/platform/role_instance.hpp"

#include "airground/platform/log.hpp"

namespace ag {

namespace {
constexpr ParamSpec kRobotParams[] = {
    ParamSpec::integer("id", 0, 0, 254, "", "robot id in the team (part of every gossip record)"),
    ParamSpec::text("name", "", "", "human-readable robot name; empty = <role><id>"),
};
constexpr ParamSpec kSchedulerParams[] = {
    ParamSpec::boolean("realtime", true, "run stage threads SCHED_FIFO at the table's priorities when permitted"),
    ParamSpec::boolean("lock_memory", true, "mlockall() at start so no page fault reaches a real-time thread"),
    ParamSpec::boolean("pin_cpus", true, "pin stage threads to the table's CPUs"),
    ParamSpec::real("watchdog_silence_s", 2.0, 0.1, 60.0, "s", "a stage thread silent this long stops the systemd watchdog"),
};
constexpr ParamSpec kLogParams[] = {
    ParamSpec::text("level", "info", "debug|info|warn|error", "lowest level written"),
};
}  // namespace

std::vector<ParamSection> role_schema(const RoleDescription& role) {
  std::vector<ParamSection> s = {
      {"robot", kRobotParams, "who this robot is"},
      {"scheduler", kSchedulerParams, "the real-time executor"},
      {"log", kLogParams, "logging"},
  };
  for (const auto& sec : role.extra_sections) s.push_back(sec);
  for (const auto& st : role.stages)
    if (!st.params.empty()) s.push_back(ParamSection{st.name, st.params, st.help});
  return s;
}

Result<std::unique_ptr<RoleInstance>> RoleInstance::create(const RoleDescription& role, const Config& config,
                                                           const Clock& clock, std::string instance_name,
                                                           StageThreads threads) {
  std::unique_ptr<RoleInstance> r(new RoleInstance());
  r->name_ = std::move(instance_name);
  r->stages_.reserve(role.stages.size());
  for (const auto& spec : role.stages) {
    // Not in the compile-time check: sanitizer builds cannot compare function addresses there.
    if (spec.make == nullptr) return Error::make(ErrorCode::kInvalidArgument, "stage '" + std::string(spec.name) + "' has no factory");
    StagePerf& perf = r->perf_.add(std::string(spec.name), static_cast<TimeNs>(spec.budget_us) * kNsPerUs,
                                   period_from_hz(spec.rate_hz));
    r->stages_.push_back(StageSlot{&spec, spec.make(), &perf});
  }
  for (std::size_t i = 0; i < r->stages_.size(); ++i) {
    StageSlot& slot = r->stages_[i];
    r->channels_.set_initialising(i);  // the writers this stage takes are its outputs (lockstep compute time)
    StageContext ctx{config, r->channels_, clock, r->perf_, r->name_, slot.spec->name, &slot.perf->device};
    if (threads == StageThreads::kRealtime) {
      if (config.get_bool("scheduler.realtime")) ctx.placement.priority = slot.spec->priority;
      if (config.get_bool("scheduler.pin_cpus")) ctx.placement.cpu = slot.spec->cpu;
    }
    Status st = slot.stage->init(ctx);
    if (!st) {
      return Error::make(st.error().code, r->name_ + "/" + std::string(slot.spec->name) + ": init failed: " + st.error().message);
    }
  }
  r->channels_.seal();
  return r;
}

void RoleInstance::stop_all() noexcept {
  if (stopped_) return;
  stopped_ = true;
  for (auto it = stages_.rbegin(); it != stages_.rend(); ++it) it->stage->stop();
}

RoleInstance::~RoleInstance() { stop_all(); }

}  // namespace ag
