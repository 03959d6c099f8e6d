// Every CAN Simple signal we send or read, checked against the vendor's DBC (parsed, not hand-copied):
// identifier (node << 5 | message id), length, and each signal's value decoded from our frame's bytes
// through the DBC's start bit, length, byte order and value type.
#include <gtest/gtest.h>

#include <cstring>

#include "airground/drivers/base/odrive_can_simple.hpp"
#include "airground/drivers/can/dbc.hpp"

namespace ag::odrive {
namespace {

const can::Dbc& dbc() {
  static const can::Dbc d = [] {
    auto r = can::read_dbc_file(std::string(AG_TEST_DATA_DIR) + "/can/odrive-cansimple.dbc");
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    return r.ok() ? r.value() : can::Dbc{};
  }();
  return d;
}

std::uint32_t bits(float v) {
  std::uint32_t b = 0;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

void expect_layout(const can::CanFrame& f, std::string_view message, std::uint8_t node) {
  const can::DbcMessage* m = dbc().message(message);
  ASSERT_NE(m, nullptr) << message;
  EXPECT_EQ(f.id, (static_cast<std::uint32_t>(node) << 5) | m->id) << message;
  EXPECT_EQ(static_cast<int>(f.dlc), m->dlc) << message;
  EXPECT_FALSE(f.extended);
  EXPECT_EQ(cmd_of(f.id), m->id);
  EXPECT_EQ(node_of(f.id), node);
  for (const auto& s : m->signals) EXPECT_TRUE(s.little_endian) << s.name << ": our codec is little-endian";
}

TEST(OdriveDbc, TheFixtureParses) {
  ASSERT_GE(dbc().messages.size(), 20U);
  const can::DbcSignal* pos = dbc().message("Get_Encoder_Estimates")->signal("Pos_Estimate");
  ASSERT_NE(pos, nullptr);
  EXPECT_EQ(pos->float_type, 1) << "SIG_VALTYPE_ 9 Pos_Estimate : 1";
  EXPECT_EQ(pos->start_bit, 0);
  EXPECT_EQ(pos->length, 32);
  EXPECT_EQ(dbc().message(13U)->name, "Set_Input_Vel");
}

TEST(OdriveDbc, SetInputVelMatchesTheDbc) {
  for (const std::uint8_t node : {std::uint8_t{0}, std::uint8_t{1}, std::uint8_t{5}, std::uint8_t{0x3F}}) {
    const can::CanFrame f = encode_set_input_vel(node, -3.25F, 0.5F);
    expect_layout(f, "Set_Input_Vel", node);
    const can::DbcMessage* m = dbc().message("Set_Input_Vel");
    // The DBC declares these as 32-bit fields without a float value type; their bits are IEEE binary32.
    EXPECT_EQ(m->signal("Input_Vel")->raw(f), bits(-3.25F));
    EXPECT_EQ(m->signal("Input_Torque_FF")->raw(f), bits(0.5F));
    EXPECT_EQ(m->signal("Input_Vel")->length, 32);
    EXPECT_EQ(static_cast<std::uint32_t>(Cmd::kSetInputVel), m->id);
  }
}

TEST(OdriveDbc, SetAxisStateAndControllerModeMatchTheDbc) {
  const can::CanFrame s = encode_set_axis_state(3, AxisState::kClosedLoopControl);
  expect_layout(s, "Set_Axis_State", 3);
  EXPECT_EQ(dbc().message("Set_Axis_State")->signal("Axis_Requested_State")->decode(s), 8.0);
  const can::CanFrame m = encode_set_controller_mode(3, kControlModeVelocity, kInputModePassthrough);
  expect_layout(m, "Set_Controller_Mode", 3);
  EXPECT_EQ(dbc().message("Set_Controller_Mode")->signal("Control_Mode")->decode(m), 2.0);
  EXPECT_EQ(dbc().message("Set_Controller_Mode")->signal("Input_Mode")->decode(m), 1.0);
}

TEST(OdriveDbc, HeartbeatWeReadMatchesTheDbc) {
  const can::CanFrame f = encode_heartbeat(2, {0x00000800U, 8U});
  expect_layout(f, "Heartbeat", 2);
  const can::DbcMessage* m = dbc().message("Heartbeat");
  EXPECT_EQ(m->signal("Axis_Error")->decode(f), 2048.0);
  EXPECT_EQ(m->signal("Axis_State")->decode(f), 8.0);
  // And the other way: a frame built from the DBC's layout decodes with our decoder.
  can::CanFrame g;
  g.id = (7U << 5) | m->id;
  g.dlc = static_cast<std::uint8_t>(m->dlc);
  const auto put = [&](const can::DbcSignal& s, std::uint64_t v) {
    for (int b = 0; b < s.length; ++b)
      if ((v >> b & 1) != 0) g.data[static_cast<std::size_t>((s.start_bit + b) / 8)] |= static_cast<std::uint8_t>(1U << ((s.start_bit + b) % 8));
  };
  put(*m->signal("Axis_Error"), 0x12345678U);
  put(*m->signal("Axis_State"), 1U);
  Heartbeat hb;
  ASSERT_TRUE(decode_heartbeat(g, hb));
  EXPECT_EQ(hb.axis_error, 0x12345678U);
  EXPECT_EQ(hb.axis_state, 1U);
}

TEST(OdriveDbc, EncoderEstimatesWeReadMatchTheDbc) {
  const can::CanFrame f = encode_encoder_estimates(1, {12.5F, -0.75F});
  expect_layout(f, "Get_Encoder_Estimates", 1);
  const can::DbcMessage* m = dbc().message("Get_Encoder_Estimates");
  EXPECT_EQ(m->signal("Pos_Estimate")->decode(f), 12.5);
  EXPECT_EQ(m->signal("Vel_Estimate")->decode(f), -0.75);
  EncoderEstimates e;
  ASSERT_TRUE(decode_encoder_estimates(f, e));
  EXPECT_EQ(e.pos_turns, 12.5F);
  can::CanFrame wrong = f;
  wrong.dlc = 4;
  EXPECT_FALSE(decode_encoder_estimates(wrong, e)) << "short frame";
  wrong = f;
  wrong.id = (1U << 5) | 0x01U;
  EXPECT_FALSE(decode_encoder_estimates(wrong, e)) << "another command";
}

TEST(OdriveDbc, MalformedDbcIsNamed) {
  auto r = can::parse_dbc("BO_ 1 Heartbeat: 8 X\n SG_ Axis_State : 32|40@1+ (1,0) [0|0] \"\" X\n", "t.dbc");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("t.dbc:2"), std::string::npos) << r.error().message;
  EXPECT_FALSE(can::parse_dbc("", "empty.dbc").ok());
}

}  // namespace
}  // namespace ag::odrive
