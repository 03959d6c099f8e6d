// The drive and base stages on one robot (RoleInstance, real config and channels), the base on the
// simulator's in-process CAN link with two simulated controllers and fake e-stop / LED lines:
// e-stop -> zero wheel commands in the next cycle, latched until released and re-armed; a stalled
// drive stage -> zero wheel velocity within 200 ms (the watchdog); bad configuration named.
#include <gtest/gtest.h>

#include <memory>

#include "airground/drivers/base/base_stage.hpp"
#include "airground/drivers/base/odrive_sim.hpp"
#include "airground/drivers/can/inprocess_bus.hpp"
#include "airground/messages/channels.hpp"
#include "airground/planning/stages.hpp"
#include "airground/platform/role_instance.hpp"

namespace ag::base {
namespace {

inline constexpr StageSpec kStages[] = {
    {"drive", &plan::DriveStage::make, 100.0, 2'000, 45, -1, plan::DriveStage::kParams, "drive control"},
    {"base", &BaseStage::make, 100.0, 2'000, 50, -1, BaseStage::kParams, "the base"},
};
inline constexpr RoleDescription kRole{"ugv", "drive + base rig", kStages, {}};
constexpr TimeNs kTick = 10 * kNsPerMs;

struct Rig {
  SimClock clock{0};
  can::InProcessCanLink link{clock};
  gpio::FakeLine estop, led;
  std::unique_ptr<OdriveSimulator> sim;
  std::unique_ptr<RoleInstance> role;
  plan::DriveStage* drive{nullptr};
  BaseStage* base{nullptr};
  LatestWriter<PlannedPathMsg> path_w;
  LatestWriter<LocalizationMsg> loc_w;
  LatestWriter<BaseArmMsg> arm_w, radio_arm_w;
  std::unique_ptr<PlannedPathMsg> path = std::make_unique<PlannedPathMsg>();
  Pose2 pose{};

  explicit Rig(std::vector<std::string> sets = {}) {
    can::register_inprocess_link("ugv1", &link);
    gpio::register_fake_line("ugv1", "estop", &estop);
    gpio::register_fake_line("ugv1", "led", &led);
    sim = std::make_unique<OdriveSimulator>(link.device(), std::array<std::uint8_t, 2>{0, 1});
    static const std::vector<ParamSection> schema = role_schema(kRole);
    Config cfg = Config::defaults(schema);
    sets.insert(sets.begin(), {"base.can_backend=sim", "base.estop_backend=fake", "base.led_backend=fake", "base.start_armed=true"});
    for (const auto& s : sets) EXPECT_TRUE(cfg.set(s).ok()) << s;
    auto r = RoleInstance::create(kRole, cfg, clock, "ugv1");
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    if (!r.ok()) return;
    role = std::move(r).value();
    drive = dynamic_cast<plan::DriveStage*>(role->stages()[0].stage.get());
    base = dynamic_cast<BaseStage*>(role->stages()[1].stage.get());
    path_w = role->channels().latest_writer(chan::kPlannedPath).value();
    loc_w = role->channels().latest_writer(chan::kLocalization).value();
    arm_w = role->channels().latest_writer(chan::kBaseArm).value();
    radio_arm_w = role->channels().latest_writer(chan::kRadioArm).value();
  }
  ~Rig() {
    role.reset();
    can::unregister_inprocess_link("ugv1");
    gpio::unregister_fake_lines("ugv1");
  }
  void send_straight_path() {
    path->seq = 1;
    path->status = RouteStatus::kOk;
    path->count = 2;
    path->points[0] = RoutePoint{0, 0};
    path->points[1] = RoutePoint{100, 0};
    path_w.publish(*path);
  }
  // One 10 ms tick: the controllers, then (unless stalled) drive, then base; the robot moves by the
  // odometry of the simulated wheels (perfect localization).
  void tick(bool drive_runs = true) {
    clock.set(clock.now() + kTick);
    sim->step(clock.now());
    LocalizationMsg m;
    m.stamp = clock.now();
    m.status = LocalizationStatus::kTracking;
    m.pose = base->base().odometry().pose;
    loc_w.publish(m);
    if (drive_runs) drive->step(clock.now());
    base->step(clock.now());
  }
  [[nodiscard]] bool wheels_zero() const {
    return base->base().sent_velocity(0) == 0.0F && base->base().sent_velocity(1) == 0.0F;
  }
};

TEST(BaseStage, EStopZeroesTheWheelsInTheNextCycleAndLatchesUntilReArmed) {
  Rig rig;
  ASSERT_NE(rig.base, nullptr);
  rig.send_straight_path();
  for (int i = 0; i < 200; ++i) rig.tick();
  ASSERT_EQ(rig.base->base().status().state, BaseState::kRunning);
  ASSERT_GT(rig.base->published().left_cmd_mps, 0.3) << "driving";
  EXPECT_TRUE(rig.led.value()) << "LED on while running";
  rig.estop.press(true);
  rig.tick();
  EXPECT_TRUE(rig.wheels_zero()) << "zero wheel commands in the cycle the e-stop is seen";
  EXPECT_EQ(rig.base->published().left_cmd_mps, 0.0);
  EXPECT_EQ(rig.base->published().estop, static_cast<std::uint8_t>(gpio::EStopState::kAsserted));
  for (int i = 0; i < 30; ++i) {
    rig.tick();
    EXPECT_TRUE(rig.wheels_zero());
  }
  rig.estop.press(false);
  for (int i = 0; i < 30; ++i) {
    rig.tick();
    EXPECT_TRUE(rig.wheels_zero()) << "released but not re-armed";
  }
  EXPECT_EQ(rig.base->estop().state(), gpio::EStopState::kLatched);
  BaseArmMsg a;
  a.stamp = rig.clock.now();
  rig.arm_w.publish(a);
  rig.tick();
  EXPECT_FALSE(rig.wheels_zero()) << "re-armed: driving again";
  EXPECT_EQ(rig.base->estop().assertions(), 1U);
}

// The shipped configuration starts latched (base.start_armed: false): the base station's arm over the
// radio (comms -> "radio_arm") starts the wheels, its disarm stops them, and a re-arm drives again.
TEST(BaseStage, TheBaseStationArmsAndDisarmsOverTheRadio) {
  Rig rig({"base.start_armed=false"});
  ASSERT_NE(rig.base, nullptr);
  rig.send_straight_path();
  for (int i = 0; i < 100; ++i) rig.tick();
  EXPECT_TRUE(rig.wheels_zero()) << "not armed yet";
  EXPECT_EQ(rig.base->estop().state(), gpio::EStopState::kLatched);
  rig.radio_arm_w.publish(BaseArmMsg{rig.clock.now(), rig.clock.now(), true});
  for (int i = 0; i < 100; ++i) rig.tick();
  EXPECT_FALSE(rig.wheels_zero()) << "armed over the radio: driving";
  EXPECT_GT(rig.base->published().left_cmd_mps, 0.3);
  rig.radio_arm_w.publish(BaseArmMsg{rig.clock.now(), rig.clock.now(), false});
  for (int i = 0; i < 5; ++i) rig.tick();
  EXPECT_TRUE(rig.wheels_zero()) << "disarmed over the radio";
  rig.radio_arm_w.publish(BaseArmMsg{rig.clock.now(), rig.clock.now(), true});
  for (int i = 0; i < 100; ++i) rig.tick();
  EXPECT_FALSE(rig.wheels_zero()) << "armed again";
}

TEST(BaseStage, ARearmWhileTheButtonIsStillPressedDoesNotDrive) {
  Rig rig;
  rig.send_straight_path();
  for (int i = 0; i < 50; ++i) rig.tick();
  rig.estop.press(true);
  rig.tick();
  BaseArmMsg a;
  a.stamp = rig.clock.now();
  rig.arm_w.publish(a);  // re-arm before the release is ignored
  rig.tick();
  rig.estop.press(false);
  for (int i = 0; i < 10; ++i) rig.tick();
  EXPECT_TRUE(rig.wheels_zero());
}

TEST(BaseStage, AnUnreadableEStopLineStops) {
  Rig rig;
  rig.send_straight_path();
  for (int i = 0; i < 100; ++i) rig.tick();
  ASSERT_FALSE(rig.wheels_zero());
  rig.estop.fail(true);
  rig.tick();
  EXPECT_TRUE(rig.wheels_zero());
  EXPECT_EQ(rig.base->estop().state(), gpio::EStopState::kLineFault);
}

TEST(BaseStage, AStalledDriveStageStopsTheWheelsWithin200ms) {
  Rig rig;
  rig.send_straight_path();
  for (int i = 0; i < 200; ++i) rig.tick();
  ASSERT_FALSE(rig.wheels_zero());
  const TimeNs stall = rig.clock.now();
  TimeNs zero_at = -1;
  for (int i = 0; i < 50 && zero_at < 0; ++i) {
    rig.tick(false);  // the drive stage no longer runs (and so no fresh wheel_command)
    if (rig.wheels_zero()) zero_at = rig.clock.now();
  }
  ASSERT_GE(zero_at, 0);
  EXPECT_LE(zero_at - stall, 200 * kNsPerMs + kTick);
  EXPECT_EQ(rig.base->published().watchdog_trips, 1U);
  for (int i = 0; i < 10; ++i) rig.tick();
  EXPECT_FALSE(rig.wheels_zero()) << "the drive stage is back";
}

TEST(BaseStage, MissingSimulatorDevicesEqualNodeIdsAndBadReplayOrBridgeSettingsAreConfigErrors) {
  static const std::vector<ParamSection> schema = role_schema(kRole);
  SimClock clock(0);
  Config cfg = Config::defaults(schema);
  ASSERT_TRUE(cfg.set("base.can_backend=sim").ok());
  auto r = RoleInstance::create(kRole, cfg, clock, "ugv9");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("ugv9"), std::string::npos) << r.error().message;
  Config c3 = Config::defaults(schema);
  ASSERT_TRUE(c3.set("base.right_node_id=0").ok());
  auto r3 = RoleInstance::create(kRole, c3, clock, "ugv9");
  ASSERT_FALSE(r3.ok());
  EXPECT_NE(r3.error().message.find("left_node_id and right_node_id"), std::string::npos) << r3.error().message;
  Config c4 = Config::defaults(schema);
  ASSERT_TRUE(c4.set("base.can_backend=replay").ok());
  auto r4 = RoleInstance::create(kRole, c4, clock, "ugv9");
  ASSERT_FALSE(r4.ok());
  EXPECT_NE(r4.error().message.find("can_replay_path is empty"), std::string::npos) << r4.error().message;
  Config c5 = Config::defaults(schema);
  ASSERT_TRUE(c5.set("base.can_backend=cannelloni").ok());
  ASSERT_TRUE(c5.set("base.can_bridge_remote=localhost").ok());
  auto r5 = RoleInstance::create(kRole, c5, clock, "ugv9");
  ASSERT_FALSE(r5.ok());
  EXPECT_NE(r5.error().message.find("not HOST:PORT"), std::string::npos) << r5.error().message;
}

// A robot whose CAN interface and GPIO chip are missing still starts (it localizes and relays for the
// team); the missing devices are counted, the bus faults at arming and the wheels get nothing.
TEST(BaseStage, AMissingCanInterfaceAndGpioChipLeaveTheWheelsStoppedNotTheRobotDown) {
  static const std::vector<ParamSection> schema = role_schema(kRole);
  SimClock clock(0);
  Config c2 = Config::defaults(schema);
  ASSERT_TRUE(c2.set("base.can_interface=agnocan0").ok());
  ASSERT_TRUE(c2.set("base.estop_chip=/dev/agnochip").ok());
  ASSERT_TRUE(c2.set("base.led_chip=/dev/agnochip").ok());
  ASSERT_TRUE(c2.set("base.start_armed=true").ok());
  auto r2 = RoleInstance::create(kRole, c2, clock, "ugv9");
  ASSERT_TRUE(r2.ok()) << r2.error().message;
  BaseStage* b = find_stage<BaseStage>(r2.value().get());
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(b->counters().device_errors, 3U) << "CAN interface, e-stop line, LED line";
  for (int k = 0; k < 10; ++k) {
    clock.set(k * 10 * kNsPerMs);
    b->step(clock.now());
  }
  EXPECT_EQ(b->base().status().state, BaseState::kFault);
  EXPECT_EQ(b->base().status().fault, BaseFault::kBusDown);
  EXPECT_EQ(b->bus().counters().tx, 0U) << "nothing reached a bus";
  EXPECT_GT(b->bus().counters().tx_dropped, 0U);
  EXPECT_EQ(b->published().state, static_cast<std::uint8_t>(BaseState::kFault));
  EXPECT_EQ(b->estop().state(), gpio::EStopState::kLineFault) << "a missing e-stop line reads as unreadable";
}

}  // namespace
}  // namespace ag::base
