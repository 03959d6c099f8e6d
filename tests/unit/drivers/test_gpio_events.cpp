// E-stop edges through an event fd that an event loop polls (the fake line's eventfd here; libgpiod's
// line-event fd on the robot), and the status LED's pattern per role state.
#include <poll.h>

#include <gtest/gtest.h>

#include <set>
#include <tuple>

#include "airground/drivers/gpio/edge_events.hpp"
#include "airground/drivers/gpio/estop.hpp"

namespace ag::gpio {
namespace {

bool readable(int fd, int timeout_ms) {
  pollfd p{fd, POLLIN, 0};
  return ::poll(&p, 1, timeout_ms) == 1 && (p.revents & POLLIN) != 0;
}

TEST(GpioEdges, PressWakesTheEventLoopAndStopsTheRobot) {
  FakeEdgeLine line;
  ASSERT_GE(line.event_fd(), 0);
  EStopEdges edges(line);
  EStopLatch latch(true);
  EXPECT_FALSE(readable(line.event_fd(), 0)) << "nothing pending: the loop sleeps";
  line.press(true, 1000);
  ASSERT_TRUE(readable(line.event_fd(), 100));
  ASSERT_TRUE(edges.drain());
  EXPECT_TRUE(edges.pressed());
  EXPECT_EQ(edges.last_edge(), 1000);
  EXPECT_TRUE(latch.update(true, edges.tapped(), false));
  EXPECT_FALSE(readable(line.event_fd(), 0)) << "drained";
  line.press(false, 2000);
  ASSERT_TRUE(edges.drain());
  EXPECT_TRUE(edges.tapped()) << "it was pressed during this interval";
  EXPECT_TRUE(latch.update(true, edges.tapped(), false));
  ASSERT_TRUE(edges.drain());  // a quiet cycle
  EXPECT_FALSE(edges.tapped());
  EXPECT_TRUE(latch.update(true, edges.tapped(), false));  // released: latched, still stopped
  EXPECT_EQ(latch.state(), EStopState::kLatched);
  EXPECT_FALSE(latch.update(true, edges.tapped(), true));  // re-armed
  // A tap shorter than a cycle (press and release before the loop runs) still stops the robot.
  line.press(true, 3000);
  line.press(false, 3001);
  ASSERT_TRUE(readable(line.event_fd(), 0));
  ASSERT_TRUE(edges.drain());
  EXPECT_FALSE(edges.pressed());
  EXPECT_TRUE(edges.tapped());
  EXPECT_TRUE(latch.update(true, edges.tapped(), false));
  EXPECT_EQ(edges.edges(), 4u);
  line.press(false, 4000);  // no change, no edge
  EXPECT_FALSE(readable(line.event_fd(), 0));
}

TEST(GpioEdges, ManyEdgesStayReadableUntilDrainedAndOverrunsCount) {
  FakeEdgeLine line;
  for (int i = 0; i < 100; ++i) line.press(i % 2 == 0, i);
  EXPECT_EQ(line.overruns(), 100u - FakeEdgeLine::kQueue);
  std::array<EdgeEvent, 10> few{};
  EXPECT_EQ(line.read_events(few), 10);
  EXPECT_EQ(few[0].stamp, 100 - static_cast<TimeNs>(FakeEdgeLine::kQueue));  // the oldest kept
  EXPECT_TRUE(readable(line.event_fd(), 0)) << "events left: the fd stays readable";
  EStopEdges edges(line);
  ASSERT_TRUE(edges.drain());
  EXPECT_EQ(edges.edges(), FakeEdgeLine::kQueue - 10);
  EXPECT_FALSE(edges.pressed());  // the last edge (i = 99) released it
  EXPECT_FALSE(readable(line.event_fd(), 0));
}

TEST(GpioEdges, RealBackendFailsWithAClearMessageHere) {
  auto r = open_gpiod_edge_line("gpiochip9", 17, true, "airground-test");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("gpiochip9 line 17"), std::string::npos) << r.error().message;
}

// Samples a pattern over one second at 1 ms: (rising edges, on-time in ms).
std::tuple<int, int> shape(LedPattern p) {
  int rises = 0, on = 0;
  bool prev = led_level(p, kNsPerS - kNsPerMs);  // the patterns repeat every second
  for (TimeNs t = 0; t < kNsPerS; t += kNsPerMs) {
    const bool v = led_level(p, t);
    rises += v && !prev;
    on += v;
    prev = v;
  }
  return {rises, on};
}

TEST(GpioLed, RoleStatesHaveDistinctPatterns) {
  EXPECT_EQ(shape(led_pattern_for(RoleState::kBooting)), std::make_tuple(1, 500));
  EXPECT_EQ(shape(led_pattern_for(RoleState::kLocalizing)), std::make_tuple(4, 500));
  EXPECT_EQ(shape(led_pattern_for(RoleState::kTracking)), std::make_tuple(0, 1000));
  EXPECT_EQ(shape(led_pattern_for(RoleState::kFault)), std::make_tuple(2, 200));
  std::set<std::tuple<int, int>> shapes;
  for (RoleState s : {RoleState::kBooting, RoleState::kLocalizing, RoleState::kTracking, RoleState::kFault})
    shapes.insert(shape(led_pattern_for(s)));
  EXPECT_EQ(shapes.size(), 4u);
  EXPECT_STREQ(to_string(RoleState::kLocalizing), "localizing");
}

}  // namespace
}  // namespace ag::gpio
