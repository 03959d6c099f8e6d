// Channel topics (airground/messages/channels.hpp): a constant naming a channel with its type and ring size
// reaches the same channel as its string name, and the registry still refuses a name used with two types.
#include "airground/messages/channels.hpp"

#include <gtest/gtest.h>

#include "airground/comms/messages.hpp"
#include "airground/mission/messages.hpp"
#include "airground/platform/status_stage.hpp"

#include <array>
#include <string>
#include <string_view>

namespace ag {
namespace {

TEST(ChannelTopics, WriterAndReadersThroughATopicShareTheChannel) {
  ChannelRegistry reg;
  auto w = reg.latest_writer(chan::kLocalization);
  auto r = reg.latest_reader(chan::kLocalization);
  auto by_name = reg.latest_reader<LocalizationMsg>("localization");  // tools and tests may still use the name
  auto rw = reg.ring_writer(chan::kWheelOdometry);
  auto rr = reg.ring_reader(chan::kWheelOdometry);
  auto tap = reg.ring_tap(chan::kWheelOdometry);
  ASSERT_TRUE(w.ok() && r.ok() && by_name.ok() && rw.ok() && rr.ok() && tap.ok());
  EXPECT_EQ(reg.size(), 2u);
  reg.seal();
  EXPECT_TRUE(reg.read_but_unwritten().empty());

  LocalizationMsg m;
  m.stamp = 42;
  w.value().publish(m);
  EXPECT_EQ(r.value().read().stamp, 42);
  EXPECT_EQ(by_name.value().read().stamp, 42);

  WheelOdometryMsg o;
  o.stamp = 7;
  EXPECT_EQ(rw.value().push(o), 0u);
  const WheelOdometryMsg* got = rr.value().front();
  const WheelOdometryMsg* tapped = tap.value().front();
  EXPECT_EQ(got != nullptr ? got->stamp : TimeNs{-1}, 7);
  EXPECT_EQ(tapped != nullptr ? tapped->stamp : TimeNs{-1}, 7);
  EXPECT_EQ(rw.value().free_slots(), kWheelOdometryRing - 1);  // the ring size came from the topic
}

TEST(ChannelTopics, AStringReaderOfAnotherTypeIsStillRefused) {
  ChannelRegistry reg;
  ASSERT_TRUE(reg.latest_writer(chan::kLocalization).ok());
  auto wrong = reg.latest_reader<InitialPoseMsg>("localization");
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(wrong.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(wrong.error().message.find("'localization'"), std::string::npos);
  EXPECT_NE(wrong.error().message.find("two different message types"), std::string::npos);

  // The ring size is part of the type; and a string writer of another type refuses a topic reader.
  ASSERT_TRUE(reg.ring_writer(chan::kWheelOdometry).ok());
  EXPECT_FALSE((reg.ring_reader<WheelOdometryMsg, kWheelOdometryRing / 2>("wheel_odometry").ok()));
  ASSERT_TRUE(reg.latest_writer<int>("goal").ok());
  EXPECT_FALSE(reg.latest_reader(chan::kGoal).ok());
  EXPECT_EQ(reg.size(), 3u);  // refused lookups add no channel
}

TEST(ChannelTopics, WithNameKeepsTheTypeUnderAConfiguredName) {
  ChannelRegistry reg;
  const std::string configured = "visual_odometry_own";  // a driver's *_channel parameter
  auto w = reg.ring_writer(chan::kVisualOdometry.with_name(configured));
  auto r = reg.ring_reader(chan::kVisualOdometryOwn);
  ASSERT_TRUE(w.ok() && r.ok());
  EXPECT_EQ(reg.size(), 1u);
  ASSERT_TRUE(reg.latest_reader(chan::kInitialPose).ok());
  reg.allow_unwritten(chan::kInitialPose);
  EXPECT_TRUE(reg.read_but_unwritten().empty());
}

TEST(ChannelTopics, NamesAreTheRecordedOnesAndDistinct) {
  // Recordings and the Foxglove output carry these names.
  static_assert(chan::kMapTiles.name == "map_tiles");
  static_assert(chan::kLocalization.name == "localization");
  static_assert(chan::kSchedulerStatus.name == "scheduler_status");
  static_assert(chan::names_distinct(chan::kNames));
  // Every channel of every layer at once (each pipeline/ header checks only its own against messages/'s).
  constexpr std::array<std::string_view, 1> kPlatformNames{chan::kSchedulerStatus.name};
  static_assert(chan::names_distinct(chan::kNames, chan::kCommsNames, chan::kMissionNames, kPlatformNames));
  constexpr std::array<std::string_view, 1> kClash{"planned_path"};
  static_assert(!chan::names_distinct(chan::kNames, kClash));
  constexpr std::array<std::string_view, 3> kDuplicate{"a", "b", "a"};
  EXPECT_FALSE(chan::names_distinct(kDuplicate));
  EXPECT_TRUE(chan::names_distinct(chan::kNames));
}

}  // namespace
}  // namespace ag
