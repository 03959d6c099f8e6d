// step() must not allocate: the global operator new is replaced here to count calls inside a window.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "test_robot.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/status_stage.hpp"
#include "airground/platform/worker_group.hpp"
#include "roles.hpp"  // ugv_role()

#include "../../common/counting_new.hpp"

namespace ag {
namespace {

using test_alloc::AllocationWindow;

// Keeps the compiler from proving an allocation unused and removing it.
void escape(const void* p) { asm volatile("" : : "g"(p) : "memory"); }

TEST(AllocationCounter, CountsEveryKindOfNewInsideTheWindow) {
  std::uint64_t n = 0;
  {
    AllocationWindow w;
    std::vector<int> v;
    for (int i = 0; i < 100; ++i) v.push_back(i);
    escape(v.data());
    auto plain = std::make_unique<int>(1);
    escape(plain.get());
    struct alignas(256) Wide {
      char c[256];
    };
    auto wide = std::make_unique<Wide>();
    escape(wide.get());
    int* nothrow = new (std::nothrow) int[4];
    escape(nothrow);
    delete[] nothrow;
    n = w.allocations();
  }
  EXPECT_GE(n, 4u);
}

TEST(AllocationCounter, IgnoresAllocationsOutsideTheWindow) {
  std::uint64_t before = 0;
  {
    AllocationWindow w;
    before = w.allocations();
  }
  std::vector<std::string> outside(100, std::string(64, 'x'));
  escape(outside.data());
  AllocationWindow w;
  EXPECT_EQ(w.allocations(), 0u);
  EXPECT_EQ(before, 0u);
}

// ------------------------------------------------------------------------- stages that use channels

struct Frame {
  TimeNs sample_time_ns{0};   // [ns]
  TimeNs publish_time_ns{0};  // [ns]
  std::uint32_t seq{0};
  std::uint8_t pixels[4096]{};
};

class FrameSource final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<FrameSource>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.latest_writer<Frame>("frame");
    if (!w) return w.error();
    frame_out_ = w.value();
    auto r = ctx.channels.ring_writer<Frame, 8>("frames");
    if (!r) return r.error();
    ring_out_ = r.value();
    return ok_status();
  }
  void step(TimeNs now) noexcept override {
    frame_.sample_time_ns = now;
    frame_.publish_time_ns = now;
    ++frame_.seq;
    frame_.pixels[frame_.seq % sizeof frame_.pixels] = static_cast<std::uint8_t>(frame_.seq);
    frame_out_.publish(frame_);
    (void)ring_out_.push(frame_);  // refusals are counted by the channel; the consumer keeps up anyway
  }

 private:
  LatestWriter<Frame> frame_out_;
  RingWriter<Frame, 8> ring_out_;
  Frame frame_{};
};

class FrameSink final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<FrameSink>(); }
  Status init(StageContext& ctx) override {
    auto l = ctx.channels.latest_reader<Frame>("frame");
    if (!l) return l.error();
    latest_ = l.value();
    auto r = ctx.channels.ring_reader<Frame, 8>("frames");
    if (!r) return r.error();
    ring_ = r.value();
    auto s = ctx.channels.latest_reader(chan::kSchedulerStatus);
    if (!s) return s.error();
    status_ = s.value();
    return ok_status();
  }
  void step(TimeNs) noexcept override {
    while (const Frame* f = ring_.front()) {
      checksum_ += f->seq;
      ring_.pop();
    }
    if (latest_.fresh()) checksum_ += latest_.read().seq;
    checksum_ += status_.read().seq;
  }

 private:
  LatestReader<Frame> latest_;
  RingReader<Frame, 8> ring_;
  LatestReader<SchedulerStatus> status_;
  std::uint64_t checksum_{0};
};

// name, factory, rate [Hz], budget [µs], priority, CPU, parameters
constexpr StageSpec kChannelStages[] = {
    {"source", &FrameSource::make, 100.0, 1'000, 30, -1, {}, "publishes frames"},
    {"sink", &FrameSink::make, 50.0, 1'000, 20, -1, {}, "reads them in place"},
    {"status", &StatusStage::make, 1.0, 2'000, 10, -1, StatusStage::kParams, "scheduler counters"},
};
static_assert(role_table_ok(kChannelStages));
const RoleDescription kChannelRole{"channels", "a writer and a reader of a latest and a ring channel", kChannelStages, {}};

using test::build;
using test::TestRobot;

TEST(NoAllocation, LockstepStepsOfTheUgvRoleAndAChannelPairAllocateNothing) {
  SimClock clock;
  auto ugv = build(ugv_role(), clock, "ugv1");
  auto pair = build(kChannelRole, clock, "pair");
  ASSERT_TRUE(ugv && pair);
  LockstepExecutor ex(clock);
  ex.add(*ugv->robot);
  ex.add(*pair->robot);
  ex.start(0);

  std::uint64_t allocations = 0;
  {
    AllocationWindow w;
    ex.run_until(120 * kNsPerS);
    allocations = w.allocations();
  }
  EXPECT_EQ(allocations, 0u);

  // The window really covered the steps: every stage ran, including the logging status stages.
  std::uint64_t steps = 0;
  for (auto* r : {ugv->robot.get(), pair->robot.get()})
    for (std::size_t i = 0; i < r->perf().size(); ++i) {
      EXPECT_GT(r->perf().at(i).runs.load(), 100u) << r->perf().at(i).name;
      steps += r->perf().at(i).runs.load();
    }
  EXPECT_GT(steps, 18'000u);
}

// The caller's side of run(): the hand-out, the wake-up and the wait (workers are started before).
TEST(NoAllocation, WorkerGroupRunsAllocateNothing) {
  WorkerGroup g(3);
  std::vector<int> out(256, 0);
  const auto item = [](void* ctx, int i, int /*thread*/) noexcept { static_cast<int*>(ctx)[i] += i; };
  std::uint64_t allocations = 0;
  {
    AllocationWindow w;
    for (int rep = 0; rep < 100; ++rep) {
      g.run(static_cast<int>(out.size()), item, out.data());
      g.run(out.size(), [&](std::size_t j, int /*thread*/) { out[j] -= static_cast<int>(j); });
    }
    allocations = w.allocations();
  }
  EXPECT_EQ(allocations, 0u);
  for (int v : out) EXPECT_EQ(v, 0);
}

}  // namespace
}  // namespace ag
