// Compute time in lockstep: a stage's outputs show when its modelled compute time has passed, a stage
// busy past its next release starts late or slips, and held rings and latest values hand over in order.
#include "test_robot.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <vector>

#include "airground/platform/channels.hpp"
#include "airground/platform/executor.hpp"
#include "airground/platform/latest_value.hpp"
#include "airground/platform/role_instance.hpp"
#include "airground/platform/role_table.hpp"
#include "airground/platform/spsc_ring.hpp"

namespace ag {
namespace {

// ------------------------------------------------------------------------------------- held channels

TEST(HeldRing, PushesStayInvisibleUntilReleaseThenArriveInOrder) {
  SpscRing<int, 4> ring;
  ASSERT_TRUE(ring.try_push(1));
  ring.hold();
  ASSERT_TRUE(ring.try_push(2));
  ASSERT_TRUE(ring.try_push(3));
  ASSERT_TRUE(ring.try_push(4));
  EXPECT_FALSE(ring.try_push(5)) << "held elements still take their slots";
  EXPECT_EQ(ring.unread_from_producer(), 4u);
  ASSERT_NE(ring.front(), nullptr);
  EXPECT_EQ(*ring.front(), 1);
  ring.pop();
  EXPECT_EQ(ring.front(), nullptr) << "2, 3, 4 are held";
  ring.release();
  std::vector<int> seen;
  while (int* v = ring.front()) {
    seen.push_back(*v);
    ring.pop();
  }
  EXPECT_EQ(seen, (std::vector<int>{2, 3, 4}));
  ASSERT_TRUE(ring.try_push(6));
  ASSERT_NE(ring.front(), nullptr) << "after release pushes are visible at once again";
  EXPECT_EQ(*ring.front(), 6);
}

TEST(HeldLatestValue, TheNewestHeldPublicationIsHandedOverAtRelease) {
  LatestValue<int> lv(0);
  lv.write(1);
  EXPECT_EQ(lv.read(), 1);
  lv.hold();
  lv.write(2);
  lv.write(3);
  EXPECT_FALSE(lv.fresh());
  EXPECT_EQ(lv.read(), 1);
  lv.release();
  EXPECT_TRUE(lv.fresh());
  EXPECT_EQ(lv.read(), 3);
  lv.release();  // nothing pending: no new hand-over
  EXPECT_FALSE(lv.fresh());
  EXPECT_EQ(lv.published(), 3u);
}

TEST(HeldChannel, FreeSlotsCountWhatIsHeld) {
  ChannelRegistry reg;
  reg.set_initialising(0);
  auto w = reg.ring_writer<int, 4>("c");
  ASSERT_TRUE(w.ok());
  reg.set_initialising(1);
  auto r = reg.ring_reader<int, 4>("c");
  ASSERT_TRUE(r.ok());
  reg.seal();
  auto writer = w.value();
  auto reader = r.value();
  reg.hold_outputs(1);  // stage 1 writes nothing: no effect
  (void)writer.push(7);
  EXPECT_NE(reader.front(), nullptr);
  reader.pop();
  reg.hold_outputs(0);
  (void)writer.push(8);
  (void)writer.push(9);
  EXPECT_EQ(reader.front(), nullptr);
  EXPECT_EQ(writer.free_slots(), 2u);
  reg.release_outputs(0);
  ASSERT_NE(reader.front(), nullptr);
  EXPECT_EQ(*reader.front(), 8);
}

// ------------------------------------------------------------------------------------- the executor

struct Seen {
  TimeNs t;
  std::int64_t latest;
  std::int64_t ring_total;  // ring messages drained so far
};
std::vector<Seen>* g_seen = nullptr;

// 10 Hz: publishes its step number on a latest value and a ring; one unit of work a step.
class ProducerStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<ProducerStage>(); }
  Status init(StageContext& ctx) override {
    auto w = ctx.channels.latest_writer<std::int64_t>("value");
    if (!w) return w.error();
    out_ = w.value();
    auto e = ctx.channels.ring_writer<std::int64_t, 16>("events");
    if (!e) return e.error();
    events_ = e.value();
    return ok_status();
  }
  void step(TimeNs) noexcept override {
    ++n_;
    out_.publish(n_);
    (void)events_.push(n_);
    add_work(1.0);
  }

 private:
  LatestWriter<std::int64_t> out_;
  RingWriter<std::int64_t, 16> events_;
  std::int64_t n_{0};
};

// 100 Hz, after the producer in the table: records what it sees of both channels.
class ConsumerStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<ConsumerStage>(); }
  Status init(StageContext& ctx) override {
    auto r = ctx.channels.latest_reader<std::int64_t>("value");
    if (!r) return r.error();
    in_ = r.value();
    auto e = ctx.channels.ring_reader<std::int64_t, 16>("events");
    if (!e) return e.error();
    events_ = e.value();
    seen_ = g_seen;
    return seen_ != nullptr ? ok_status() : Error::make(ErrorCode::kInternal, "test: no record set");
  }
  void step(TimeNs now) noexcept override {
    while (events_.front() != nullptr) {
      events_.pop();
      ++drained_;
    }
    seen_->push_back({now, in_.read(), drained_});
  }

 private:
  LatestReader<std::int64_t> in_;
  RingReader<std::int64_t, 16> events_;
  std::int64_t drained_{0};
  std::vector<Seen>* seen_{nullptr};
};

// name, factory, rate [Hz], budget [µs], priority, CPU
constexpr StageSpec kStages[] = {
    {"producer", &ProducerStage::make, 10.0, 50'000, 30, -1},
    {"consumer", &ConsumerStage::make, 100.0, 1'000, 20, -1},
};
static_assert(role_table_ok(kStages));
const RoleDescription kRole{"test", "a 10 Hz producer and a 100 Hz consumer", kStages};

// Cost: `per_unit` ns for each unit of work the stage reported (the consumer reports none).
TimeNs g_per_unit = 0;
TimeNs unit_cost(void*, std::size_t, double work, TimeNs) noexcept { return static_cast<TimeNs>(work * static_cast<double>(g_per_unit)); }

struct TimedRun {
  SimClock clock;
  std::vector<Seen> seen;
  std::unique_ptr<test::TestRobot> built;
  LockstepExecutor ex{clock};

  TimedRun(bool timed, TimeNs per_unit) {
    seen.reserve(4000);
    g_seen = &seen;
    built = test::build(kRole, clock, "r");
    g_seen = nullptr;
    g_per_unit = per_unit;
    if (built) ex.add(*built->robot);
    if (timed) ex.set_compute_time(&unit_cost, nullptr);
    ex.start(0);
  }
  const StagePerf& producer() { return built->robot->perf().at(0); }
};

// The first time the consumer saw `latest` (or -1).
TimeNs first_seen(const std::vector<Seen>& seen, std::int64_t latest) {
  for (const auto& s : seen)
    if (s.latest == latest) return s.t;
  return -1;
}

TEST(LockstepComputeTime, OutputsShowWhenTheModelledComputeTimeHasPassed) {
  TimedRun untimed(false, 0);
  TimedRun timed(true, 35 * kNsPerMs);
  ASSERT_TRUE(untimed.built && timed.built);
  untimed.ex.run_until(kNsPerS - 1);
  timed.ex.run_until(kNsPerS - 1);
  // Without compute time the consumer, later in the table, sees each value at the producer's release.
  EXPECT_EQ(first_seen(untimed.seen, 1), 0);
  EXPECT_EQ(first_seen(untimed.seen, 3), 200 * kNsPerMs);
  // With 35 ms a step the value shows at 35 ms: the consumer's first step after that is at 40 ms.
  EXPECT_EQ(first_seen(timed.seen, 1), 40 * kNsPerMs);
  EXPECT_EQ(first_seen(timed.seen, 3), 240 * kNsPerMs);
  for (const auto& s : timed.seen) {
    if (s.t == 230 * kNsPerMs) {
      EXPECT_EQ(s.ring_total, 2) << "the third ring message is still held at 230 ms";
    }
    if (s.t == 240 * kNsPerMs) {
      EXPECT_EQ(s.ring_total, 3);
    }
  }
  EXPECT_EQ(timed.producer().runs.load(), 10u);
  EXPECT_EQ(timed.producer().slips.load(), 0u);
  EXPECT_EQ(timed.producer().overruns.load(), 0u) << "35 ms is within the 50 ms budget";
  EXPECT_EQ(timed.producer().exec.max(), 35 * kNsPerMs) << "the histogram holds the modelled time";
}

TEST(LockstepComputeTime, AStageBusyPastItsReleasesStartsLateSlipsAndOverruns) {
  TimedRun timed(true, 250 * kNsPerMs);
  ASSERT_TRUE(timed.built);
  timed.ex.run_until(2 * kNsPerS - 1);
  // Steps start at 0, 250 (release 200, 50 late: one slip), 500 (release 500), 750 (release 700), 1000,
  // 1250, 1500, 1750: eight runs and ten slips serve the releases up to 1.7 s; 1.8 and 1.9 s wait for the
  // step that ends at 2 s.
  const StagePerf& p = timed.producer();
  EXPECT_EQ(p.runs.load(), 8u);
  EXPECT_EQ(p.slips.load(), 10u);
  EXPECT_EQ(p.overruns.load(), 8u) << "250 ms against a 50 ms budget";
  EXPECT_EQ(first_seen(timed.seen, 1), 250 * kNsPerMs);
  EXPECT_EQ(first_seen(timed.seen, 2), 500 * kNsPerMs);
  EXPECT_EQ(p.lateness.max(), 50 * kNsPerMs);
}

TEST(LockstepComputeTime, ZeroCostGivesTheUntimedRunExactly) {
  TimedRun untimed(false, 0);
  TimedRun timed(true, 0);
  ASSERT_TRUE(untimed.built && timed.built);
  untimed.ex.run_until(3 * kNsPerS);
  timed.ex.run_until(3 * kNsPerS);
  ASSERT_EQ(untimed.seen.size(), timed.seen.size());
  for (std::size_t i = 0; i < untimed.seen.size(); ++i) {
    EXPECT_EQ(untimed.seen[i].t, timed.seen[i].t) << i;
    EXPECT_EQ(untimed.seen[i].latest, timed.seen[i].latest) << i;
    EXPECT_EQ(untimed.seen[i].ring_total, timed.seen[i].ring_total) << i;
  }
}

}  // namespace
}  // namespace ag
