// MAVLink (mavlink.io/en/guide/serialization.html, mavlink.io/en/guide/mavlink_2.html), transcribed:
//
//   v1 frame: 0xFE len seq sysid compid msgid                          payload[len] crc(u16 LE)
//   v2 frame: 0xFD len incompat compat seq sysid compid msgid(u24 LE)  payload[len] crc(u16 LE) [signature 13]
//
// The CRC is CRC-16/MCRF4XX (X.25 polynomial 0x1021 reflected, init 0xFFFF, no final XOR) over every
// byte after the magic up to the end of the payload, then the message's CRC_EXTRA byte (a hash of its
// definition, so both ends agree on the layout). incompat flag 0x01: the frame is signed and 13 bytes
// follow the CRC (link id u8, timestamp u48, signature 6 B); any other incompat bit must be refused.
// v2 senders drop the payload's trailing zero bytes (never the first byte); a receiver zero-extends it
// to the message's length. Payload fields are little-endian, ordered by size (largest first), with the
// extension fields appended in definition order after the base fields.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace ag::mavlink {

inline constexpr std::uint8_t kMagicV1 = 0xFE, kMagicV2 = 0xFD;
inline constexpr std::size_t kHeaderV1 = 6, kHeaderV2 = 10;  // with the magic byte
inline constexpr std::size_t kChecksumBytes = 2, kSignatureBytes = 13;
inline constexpr std::size_t kMaxPayload = 255;
inline constexpr std::size_t kMaxFrame = kHeaderV2 + kMaxPayload + kChecksumBytes + kSignatureBytes;  // 280
inline constexpr std::uint8_t kIncompatSigned = 0x01;

// CRC-16/MCRF4XX, one byte at a time (the MAVLink C library's crc_accumulate).
[[nodiscard]] constexpr std::uint16_t crc_accumulate(std::uint8_t b, std::uint16_t crc) noexcept {
  std::uint8_t t = static_cast<std::uint8_t>(b ^ (crc & 0xFF));
  t = static_cast<std::uint8_t>(t ^ (t << 4));
  return static_cast<std::uint16_t>((crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4));
}
[[nodiscard]] constexpr std::uint16_t crc_x25(std::span<const std::uint8_t> bytes, std::uint16_t crc = 0xFFFF) noexcept {
  for (const std::uint8_t b : bytes) crc = crc_accumulate(b, crc);
  return crc;
}

// One row of the message table (src/message_table.cpp): what a receiver needs to check a frame.
struct MessageInfo {
  std::uint32_t id;
  std::uint8_t crc_extra;
  std::uint8_t min_length;  // base fields [bytes]: what a v1 frame carries
  std::uint8_t max_length;  // with the extension fields [bytes]
};
// The row of `id` in the minimal, common and ardupilotmega dialects; nullptr for any other id.
[[nodiscard]] const MessageInfo* find_message(std::uint32_t id) noexcept;
[[nodiscard]] std::size_t message_count() noexcept;

// Message ids, commands and enum values used here (common.xml / minimal.xml).
inline constexpr std::uint32_t kIdHeartbeat = 0;
inline constexpr std::uint32_t kIdAttitude = 30;
inline constexpr std::uint32_t kIdAttitudeQuaternion = 31;
inline constexpr std::uint32_t kIdCommandLong = 76;
inline constexpr std::uint32_t kIdCommandAck = 77;
inline constexpr std::uint32_t kIdMessageInterval = 244;
inline constexpr std::uint16_t kCmdSetMessageInterval = 511;  // MAV_CMD_SET_MESSAGE_INTERVAL, sent in COMMAND_LONG
inline constexpr std::uint8_t kAutopilotArdupilot = 3, kAutopilotPx4 = 12;  // MAV_AUTOPILOT
inline constexpr std::uint8_t kCompAutopilot1 = 1, kCompOnboardComputer = 191;  // MAV_COMPONENT
inline constexpr std::uint8_t kResultAccepted = 0;  // MAV_RESULT_ACCEPTED

struct FrameHeader {
  std::uint8_t version{2};      // 1 (0xFE) or 2 (0xFD)
  std::uint8_t incompat_flags{0}, compat_flags{0};  // v2 only
  std::uint8_t seq{0};
  std::uint8_t sysid{0}, compid{0};
  std::uint32_t msgid{0};       // 0..255 in v1, 24 bits in v2
};

// HEARTBEAT (0, 9 bytes): custom_mode u32, type u8, autopilot u8, base_mode u8, system_status u8, mavlink_version u8.
struct Heartbeat {
  static constexpr std::uint32_t kId = kIdHeartbeat;
  std::uint32_t custom_mode{0};
  std::uint8_t type{0}, autopilot{0}, base_mode{0}, system_status{0}, mavlink_version{3};
};
// ATTITUDE (30, 28 bytes): the autopilot's attitude, aeronautical frame (FRD body in NED), ZYX Euler.
struct Attitude {
  static constexpr std::uint32_t kId = kIdAttitude;
  std::uint32_t time_boot_ms{0};  // [ms] since the autopilot booted
  float roll{0}, pitch{0}, yaw{0};                    // [rad] -pi..pi
  float rollspeed{0}, pitchspeed{0}, yawspeed{0};     // [rad/s] body FRD rates
};
// ATTITUDE_QUATERNION (31, 32 bytes + extension repr_offset_q 16 bytes): q1..q4 = w, x, y, z (FRD to NED).
struct AttitudeQuaternion {
  static constexpr std::uint32_t kId = kIdAttitudeQuaternion;
  std::uint32_t time_boot_ms{0};
  float q1{1}, q2{0}, q3{0}, q4{0};
  float rollspeed{0}, pitchspeed{0}, yawspeed{0};
  std::array<float, 4> repr_offset_q{0, 0, 0, 0};
};
// COMMAND_LONG (76, 33 bytes): param1..7 f32, command u16, target_system u8, target_component u8, confirmation u8.
struct CommandLong {
  static constexpr std::uint32_t kId = kIdCommandLong;
  std::array<float, 7> param{0, 0, 0, 0, 0, 0, 0};
  std::uint16_t command{0};
  std::uint8_t target_system{0}, target_component{0}, confirmation{0};
};
// COMMAND_ACK (77, 3 bytes + extensions progress u8, result_param2 i32, target_system u8, target_component u8).
struct CommandAck {
  static constexpr std::uint32_t kId = kIdCommandAck;
  std::uint16_t command{0};
  std::uint8_t result{0}, progress{0};
  std::int32_t result_param2{0};
  std::uint8_t target_system{0}, target_component{0};
};

// Payload decoders: the payload as received (a v2 payload may be cut short: it is zero-extended);
// false when it is longer than the message.
[[nodiscard]] bool decode(std::span<const std::uint8_t> payload, Heartbeat& out) noexcept;
[[nodiscard]] bool decode(std::span<const std::uint8_t> payload, Attitude& out) noexcept;
[[nodiscard]] bool decode(std::span<const std::uint8_t> payload, AttitudeQuaternion& out) noexcept;
[[nodiscard]] bool decode(std::span<const std::uint8_t> payload, CommandLong& out) noexcept;
[[nodiscard]] bool decode(std::span<const std::uint8_t> payload, CommandAck& out) noexcept;

// Payload encoders: the whole payload with extensions (encode_frame drops what v1 or truncation omit);
// return its size, 0 when `out` is too small.
std::size_t encode(const Heartbeat& m, std::span<std::uint8_t> out) noexcept;
std::size_t encode(const Attitude& m, std::span<std::uint8_t> out) noexcept;
std::size_t encode(const AttitudeQuaternion& m, std::span<std::uint8_t> out) noexcept;
std::size_t encode(const CommandLong& m, std::span<std::uint8_t> out) noexcept;
std::size_t encode(const CommandAck& m, std::span<std::uint8_t> out) noexcept;

// A whole frame of h.version for a message in the table: v1 carries the base fields only; v2 drops
// trailing zeros unless `truncate` is false, and appends `signature` (13 bytes) with the signed flag
// set when one is given (the signature itself is the caller's: this side does not sign). Returns the
// frame's size; 0 when the id is not in the table, the payload is too long or `out` too small.
std::size_t encode_frame(const FrameHeader& h, std::span<const std::uint8_t> payload, std::span<std::uint8_t> out,
                         bool truncate = true, const std::array<std::uint8_t, kSignatureBytes>* signature = nullptr) noexcept;

// Typed shorthand: encode(m) then encode_frame with msgid = the message's id.
template <typename Msg>
std::size_t encode_message(FrameHeader h, const Msg& m, std::span<std::uint8_t> out, bool truncate = true) noexcept {
  std::array<std::uint8_t, kMaxPayload> payload{};
  const std::size_t n = encode(m, payload);
  h.msgid = Msg::kId;
  return encode_frame(h, std::span<const std::uint8_t>(payload.data(), n), out, truncate);
}

}  // namespace ag::mavlink
