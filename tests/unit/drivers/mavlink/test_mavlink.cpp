// The MAVLink driver on real bytes (tests/data/mavlink, from node-mavlink's examples, LGPL-3.0): a PX4
// vehicle's v2 stream (3412 frames), a PX4 stream mixing v1 and v2 behind garbage, and an ArduPilot
// SITL QuadPlane .tlog. Hand-decoded fields, CRC, resynchronisation, v2 truncation, signing, the
// error kinds, the FRD/NED to FLU/ENU conversion, and the serial (pty), UDP and tlog links.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <vector>

#include "airground/drivers/autopilot/mavlink/frame_parser.hpp"
#include "airground/drivers/autopilot/mavlink/frames.hpp"
#include "airground/drivers/autopilot/mavlink/link.hpp"
#include "airground/drivers/autopilot/mavlink/mavlink.hpp"

namespace ag::mavlink {
namespace {

using Bytes = std::vector<std::uint8_t>;
const std::string kDir = std::string(AG_TEST_DATA_DIR) + "/mavlink/";
constexpr double kPi = 3.14159265358979323846;

Bytes load(const std::string& name) {
  std::ifstream in(kDir + name, std::ios::binary);
  EXPECT_TRUE(in.good()) << kDir + name;
  return Bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

struct Parsed {
  std::vector<FrameHeader> headers;
  std::vector<Bytes> payloads;
  std::vector<Bytes> wire;
  ParserCounters counters;
};

// Feeds `bytes` in `chunk`-sized pieces, as a serial port delivers them.
Parsed parse_stream(std::span<const std::uint8_t> bytes, std::size_t chunk = 64) {
  FrameParser p;
  Parsed out;
  Frame f;
  auto take = [&] {
    while (p.next(f)) {
      out.headers.push_back(f.header);
      out.payloads.emplace_back(f.payload.begin(), f.payload.end());
      const std::uint8_t* start = f.payload.data() - (f.header.version == 2 ? kHeaderV2 : kHeaderV1);
      out.wire.emplace_back(start, start + f.wire_bytes);
    }
  };
  for (std::size_t i = 0; i < bytes.size(); i += chunk) {
    auto in = bytes.subspan(i, std::min(chunk, bytes.size() - i));
    while (!in.empty()) {
      in = in.subspan(p.feed(in));
      take();
    }
  }
  p.end_of_packet();  // the end of the input: a false start still waiting for bytes is given up
  take();
  out.counters = p.counters();
  return out;
}

TEST(MavlinkCrc, CheckValueOfCrc16Mcrf4xx) {
  const std::uint8_t s[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
  EXPECT_EQ(crc_x25(s), 0x6F91);  // the catalogued check value of CRC-16/MCRF4XX
  ASSERT_NE(find_message(kIdAttitude), nullptr);
  EXPECT_EQ(find_message(kIdAttitude)->crc_extra, 39);
  EXPECT_EQ(find_message(kIdAttitudeQuaternion)->crc_extra, 246);
  EXPECT_EQ(find_message(kIdHeartbeat)->crc_extra, 50);
  EXPECT_EQ(find_message(kIdCommandLong)->crc_extra, 152);
  EXPECT_EQ(find_message(kIdAttitudeQuaternion)->min_length, 32);
  EXPECT_EQ(find_message(kIdAttitudeQuaternion)->max_length, 48);
  EXPECT_EQ(find_message(0xABCDEF), nullptr);
}

// The first ATTITUDE of the PX4 capture, at byte 44, decoded by hand from its bytes.
TEST(MavlinkPx4Capture, FirstAttitudeDecodedByHand) {
  const Bytes d = load("px4-v2-3412-packets.bin");
  const Bytes frame = {0xfd, 0x1c, 0x00, 0x00, 0xb4, 0x01, 0x01, 0x1e, 0x00, 0x00,  // v2, len 28, seq 180, 1/1, id 30
                       0x14, 0x26, 0xc1, 0x00,   // time_boot_ms 0x00C12614 = 12658196
                       0xb3, 0xc7, 0x0a, 0xbb,   // roll 0xBB0AC7B3: -(1 + 0x0AC7B3/2^23) * 2^(118-127) = -0.0021176
                       0x52, 0x77, 0xf5, 0x3b,   // pitch 0x3BF57752: (1 + 0x757752/2^23) * 2^-8 = 0.0074910
                       0xf2, 0x52, 0xc6, 0x3f,   // yaw 0x3FC652F2: 1 + 0x4652F2/2^23 = 1.5494063
                       0x68, 0x09, 0xb9, 0x3b,   // rollspeed 0x3BB90968: (1 + 0x390968/2^23) * 2^-8 = 0.0056469
                       0xe3, 0x13, 0x1b, 0x3b,   // pitchspeed 0x3B1B13E3: (1 + 0x1B13E3/2^23) * 2^-9 = 0.0023663
                       0xef, 0x19, 0xe7, 0x3a,   // yawspeed 0x3AE719EF: (1 + 0x6719EF/2^23) * 2^-10 = 0.0017632
                       0x6d, 0x8d};              // CRC 0x8D6D
  ASSERT_GE(d.size(), 44 + frame.size());
  ASSERT_TRUE(std::equal(frame.begin(), frame.end(), d.begin() + 44)) << "the literal is the capture's bytes";
  const Parsed p = parse_stream(frame);
  ASSERT_EQ(p.headers.size(), 1u);
  EXPECT_EQ(p.headers[0].version, 2);
  EXPECT_EQ(p.headers[0].seq, 180);
  EXPECT_EQ(p.headers[0].sysid, 1);
  EXPECT_EQ(p.headers[0].compid, 1);
  EXPECT_EQ(p.headers[0].msgid, 30u);
  Attitude a;
  ASSERT_TRUE(decode(p.payloads[0], a));
  EXPECT_EQ(a.time_boot_ms, 12658196u);
  EXPECT_NEAR(a.roll, -0.0021176, 1e-7);
  EXPECT_NEAR(a.pitch, 0.0074910, 1e-7);
  EXPECT_NEAR(a.yaw, 1.5494063, 1e-7);
  EXPECT_NEAR(a.rollspeed, 0.0056469, 1e-7);
  EXPECT_NEAR(a.pitchspeed, 0.0023663, 1e-7);
  EXPECT_NEAR(a.yawspeed, 0.0017632, 1e-7);
  // Hand: REP-103 keeps the roll, negates the pitch and the y/z rates, yaw = pi/2 - 1.5494063 = 0.0213900.
  const EulerAttitude e = frd_ned_to_flu_enu({a.roll, a.pitch, a.yaw, a.rollspeed, a.pitchspeed, a.yawspeed});
  EXPECT_NEAR(e.roll, -0.0021176, 1e-7);
  EXPECT_NEAR(e.pitch, -0.0074910, 1e-7);
  EXPECT_NEAR(e.yaw, 0.0213900, 1e-7);
  EXPECT_NEAR(e.pitch_rate, -0.0023663, 1e-7);
  EXPECT_NEAR(e.yaw_rate, -0.0017632, 1e-7);
  // The CRC over bytes 1..37 plus CRC_EXTRA 39, and the encoder writing the same frame back.
  std::uint16_t crc = crc_x25(std::span(frame).subspan(1, 9 + 28));
  EXPECT_EQ(crc_accumulate(39, crc), 0x8D6D);
  std::array<std::uint8_t, kMaxFrame> again{};
  const std::size_t n = encode_message(p.headers[0], a, again);
  EXPECT_TRUE(std::equal(frame.begin(), frame.end(), again.begin(), again.begin() + static_cast<long>(n)));
  EXPECT_EQ(n, frame.size());
}

TEST(MavlinkPx4Capture, WholeStreamNoErrorsAndEncoderReproducesEveryAttitude) {
  const Bytes d = load("px4-v2-3412-packets.bin");
  const Parsed p = parse_stream(d, 37);
  EXPECT_EQ(p.counters.frames, 3412u);
  EXPECT_EQ(p.counters.v2_frames, 3412u);
  EXPECT_EQ(p.counters.errors(), 0u);
  EXPECT_EQ(p.counters.garbage_bytes, 0u);
  EXPECT_EQ(p.counters.truncated_payloads, 1842u);  // PX4 drops trailing zeros (counted by an independent Python decode)
  std::map<std::uint32_t, int> ids;
  std::map<std::uint32_t, Attitude> att;
  std::map<std::uint32_t, AttitudeQuaternion> quat;
  int reencoded = 0;
  for (std::size_t i = 0; i < p.headers.size(); ++i) {
    ++ids[p.headers[i].msgid];
    if (p.headers[i].msgid == kIdHeartbeat) {
      Heartbeat h;
      ASSERT_TRUE(decode(p.payloads[i], h));
      EXPECT_EQ(h.autopilot, kAutopilotPx4);
      EXPECT_EQ(h.type, 1);  // MAV_TYPE_FIXED_WING
    } else if (p.headers[i].msgid == kIdAttitude) {
      Attitude a;
      ASSERT_TRUE(decode(p.payloads[i], a));
      att[a.time_boot_ms] = a;
      std::array<std::uint8_t, kMaxFrame> again{};
      const std::size_t n = encode_message(p.headers[i], a, again);
      reencoded += n == p.wire[i].size() && std::equal(p.wire[i].begin(), p.wire[i].end(), again.begin());
    } else if (p.headers[i].msgid == kIdAttitudeQuaternion) {
      AttitudeQuaternion q;
      ASSERT_TRUE(decode(p.payloads[i], q));
      quat[q.time_boot_ms] = q;
      std::array<std::uint8_t, kMaxFrame> again{};
      const std::size_t n = encode_message(p.headers[i], q, again);
      reencoded += n == p.wire[i].size() && std::equal(p.wire[i].begin(), p.wire[i].end(), again.begin());
    }
  }
  EXPECT_EQ(ids[kIdAttitude], 505);
  EXPECT_EQ(ids[kIdAttitudeQuaternion], 505);
  EXPECT_EQ(ids[kIdHeartbeat], 10);
  EXPECT_EQ(reencoded, 1010) << "every ATTITUDE and ATTITUDE_QUATERNION re-encodes byte for byte (truncation included)";
  // PX4 sends ATTITUDE at 50 Hz: 505 in 10.08 s of time_boot_ms.
  EXPECT_EQ(att.rbegin()->first - att.begin()->first, 10080u);
  // Both messages come from the same estimate: the quaternion's Euler angles equal ATTITUDE's.
  int paired = 0;
  for (const auto& [t, q] : quat) {
    auto it = att.find(t);
    if (it == att.end()) continue;
    ++paired;
    const EulerAttitude e = euler_from_quaternion(q.q1, q.q2, q.q3, q.q4);
    EXPECT_NEAR(e.roll, it->second.roll, 1e-5);
    EXPECT_NEAR(e.pitch, it->second.pitch, 1e-5);
    EXPECT_NEAR(wrap_pi(e.yaw - static_cast<double>(it->second.yaw)), 0.0, 1e-5);
  }
  EXPECT_GT(paired, 400);
}

TEST(MavlinkPx4Capture, MixedV1V2StreamBehindGarbage) {
  const Bytes d = load("px4-v1-v2-mixed-gh5.bin");
  const Parsed p = parse_stream(d, 1);  // a byte at a time
  EXPECT_EQ(p.counters.frames, 138u);
  EXPECT_EQ(p.counters.v1_frames, 26u);
  EXPECT_EQ(p.counters.v2_frames, 112u);
  EXPECT_EQ(p.counters.garbage_bytes, 5u);  // the file starts 5 bytes into some record
  EXPECT_EQ(p.counters.errors(), 0u);
  int att = 0;
  for (const auto& h : p.headers) att += h.msgid == kIdAttitude;
  EXPECT_EQ(att, 14);
}

TEST(MavlinkParser, FlippedByteLosesOnlyThatFrameAndGarbageIsSkipped) {
  const Bytes d = load("px4-v2-3412-packets.bin");
  const Parsed clean = parse_stream(d);
  ASSERT_EQ(clean.wire.size(), 3412u);
  // Garbage with false magic bytes between frames, and one flipped payload byte in frame 100.
  const Bytes junk = {0x00, 0xFD, 0x1C, 0x00, 0xFE, 0x05, 0xFD, 0x01, 0x02, 0x55, 0xFE, 0xFE, 0x00, 0xFD};
  Bytes noisy;
  for (std::size_t i = 0; i < clean.wire.size(); ++i) {
    if (i % 50 == 7) noisy.insert(noisy.end(), junk.begin(), junk.end());
    Bytes w = clean.wire[i];
    if (i == 100) w[12] ^= 0x10;
    noisy.insert(noisy.end(), w.begin(), w.end());
  }
  const Parsed p = parse_stream(noisy, 29);
  EXPECT_EQ(p.counters.frames, 3411u) << "only the corrupted frame is lost";
  EXPECT_GE(p.counters.bad_crc, 1u);
  EXPECT_GT(p.counters.garbage_bytes, 0u);
  EXPECT_GT(p.counters.unsupported_flags + p.counters.unknown_id, 0u) << "false starts are refused for other reasons too";
  // Every other frame comes out, in order, unchanged.
  std::size_t j = 0;
  for (std::size_t i = 0; i < clean.wire.size(); ++i) {
    if (i == 100) continue;
    ASSERT_LT(j, p.wire.size());
    EXPECT_EQ(p.wire[j], clean.wire[i]) << i;
    ++j;
  }
  // The flipped frame alone: exactly one CRC failure, its bytes rescanned as garbage.
  const Parsed one = parse_stream([&] { Bytes w = clean.wire[100]; w[12] ^= 0x10; return w; }());
  EXPECT_EQ(one.counters.frames, 0u);
  EXPECT_EQ(one.counters.bad_crc, 1u);
}

TEST(MavlinkParser, V2TruncatedPayloadIsZeroExtended) {
  Attitude a;
  a.time_boot_ms = 0x0102;
  a.roll = 0.5f;  // the rest zero: a v2 sender drops those 20 bytes
  std::array<std::uint8_t, kMaxFrame> buf{};
  FrameHeader h;
  h.sysid = 1;
  h.compid = 1;
  const std::size_t n = encode_message(h, a, buf);
  ASSERT_EQ(n, kHeaderV2 + 8 + 2);
  EXPECT_EQ(buf[1], 8);  // len: time_boot_ms and roll
  const Parsed p = parse_stream(std::span(buf.data(), n));
  ASSERT_EQ(p.headers.size(), 1u);
  EXPECT_EQ(p.counters.truncated_payloads, 1u);
  Attitude b;
  b.yaw = 9.0f;
  ASSERT_TRUE(decode(p.payloads[0], b));
  EXPECT_EQ(b.time_boot_ms, 0x0102u);
  EXPECT_EQ(b.roll, 0.5f);
  EXPECT_EQ(b.yaw, 0.0f) << "zero-extended, not left as it was";
  // An all-zero payload keeps its first byte; v1 never truncates.
  const std::size_t z = encode_message(h, Attitude{}, buf);
  EXPECT_EQ(z, kHeaderV2 + 1 + 2);
  FrameHeader h1 = h;
  h1.version = 1;
  EXPECT_EQ(encode_message(h1, Attitude{}, buf), kHeaderV1 + 28 + 2);
}

TEST(MavlinkParser, SignedFramesAreReadAndTheirSignatureSkipped) {
  const Bytes d = load("px4-v2-3412-packets.bin");
  const Bytes real(d.begin() + 44, d.begin() + 44 + 40);  // the hand-decoded ATTITUDE
  const Parsed p0 = parse_stream(real);
  ASSERT_EQ(p0.headers.size(), 1u);
  Attitude a;
  ASSERT_TRUE(decode(p0.payloads[0], a));
  std::array<std::uint8_t, kSignatureBytes> sig{7, 1, 2, 3, 4, 5, 6, 0xFD, 0xFE, 0xAA, 0xBB, 0xCC, 0xDD};  // link 7, magic-like bytes inside
  std::array<std::uint8_t, kMaxFrame> buf{};
  std::array<std::uint8_t, 48> payload{};
  const std::size_t pl = encode(a, payload);
  const std::size_t n = encode_frame(p0.headers[0], std::span(payload.data(), pl), buf, true, &sig);
  ASSERT_EQ(n, 40u + kSignatureBytes);
  EXPECT_EQ(buf[2], kIncompatSigned);
  EXPECT_NE(buf[38] | buf[39] << 8, 0x8D6D) << "the incompat flags are under the CRC";
  Bytes stream(buf.begin(), buf.begin() + static_cast<long>(n));
  stream.insert(stream.end(), real.begin(), real.end());  // an unsigned frame right behind it
  const Parsed p = parse_stream(stream, 5);
  ASSERT_EQ(p.headers.size(), 2u);
  EXPECT_EQ(p.counters.signed_frames, 1u);
  EXPECT_EQ(p.counters.errors(), 0u);
  EXPECT_EQ(p.payloads[0], p0.payloads[0]);
  EXPECT_EQ(p.wire[0].size(), 53u);
  EXPECT_TRUE(std::equal(sig.begin(), sig.end(), p.wire[0].end() - 13));
  // An incompat flag we do not know: refused (the spec says so), the next frame still read.
  Bytes odd = real;
  odd[2] = 0x02;
  odd.insert(odd.end(), real.begin(), real.end());
  const Parsed q = parse_stream(odd);
  EXPECT_EQ(q.counters.unsupported_flags, 1u);
  EXPECT_EQ(q.headers.size(), 1u);
}

TEST(MavlinkParser, UnknownIdBadLengthAndTruncatedAreCountedApart) {
  const Bytes d = load("px4-v2-3412-packets.bin");
  const Bytes real(d.begin() + 44, d.begin() + 44 + 40);
  // A v2 frame of id 0x123456 (no dialect we know) with a consistent CRC: unknown, then the real frame.
  Bytes unknown = {0xFD, 2, 0, 0, 9, 1, 1, 0x56, 0x34, 0x12, 0xAB, 0xCD};
  const std::uint16_t c = crc_x25(std::span(unknown).subspan(1));
  unknown.push_back(static_cast<std::uint8_t>(c));
  unknown.push_back(static_cast<std::uint8_t>(c >> 8));
  Bytes s = unknown;
  s.insert(s.end(), real.begin(), real.end());
  Parsed p = parse_stream(s);
  EXPECT_EQ(p.counters.unknown_id, 1u);
  EXPECT_EQ(p.headers.size(), 1u);
  // A CRC-valid v1 ATTITUDE of 27 bytes and a v2 one of 29: bad lengths.
  auto with_crc = [](Bytes f, std::uint8_t extra) {
    std::uint16_t k = crc_accumulate(extra, crc_x25(std::span(f).subspan(1)));
    f.push_back(static_cast<std::uint8_t>(k));
    f.push_back(static_cast<std::uint8_t>(k >> 8));
    return f;
  };
  Bytes v1 = {0xFE, 27, 0, 1, 1, 30};
  v1.resize(6 + 27, 0x11);
  Bytes v2 = {0xFD, 29, 0, 0, 0, 1, 1, 30, 0, 0};
  v2.resize(10 + 29, 0x22);
  s = with_crc(v1, 39);
  const Bytes v2f = with_crc(v2, 39);
  s.insert(s.end(), v2f.begin(), v2f.end());
  s.insert(s.end(), real.begin(), real.end());
  p = parse_stream(s);
  EXPECT_EQ(p.counters.bad_length, 2u);
  EXPECT_EQ(p.counters.bad_crc, 0u);
  EXPECT_EQ(p.headers.size(), 1u);
  // A datagram cut 10 bytes into a frame: truncated at its end; the next datagram is read whole.
  FrameParser fp;
  Frame f;
  (void)fp.feed(std::span(real).first(30));
  fp.end_of_packet();
  EXPECT_FALSE(fp.next(f));
  EXPECT_EQ(fp.counters().truncated, 1u);
  (void)fp.feed(real);
  fp.end_of_packet();
  ASSERT_TRUE(fp.next(f));
  EXPECT_EQ(f.header.msgid, kIdAttitude);
  EXPECT_EQ(fp.counters().truncated, 1u);
  EXPECT_EQ(fp.counters().frames, 1u);
}

// Hand-worked: a vehicle heading 30 deg east of north (yaw_ned = pi/6), nose up 0.2 rad, right wing down
// 0.1 rad. In ENU the heading is 60 deg from east (yaw = pi/2 - pi/6 = pi/3); nose up is a negative
// rotation about the left axis (pitch = -0.2); right wing down is the same rotation about x (roll = 0.1).
TEST(MavlinkFrames, HandWorkedExampleAndRotationMatrices) {
  EulerAttitude frd{0.1, 0.2, kPi / 6, 0.01, 0.02, 0.03};
  EulerAttitude flu = frd_ned_to_flu_enu(frd);
  EXPECT_NEAR(flu.roll, 0.1, 1e-12);
  EXPECT_NEAR(flu.pitch, -0.2, 1e-12);
  EXPECT_NEAR(flu.yaw, kPi / 3, 1e-12);
  EXPECT_NEAR(flu.roll_rate, 0.01, 1e-12);
  EXPECT_NEAR(flu.pitch_rate, -0.02, 1e-12);
  EXPECT_NEAR(flu.yaw_rate, -0.03, 1e-12);
  // The nose direction: in NED (cos .2 cos 30deg, cos .2 sin 30deg, -sin .2); in ENU (north, east, up)
  // swapped and z negated: (cos .2 sin 30deg, cos .2 cos 30deg, sin .2). From the FLU angles:
  const double cp = std::cos(flu.pitch), sp = std::sin(flu.pitch), cy = std::cos(flu.yaw), sy = std::sin(flu.yaw);
  EXPECT_NEAR(cy * cp, std::cos(0.2) * 0.5, 1e-12);
  EXPECT_NEAR(sy * cp, std::cos(0.2) * std::sqrt(3.0) / 2, 1e-12);
  EXPECT_NEAR(-sp, std::sin(0.2), 1e-12);
  // Wrapping: heading 170 deg west of north (yaw_ned = -170 deg) is 260 deg = -100 deg from east.
  EXPECT_NEAR(frd_ned_to_flu_enu({0, 0, -170 * kPi / 180, 0, 0, 0}).yaw, -100 * kPi / 180, 1e-12);
  EXPECT_NEAR(wrap_pi(kPi), kPi, 1e-12);
  EXPECT_NEAR(wrap_pi(-kPi), kPi, 1e-12);
  // The whole rotation: R_enu_flu = P R_ned_frd D for many attitudes, P = [[0,1,0],[1,0,0],[0,0,-1]], D = diag(1,-1,-1).
  auto rot = [](double r, double p, double y, double m[3][3]) {
    const double cr = std::cos(r), sr = std::sin(r), cpp = std::cos(p), spp = std::sin(p), cyy = std::cos(y), syy = std::sin(y);
    const double v[3][3] = {{cyy * cpp, cyy * spp * sr - syy * cr, cyy * spp * cr + syy * sr},
                            {syy * cpp, syy * spp * sr + cyy * cr, syy * spp * cr - cyy * sr},
                            {-spp, cpp * sr, cpp * cr}};
    std::memcpy(m, v, sizeof v);
  };
  for (double r = -2.5; r < 2.6; r += 0.7)
    for (double p = -1.4; p < 1.5; p += 0.35)
      for (double y = -3.1; y < 3.2; y += 0.45) {
        double a[3][3], b[3][3];
        rot(r, p, y, a);
        const EulerAttitude e = frd_ned_to_flu_enu({r, p, y, 0, 0, 0});
        rot(e.roll, e.pitch, e.yaw, b);
        const int perm[3] = {1, 0, 2};
        const double row_sign[3] = {1, 1, -1}, col_sign[3] = {1, -1, -1};
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) ASSERT_NEAR(b[i][j], row_sign[i] * a[perm[i]][j] * col_sign[j], 1e-12) << r << " " << p << " " << y;
      }
  // Quaternions: identity, and 90 deg about z (heading east in NED).
  EXPECT_NEAR(euler_from_quaternion(1, 0, 0, 0).yaw, 0.0, 1e-12);
  EXPECT_NEAR(euler_from_quaternion(std::sqrt(0.5), 0, 0, std::sqrt(0.5)).yaw, kPi / 2, 1e-12);
  EXPECT_NEAR(euler_from_quaternion(std::cos(0.15), std::sin(0.15), 0, 0).roll, 0.3, 1e-12);
}

TEST(MavlinkTlog, ArduPilotReplayGivesEveryRecordWithItsTime) {
  auto r = TlogReplay::open(kDir + "ardupilot-sitl-quadplane-40s.tlog");
  ASSERT_TRUE(r.ok()) << r.error().message;
  TlogReplay& t = *r.value();
  EXPECT_EQ(t.next_recorded(), TimeNs{1533737161905000} * 1000);  // 2018-08-08T14:06:01.905Z
  FrameParser p;
  std::array<std::uint8_t, 512> buf{};
  Frame f;
  int att = 0, hb = 0;
  TimeNs last = 0;
  Attitude first{};
  for (;;) {
    TimeNs rec = 0;
    const long n = t.read(buf, rec);
    if (n < 0) break;
    EXPECT_GE(rec, last);
    last = rec;
    (void)p.feed(std::span(buf.data(), static_cast<std::size_t>(n)));
    p.end_of_packet();
    int in_record = 0;
    while (p.next(f)) {
      ++in_record;
      if (f.header.msgid == kIdAttitude && att++ == 0) {
        ASSERT_TRUE(decode(f.payload, first));
      }
      if (f.header.msgid == kIdHeartbeat) {
        Heartbeat h;
        ASSERT_TRUE(decode(f.payload, h));
        EXPECT_EQ(h.autopilot, kAutopilotArdupilot);
        ++hb;
      }
    }
    EXPECT_EQ(in_record, 1);
  }
  EXPECT_TRUE(t.at_end());
  EXPECT_EQ(t.records(), 5057u);
  EXPECT_EQ(t.skipped_bytes(), 0u);
  EXPECT_EQ(last, TimeNs{1533737201065000} * 1000);
  EXPECT_EQ(p.counters().frames, 5057u);
  EXPECT_EQ(p.counters().v1_frames, 5057u);
  EXPECT_EQ(p.counters().errors(), 0u);
  EXPECT_EQ(att, 213);
  EXPECT_EQ(hb, 37);
  EXPECT_EQ(first.time_boot_ms, 608582u);
  EXPECT_NEAR(first.roll, -0.0246537, 1e-6);
  EXPECT_NEAR(first.yaw, 2.4500322, 1e-6);
}

TEST(MavlinkTlog, CorruptAndCutRecordsAreSkippedAndCounted) {
  const Bytes d = load("px4-v2-3412-packets.bin");
  const Bytes real(d.begin() + 44, d.begin() + 44 + 40);
  Bytes log;
  append_tlog_record(log, 1'000'000, real);
  log.insert(log.end(), {0x01, 0x02, 0x03});  // junk between records
  append_tlog_record(log, 2'000'000, real);
  append_tlog_record(log, 3'000'000, std::span(real).first(20));  // the last record cut short
  auto t = TlogReplay::from_bytes(log);
  FrameParser p;
  std::array<std::uint8_t, 512> buf{};
  Frame f;
  int frames = 0;
  std::vector<TimeNs> stamps;
  for (TimeNs rec = 0;;) {
    const long n = t->read(buf, rec);
    if (n < 0) break;
    stamps.push_back(rec);
    (void)p.feed(std::span(buf.data(), static_cast<std::size_t>(n)));
    p.end_of_packet();
    while (p.next(f)) ++frames;
  }
  EXPECT_EQ(frames, 2);
  EXPECT_EQ(t->skipped_bytes(), 3u);
  EXPECT_EQ(p.counters().truncated, 1u);
  ASSERT_EQ(stamps.size(), 3u);
  EXPECT_EQ(stamps[1], 2'000'000'000);
}

TEST(MavlinkLinks, UdpDeliversDatagramsAndAnswersTheSender) {
  auto u = UdpLink::open("127.0.0.1", 0);
  ASSERT_TRUE(u.ok()) << u.error().message;
  UdpLink& link = *u.value();
  const int tx = ::socket(AF_INET, SOCK_DGRAM, 0);
  ASSERT_GE(tx, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<std::uint16_t>(link.port()));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const Bytes d = load("px4-v2-3412-packets.bin");
  const Bytes datagram(d.begin(), d.begin() + 1000);  // several frames, the last cut off
  ASSERT_EQ(::sendto(tx, datagram.data(), datagram.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to), 1000);
  ASSERT_TRUE(link.wait(kNsPerS));
  std::array<std::uint8_t, 2048> buf{};
  TimeNs rec = 0;
  const long n = link.read(buf, rec);
  ASSERT_EQ(n, 1000);
  EXPECT_EQ(rec, -1);
  EXPECT_TRUE(std::equal(datagram.begin(), datagram.end(), buf.begin()));
  FrameParser p;
  (void)p.feed(std::span(buf.data(), 1000));
  p.end_of_packet();
  Frame f;
  int frames = 0;
  while (p.next(f)) ++frames;
  EXPECT_GT(frames, 20);
  EXPECT_EQ(p.counters().truncated, 1u) << "the frame cut at the datagram's end";
  // A reply goes back to the sender's port.
  const std::uint8_t hello[] = {1, 2, 3};
  EXPECT_EQ(link.write(hello), 3);
  std::uint8_t back[8];
  EXPECT_EQ(::recv(tx, back, sizeof back, 0), 3);
  ::close(tx);
}

TEST(MavlinkLinks, SerialOverAPseudoTerminalGivesTheSameFrames) {
  const int master = ::posix_openpt(O_RDWR | O_NOCTTY);
  ASSERT_GE(master, 0);
  ASSERT_EQ(::grantpt(master), 0);
  ASSERT_EQ(::unlockpt(master), 0);
  const std::string name = ::ptsname(master);
  auto s = SerialLink::open(name, 921600);
  ASSERT_TRUE(s.ok()) << s.error().message;
  const Bytes d = load("px4-v1-v2-mixed-gh5.bin");
  Bytes got;
  std::array<std::uint8_t, 256> buf{};
  // Written in pieces while the reader runs (a pty's input queue holds 4 KiB), as a UART delivers.
  std::size_t pos = 0;
  for (int idle = 0; got.size() < d.size() && idle < 100;) {
    if (pos < d.size()) {
      const std::size_t k = std::min<std::size_t>(200, d.size() - pos);
      ASSERT_EQ(::write(master, d.data() + pos, k), static_cast<ssize_t>(k));
      pos += k;
    }
    (void)s.value()->wait(10 * kNsPerMs);
    TimeNs rec = 0;
    const long n = s.value()->read(buf, rec);
    ASSERT_GE(n, 0);
    idle = n == 0 ? idle + 1 : 0;
    got.insert(got.end(), buf.begin(), buf.begin() + n);
  }
  EXPECT_EQ(got, d);
  EXPECT_EQ(parse_stream(got).counters.frames, 138u);
  const std::uint8_t ping[] = {0xFD, 0x00};
  EXPECT_EQ(s.value()->write(ping), 2);
  std::uint8_t back[4];
  EXPECT_EQ(::read(master, back, sizeof back), 2);
  EXPECT_FALSE(SerialLink::open(name, 12345).ok());
  EXPECT_FALSE(SerialLink::open("/dev/nonexistent-autopilot", 921600).ok());
  ::close(master);
}

}  // namespace
}  // namespace ag::mavlink
