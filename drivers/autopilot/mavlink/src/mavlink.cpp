// MAVLink payloads (little-endian, zero-extended when a v2 sender truncated them) and frame encoding.
#include "airground/drivers/autopilot/mavlink/mavlink.hpp"

#include <algorithm>
#include <cstring>

namespace ag::mavlink {

namespace {

// A payload copied into a zeroed buffer of the message's full length: the v2 truncation undone.
template <std::size_t N>
bool widen(std::span<const std::uint8_t> payload, std::array<std::uint8_t, N>& out) noexcept {
  if (payload.size() > N) return false;
  out.fill(0);
  std::memcpy(out.data(), payload.data(), payload.size());
  return true;
}

std::uint32_t u32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 | static_cast<std::uint32_t>(p[2]) << 16 |
         static_cast<std::uint32_t>(p[3]) << 24;
}
std::uint16_t u16(const std::uint8_t* p) noexcept { return static_cast<std::uint16_t>(p[0] | p[1] << 8); }
float f32(const std::uint8_t* p) noexcept {
  const std::uint32_t v = u32(p);
  float f;
  std::memcpy(&f, &v, sizeof f);
  return f;
}
void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
void put_f32(std::uint8_t* p, float f) noexcept {
  std::uint32_t v;
  std::memcpy(&v, &f, sizeof v);
  put_u32(p, v);
}

}  // namespace

bool decode(std::span<const std::uint8_t> payload, Heartbeat& out) noexcept {
  std::array<std::uint8_t, 9> b;
  if (!widen(payload, b)) return false;
  out.custom_mode = u32(&b[0]);
  out.type = b[4];
  out.autopilot = b[5];
  out.base_mode = b[6];
  out.system_status = b[7];
  out.mavlink_version = b[8];
  return true;
}

bool decode(std::span<const std::uint8_t> payload, Attitude& out) noexcept {
  std::array<std::uint8_t, 28> b;
  if (!widen(payload, b)) return false;
  out.time_boot_ms = u32(&b[0]);
  out.roll = f32(&b[4]);
  out.pitch = f32(&b[8]);
  out.yaw = f32(&b[12]);
  out.rollspeed = f32(&b[16]);
  out.pitchspeed = f32(&b[20]);
  out.yawspeed = f32(&b[24]);
  return true;
}

bool decode(std::span<const std::uint8_t> payload, AttitudeQuaternion& out) noexcept {
  std::array<std::uint8_t, 48> b;
  if (!widen(payload, b)) return false;
  out.time_boot_ms = u32(&b[0]);
  out.q1 = f32(&b[4]);
  out.q2 = f32(&b[8]);
  out.q3 = f32(&b[12]);
  out.q4 = f32(&b[16]);
  out.rollspeed = f32(&b[20]);
  out.pitchspeed = f32(&b[24]);
  out.yawspeed = f32(&b[28]);
  for (std::size_t i = 0; i < 4; ++i) out.repr_offset_q[i] = f32(&b[32 + 4 * i]);
  return true;
}

bool decode(std::span<const std::uint8_t> payload, CommandLong& out) noexcept {
  std::array<std::uint8_t, 33> b;
  if (!widen(payload, b)) return false;
  for (std::size_t i = 0; i < 7; ++i) out.param[i] = f32(&b[4 * i]);
  out.command = u16(&b[28]);
  out.target_system = b[30];
  out.target_component = b[31];
  out.confirmation = b[32];
  return true;
}

bool decode(std::span<const std::uint8_t> payload, CommandAck& out) noexcept {
  std::array<std::uint8_t, 10> b;
  if (!widen(payload, b)) return false;
  out.command = u16(&b[0]);
  out.result = b[2];
  out.progress = b[3];
  out.result_param2 = static_cast<std::int32_t>(u32(&b[4]));
  out.target_system = b[8];
  out.target_component = b[9];
  return true;
}

std::size_t encode(const Heartbeat& m, std::span<std::uint8_t> out) noexcept {
  if (out.size() < 9) return 0;
  put_u32(&out[0], m.custom_mode);
  out[4] = m.type;
  out[5] = m.autopilot;
  out[6] = m.base_mode;
  out[7] = m.system_status;
  out[8] = m.mavlink_version;
  return 9;
}

std::size_t encode(const Attitude& m, std::span<std::uint8_t> out) noexcept {
  if (out.size() < 28) return 0;
  put_u32(&out[0], m.time_boot_ms);
  put_f32(&out[4], m.roll);
  put_f32(&out[8], m.pitch);
  put_f32(&out[12], m.yaw);
  put_f32(&out[16], m.rollspeed);
  put_f32(&out[20], m.pitchspeed);
  put_f32(&out[24], m.yawspeed);
  return 28;
}

std::size_t encode(const AttitudeQuaternion& m, std::span<std::uint8_t> out) noexcept {
  if (out.size() < 48) return 0;
  put_u32(&out[0], m.time_boot_ms);
  put_f32(&out[4], m.q1);
  put_f32(&out[8], m.q2);
  put_f32(&out[12], m.q3);
  put_f32(&out[16], m.q4);
  put_f32(&out[20], m.rollspeed);
  put_f32(&out[24], m.pitchspeed);
  put_f32(&out[28], m.yawspeed);
  for (std::size_t i = 0; i < 4; ++i) put_f32(&out[32 + 4 * i], m.repr_offset_q[i]);
  return 48;
}

std::size_t encode(const CommandLong& m, std::span<std::uint8_t> out) noexcept {
  if (out.size() < 33) return 0;
  for (std::size_t i = 0; i < 7; ++i) put_f32(&out[4 * i], m.param[i]);
  put_u16(&out[28], m.command);
  out[30] = m.target_system;
  out[31] = m.target_component;
  out[32] = m.confirmation;
  return 33;
}

std::size_t encode(const CommandAck& m, std::span<std::uint8_t> out) noexcept {
  if (out.size() < 10) return 0;
  put_u16(&out[0], m.command);
  out[2] = m.result;
  out[3] = m.progress;
  put_u32(&out[4], static_cast<std::uint32_t>(m.result_param2));
  out[8] = m.target_system;
  out[9] = m.target_component;
  return 10;
}

std::size_t encode_frame(const FrameHeader& h, std::span<const std::uint8_t> payload, std::span<std::uint8_t> out, bool truncate,
                         const std::array<std::uint8_t, kSignatureBytes>* signature) noexcept {
  const MessageInfo* info = find_message(h.msgid);
  if (info == nullptr || payload.size() > kMaxPayload) return 0;
  std::size_t len = payload.size();
  std::size_t hdr = 0;
  if (h.version == 1) {
    if (h.msgid > 0xFF || signature != nullptr) return 0;
    len = std::min<std::size_t>(len, info->min_length);  // v1 has no extensions
    hdr = kHeaderV1;
  } else {
    if (truncate)
      while (len > 1 && payload[len - 1] == 0) --len;  // the first byte always stays
    hdr = kHeaderV2;
  }
  const std::size_t total = hdr + len + kChecksumBytes + (signature != nullptr ? kSignatureBytes : 0);
  if (out.size() < total) return 0;
  std::uint8_t* p = out.data();
  if (h.version == 1) {
    p[0] = kMagicV1;
    p[1] = static_cast<std::uint8_t>(len);
    p[2] = h.seq;
    p[3] = h.sysid;
    p[4] = h.compid;
    p[5] = static_cast<std::uint8_t>(h.msgid);
  } else {
    p[0] = kMagicV2;
    p[1] = static_cast<std::uint8_t>(len);
    p[2] = static_cast<std::uint8_t>(signature != nullptr ? (h.incompat_flags | kIncompatSigned) : (h.incompat_flags & ~kIncompatSigned));
    p[3] = h.compat_flags;
    p[4] = h.seq;
    p[5] = h.sysid;
    p[6] = h.compid;
    p[7] = static_cast<std::uint8_t>(h.msgid);
    p[8] = static_cast<std::uint8_t>(h.msgid >> 8);
    p[9] = static_cast<std::uint8_t>(h.msgid >> 16);
  }
  if (len > 0) std::memcpy(p + hdr, payload.data(), len);
  std::uint16_t crc = crc_x25(std::span<const std::uint8_t>(p + 1, hdr - 1 + len));
  crc = crc_accumulate(info->crc_extra, crc);
  p[hdr + len] = static_cast<std::uint8_t>(crc);
  p[hdr + len + 1] = static_cast<std::uint8_t>(crc >> 8);
  if (signature != nullptr) std::memcpy(p + hdr + len + kChecksumBytes, signature->data(), kSignatureBytes);
  return total;
}

}  // namespace ag::mavlink
