// With the recorder on, the real-time stages' steps still allocate nothing: the synthetic role's sources
// and the ugv role (its real stages) run in lockstep with the recorder writing, and every allocation is
// charged to the stage whose step made it. The recorder itself allocates (its JSON and zstd, on its own
// lowest-priority thread): that it is counted shows the window covers the steps.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "airground/platform/executor.hpp"
#include "airground/platform/role_instance.hpp"
#include "roles.hpp"  // ugv_role()
#include "synthetic_role.hpp"

#include "../../../common/counting_new.hpp"

namespace ag {
namespace {

namespace fs = std::filesystem;
using test_alloc::AllocationWindow;

// Charges the allocations since the previous call to the runnable that ran in between.
struct PerStage {
  const std::vector<Runnable>* runs{nullptr};
  std::vector<std::uint64_t> allocations;
  std::size_t current{SIZE_MAX};
  std::uint64_t mark{0};
  void charge() {
    const std::uint64_t now = test_alloc::g_allocations.load(std::memory_order_relaxed);
    if (current != SIZE_MAX) allocations[current] += now - mark;
    mark = now;
  }
  static void trace(void* self, TimeNs, std::size_t runnable) {
    auto* p = static_cast<PerStage*>(self);
    p->charge();
    p->current = runnable;
  }
};

TEST(RecorderNoAllocation, TheRealTimeStagesAllocateNothingWhileTheRecorderWrites) {
  const fs::path dir = fs::temp_directory_path() / ("ag_recorder_noalloc_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string path = "recorder.path=" + dir.string();

  // The ugv role's own stages with the recorder tapping their channels, next to the synthetic sources.
  SimClock clock;
  Config ugv_cfg = Config::defaults(role_schema(ugv_role()));
  ASSERT_TRUE(ugv_cfg.set(path));
  ASSERT_TRUE(ugv_cfg.set("recorder.scheduler_period_s=1"));
  auto ugv = RoleInstance::create(ugv_role(), ugv_cfg, clock, "ugv1");
  ASSERT_TRUE(ugv.ok()) << ugv.error().message;
  Config syn_cfg = Config::defaults(role_schema(test::kRole));
  ASSERT_TRUE(syn_cfg.set(path));
  ASSERT_TRUE(syn_cfg.set("recorder.gps_channel=gps"));
  ASSERT_TRUE(syn_cfg.set("recorder.lidar_every=1"));
  auto syn = RoleInstance::create(test::kRole, syn_cfg, clock, "rob1");
  ASSERT_TRUE(syn.ok()) << syn.error().message;

  LockstepExecutor ex(clock);
  ex.add(*ugv.value());
  ex.add(*syn.value());
  PerStage per;
  per.runs = &ex.runnables();
  per.allocations.assign(ex.runnables().size(), 0);
  ex.set_trace(&PerStage::trace, &per);
  ex.start(0);
  {
    AllocationWindow w;
    ex.run_until(20 * kNsPerS);
    per.charge();
  }
  ugv.value()->stop_all();
  syn.value()->stop_all();

  std::uint64_t recorder_allocations = 0;
  for (std::size_t i = 0; i < ex.runnables().size(); ++i) {
    const Runnable& r = ex.runnables()[i];
    if (std::string(r.name) == "recorder") {
      recorder_allocations += per.allocations[i];
      continue;
    }
    EXPECT_EQ(per.allocations[i], 0u) << r.name << " allocated in step() with the recorder on";
    EXPECT_GT(r.perf->runs.load(), 10u) << r.name;
  }
  EXPECT_GT(recorder_allocations, 100u) << "the window did not see the recorder write";
  const auto* rec = find_stage<recording::RecorderStage>(syn.value().get());
  ASSERT_NE(rec, nullptr);
  EXPECT_GT(rec->counters().lidar.written, 100u);
  EXPECT_GT(rec->counters().map_tiles.written, 100u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace ag
