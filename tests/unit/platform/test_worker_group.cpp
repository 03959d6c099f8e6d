// WorkerGroup: every item runs once across the caller and the workers, and the workers take the placement
// they report (or report its refusal); a stage learns the placement from its context.
#include "airground/platform/worker_group.hpp"

#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>

#include <atomic>
#include <chrono>
#include <cstddef>
#include <functional>
#include <initializer_list>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "airground/platform/clock.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"

namespace ag {
namespace {

struct Tally {
  std::vector<std::atomic<int>> runs;
  std::atomic<int> bad_thread{0};
  int threads{0};
};

void count_item(void* ctx, int item, int thread) noexcept {
  auto& t = *static_cast<Tally*>(ctx);
  t.runs[static_cast<std::size_t>(item)].fetch_add(1, std::memory_order_relaxed);
  if (thread < 0 || thread >= t.threads) t.bad_thread.fetch_add(1, std::memory_order_relaxed);
}

TEST(WorkerGroup, EveryItemRunsExactlyOnce) {
  for (int threads : {1, 2, 4}) {
    WorkerGroup g(threads);
    ASSERT_EQ(g.size(), threads);
    for (int items : {0, 1, 2, 3, 7, 100, 1000}) {
      for (int rep = 0; rep < 20; ++rep) {
        Tally t{std::vector<std::atomic<int>>(static_cast<std::size_t>(items)), {}, threads};
        g.run(items, count_item, &t);
        for (int i = 0; i < items; ++i) ASSERT_EQ(t.runs[static_cast<std::size_t>(i)].load(), 1) << threads << " threads, item " << i << " of " << items;
        EXPECT_EQ(t.bad_thread.load(), 0);
      }
    }
  }
}

// Each item waits until all have started, so no thread can take two: every thread, the caller included,
// runs exactly one, and thread 0 is the caller.
TEST(WorkerGroup, TheCallerTakesPartAsThreadZero) {
  WorkerGroup g(3);
  const std::thread::id caller = std::this_thread::get_id();
  std::atomic<int> started{0};
  std::vector<std::thread::id> who(3);
  std::vector<int> items_of(3, 0);
  bool timed_out = false;
  g.run(std::size_t{3}, [&](std::size_t /*item*/, int thread) {
    who[static_cast<std::size_t>(thread)] = std::this_thread::get_id();
    ++items_of[static_cast<std::size_t>(thread)];
    started.fetch_add(1);
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (started.load() < 3)
      if (std::chrono::steady_clock::now() > until) {
        timed_out = true;
        break;
      } else {
        std::this_thread::yield();
      }
  });
  ASSERT_FALSE(timed_out);
  EXPECT_EQ(items_of, (std::vector<int>{1, 1, 1}));
  EXPECT_EQ(who[0], caller);
  EXPECT_NE(who[1], caller);
  EXPECT_NE(who[2], caller);
  EXPECT_NE(who[1], who[2]);
}

TEST(WorkerGroup, CallablesRunInPlace) {
  WorkerGroup g(3);
  std::vector<int> out(50, 0);
  g.run(out.size(), [&](std::size_t j) { out[j] = static_cast<int>(j) * 2; });
  for (std::size_t j = 0; j < out.size(); ++j) EXPECT_EQ(out[j], static_cast<int>(j) * 2);
  const std::function<void(std::size_t)> fn = [&](std::size_t j) { out[j] += 1; };  // as the simulator passes
  g.run(out.size(), fn);
  for (std::size_t j = 0; j < out.size(); ++j) EXPECT_EQ(out[j], static_cast<int>(j) * 2 + 1);
}

struct Seen {
  int policy{-1}, priority{-1};
  bool only_cpu0{false};
};

// Runs sleeping items until every worker has taken one; what each thread saw of its own scheduling.
std::vector<Seen> scheduling_seen(WorkerGroup& g) {
  std::vector<Seen> seen(static_cast<std::size_t>(g.size()));
  std::vector<std::atomic<bool>> ran(static_cast<std::size_t>(g.size()));
  for (int attempt = 0; attempt < 200; ++attempt) {
    g.run(static_cast<std::size_t>(4 * g.size()), [&](std::size_t /*item*/, int thread) {
      Seen s;
      sched_param sp{};
      s.policy = sched_getscheduler(0);
      if (sched_getparam(0, &sp) == 0) s.priority = sp.sched_priority;
      cpu_set_t set;
      CPU_ZERO(&set);
      if (sched_getaffinity(0, sizeof set, &set) == 0) s.only_cpu0 = CPU_COUNT(&set) == 1 && CPU_ISSET(0, &set);
      seen[static_cast<std::size_t>(thread)] = s;  // each slot written by its own thread only
      ran[static_cast<std::size_t>(thread)].store(true);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));  // lets the others take items, even on one CPU
    });
    bool all = true;
    for (std::size_t t = 1; t < ran.size(); ++t) all = all && ran[t].load();
    if (all) return seen;
  }
  ADD_FAILURE() << "a worker never took an item";
  return seen;
}

TEST(WorkerGroup, WorkersTakeThePlacementTheyReport) {
  const int caller_policy = sched_getscheduler(0);
  WorkerGroup g(3, WorkerPlacement{5, 0});
  const WorkerPlacementReport& rep = g.placement();
  EXPECT_EQ(rep.warning.empty(), rep.fifo_applied && rep.pinned) << rep.warning;
  const std::vector<Seen> seen = scheduling_seen(g);
  for (std::size_t t = 1; t < seen.size(); ++t) {
    if (rep.fifo_applied) {
      EXPECT_EQ(seen[t].policy, SCHED_FIFO) << "worker " << t;
      EXPECT_EQ(seen[t].priority, 5) << "worker " << t;
    } else {
      EXPECT_NE(rep.warning.find("SCHED_FIFO"), std::string::npos) << rep.warning;
    }
    if (rep.pinned) {
      EXPECT_TRUE(seen[t].only_cpu0) << "worker " << t;
    }
  }
  EXPECT_EQ(seen[0].policy, caller_policy) << "the caller's own scheduling is left alone";
}

TEST(WorkerGroup, NoPlacementAsksForNothing) {
  WorkerGroup g(2);
  EXPECT_FALSE(g.placement().fifo_applied);
  EXPECT_FALSE(g.placement().pinned);
  EXPECT_TRUE(g.placement().warning.empty());
  const std::vector<Seen> seen = scheduling_seen(g);
  EXPECT_EQ(seen[1].policy, SCHED_OTHER);
}

TEST(WorkerGroup, ARefusedPlacementIsReportedAndTheWorkStillRuns) {
  WorkerGroup g(3, WorkerPlacement{200, 1 << 20});  // no such priority, no such CPU
  EXPECT_FALSE(g.placement().fifo_applied);
  EXPECT_FALSE(g.placement().pinned);
  EXPECT_NE(g.placement().warning.find("SCHED_FIFO 200"), std::string::npos) << g.placement().warning;
  EXPECT_NE(g.placement().warning.find("CPU 1048576"), std::string::npos) << g.placement().warning;
  Tally t{std::vector<std::atomic<int>>(100), {}, 3};
  g.run(100, count_item, &t);
  for (const auto& r : t.runs) EXPECT_EQ(r.load(), 1);
}

// ------------------------------------------------------------------------ the placement a stage learns

WorkerPlacement g_placement_seen{-7, -7};

class PlacementProbe final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<PlacementProbe>(); }
  Status init(StageContext& ctx) override {
    g_placement_seen = ctx.placement;
    return ok_status();
  }
  void step(TimeNs /*now*/) noexcept override {}
};

constexpr StageSpec kProbeStages[] = {{"probe", &PlacementProbe::make, 10.0, 1'000, 24, 1, {}, "records its placement"}};
static_assert(role_table_ok(kProbeStages));
const RoleDescription kProbeRole{"probe", "one stage that records its context's placement", kProbeStages, {}};

WorkerPlacement placement_under(StageThreads threads, std::initializer_list<const char*> settings) {
  Config cfg = Config::defaults(role_schema(kProbeRole));
  for (const char* kv : settings) EXPECT_TRUE(cfg.set(kv).ok()) << kv;
  SimClock clock;
  g_placement_seen = {-7, -7};
  auto r = RoleInstance::create(kProbeRole, cfg, clock, "probe1", threads);
  EXPECT_TRUE(r.ok()) << r.error().message;
  return g_placement_seen;
}

TEST(StagePlacement, IsTheTableRowUnderTheRealtimeExecutorAsTheSchedulerAllows) {
  const WorkerPlacement rt = placement_under(StageThreads::kRealtime, {});
  EXPECT_EQ(rt.priority, 24);
  EXPECT_EQ(rt.cpu, 1);
  const WorkerPlacement normal = placement_under(StageThreads::kRealtime, {"scheduler.realtime=false", "scheduler.pin_cpus=false"});
  EXPECT_EQ(normal.priority, 0);
  EXPECT_EQ(normal.cpu, -1);
}

TEST(StagePlacement, IsNormalThreadsInLockstep) {
  const WorkerPlacement ls = placement_under(StageThreads::kLockstep, {});
  EXPECT_EQ(ls.priority, 0);
  EXPECT_EQ(ls.cpu, -1);
}

}  // namespace
}  // namespace ag
