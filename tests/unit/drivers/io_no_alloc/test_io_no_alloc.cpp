// The drivers' per-cycle calls never allocate after init: Ouster decode, frame assembly and XYZ (pcap
// and UDP sources), the u-blox stream parser and NAV-PVT, the cannelloni bus with filters and error
// frames, V4L2 dequeue/requeue on the fake device, e-stop edges.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "../../../common/counting_new.hpp"
#include "airground/drivers/can/cannelloni.hpp"
#include "airground/drivers/gpio/edge_events.hpp"
#include "airground/drivers/autopilot/mavlink/frame_parser.hpp"
#include "airground/drivers/autopilot/mavlink/frames.hpp"
#include "airground/drivers/autopilot/mavlink/link.hpp"
#include "airground/drivers/lidar/ouster/frame.hpp"
#include "airground/drivers/lidar/ouster/packet_source.hpp"
#include "airground/drivers/lidar/ouster/xyz_lut.hpp"
#include "airground/drivers/gps/ublox/byte_source.hpp"
#include "airground/drivers/gps/ublox/stream_parser.hpp"
#include "airground/drivers/gps/ublox/ubx.hpp"
#include "airground/drivers/camera/v4l2/camera.hpp"
#include "fake_device.hpp"

namespace ag {
namespace {
using test_alloc::AllocationWindow;

TEST(DriversIoNoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(10);
  EXPECT_GE(w.allocations(), 1u);
}

TEST(DriversIoNoAllocation, OusterPcapAndUdpDecodeAssembleXyz) {
  const std::string dir = std::string(AG_TEST_DATA_DIR) + "/ouster/";
  auto info = ouster::read_metadata_file(dir + "OS-1-64_sensor_config_reduced.json");
  ASSERT_TRUE(info.ok());
  auto src = ouster::PcapPacketSource::open(dir + "OS-1-64_1024x10_fw20.pcap");
  ASSERT_TRUE(src.ok());
  const ouster::PacketFormat fmt(info.value());
  ouster::FrameAssembler assembler(info.value());
  const ouster::XyzLut lut(info.value());
  std::vector<float> xyz(3 * 1024 * 64);
  std::vector<std::uint8_t> buf(ouster::kMaxPacketSize);
  auto pkt = std::make_unique<ouster::LidarPacket>();
  ouster::UdpSourceConfig ucfg;
  ucfg.bind_address = "127.0.0.1";
  ucfg.lidar_port = 0;
  ucfg.imu_port = 0;
  auto udp = ouster::UdpPacketSource::open(ucfg);
  ASSERT_TRUE(udp.ok());
  const int tx = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(udp.value()->lidar_port());
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  int frames = 0, imu = 0;
  {
    AllocationWindow w;
    for (;;) {
      std::size_t n = 0;
      TimeNs t = 0;
      const ouster::PacketKind k = src.value()->next(buf, n, t);
      if (k == ouster::PacketKind::kEnd) break;
      if (k == ouster::PacketKind::kImu) {
        ouster::ImuSample s;
        imu += ouster::decode_imu(std::span(buf).first(n), s) == ouster::DecodeStatus::kOk;
        continue;
      }
      ASSERT_EQ(fmt.decode_lidar(std::span(buf).first(n), *pkt), ouster::DecodeStatus::kOk);
      if (const ouster::LidarFrame* f = assembler.add(*pkt)) {
        lut.cartesian(*f, xyz.data());
        ++frames;
      }
    }
    // The live client's receive path.
    ASSERT_GT(::sendto(tx, buf.data(), fmt.lidar_packet_size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to), 0);
    std::size_t n = 0;
    TimeNs t = 0;
    ouster::PacketKind k = ouster::PacketKind::kNone;
    for (int i = 0; i < 100 && k == ouster::PacketKind::kNone; ++i) {
      udp.value()->wait(10 * kNsPerMs);
      k = udp.value()->next(buf, n, t);
    }
    EXPECT_EQ(k, ouster::PacketKind::kLidar);
    EXPECT_EQ(w.allocations(), 0u);
  }
  ::close(tx);
  EXPECT_EQ(frames, 1);
  EXPECT_EQ(imu, 11);
}

// The FW 2.2+ profiles (RNG15 and dual captures): decode, assemble (both returns), XYZ and re-encode.
TEST(DriversIoNoAllocation, OusterCurrentProfilesDecodeAssembleXyzEncode) {
  const std::string dir = std::string(AG_TEST_DATA_DIR) + "/ouster/";
  for (const char* name : {"OS-0-128-U1_v2.3.0_1024x10", "OS-0-32-U1_v2.2.0_1024x10"}) {
    SCOPED_TRACE(name);
    auto info = ouster::read_metadata_file(dir + name + ".json");
    ASSERT_TRUE(info.ok()) << info.error().message;
    auto src = ouster::PcapPacketSource::open(dir + name + ".pcap");
    ASSERT_TRUE(src.ok());
    const ouster::PacketFormat fmt(info.value());
    ouster::FrameAssembler assembler(info.value());
    const ouster::XyzLut lut(info.value());
    std::vector<float> xyz(3 * 1024 * info.value().beam_altitude_deg.size());
    std::vector<std::uint8_t> buf(ouster::kMaxPacketSize), out(fmt.lidar_packet_size());
    auto pkt = std::make_unique<ouster::LidarPacket>();
    int frames = 0;
    {
      AllocationWindow w;
      for (;;) {
        std::size_t n = 0;
        TimeNs t = 0;
        const ouster::PacketKind k = src.value()->next(buf, n, t);
        if (k == ouster::PacketKind::kEnd) break;
        if (k != ouster::PacketKind::kLidar) continue;
        ASSERT_EQ(fmt.decode_lidar(std::span(buf).first(n), *pkt), ouster::DecodeStatus::kOk);
        if (const ouster::LidarFrame* f = assembler.add(*pkt)) {
          lut.cartesian(*f, xyz.data());
          EXPECT_EQ(ouster::encode_lidar_packet(fmt, *f, 0, out), out.size());
          ++frames;
        }
      }
      EXPECT_EQ(w.allocations(), 0u);
    }
    EXPECT_EQ(frames, 1);
  }
}

TEST(DriversIoNoAllocation, UbloxStreamAndNavPvt) {
  auto file = ublox::ReplayFile::open(std::string(AG_TEST_DATA_DIR) + "/gps/ublox-zed-f9p-rtk.log", 128);
  ASSERT_TRUE(file.ok());
  auto parser = std::make_unique<ublox::StreamParser>();
  std::uint8_t buf[128];
  int fixes = 0;
  {
    AllocationWindow w;
    long n;
    while ((n = file.value()->read(buf)) > 0) {
      std::span<const std::uint8_t> in(buf, static_cast<std::size_t>(n));
      while (!in.empty()) {
        ublox::StreamMessage m;
        in = in.subspan(parser->feed(in, m));
        ublox::NavPvt p;
        if (m.kind == ublox::StreamMessage::Kind::kUbx && m.cls == ublox::kClassNav && m.id == ublox::kIdNavPvt) fixes += ublox::decode_nav_pvt(m.payload, p);
      }
    }
    EXPECT_EQ(w.allocations(), 0u);
  }
  EXPECT_GE(fixes, 9);
}

TEST(DriversIoNoAllocation, CannelloniBusFiltersAndErrors) {
  can::CannelloniConfig a;
  a.bind_address = "127.0.0.1";
  a.local_port = 0;
  a.learn_remote = true;
  auto robot = can::CannelloniBus::open(a);
  ASSERT_TRUE(robot.ok());
  can::CannelloniConfig b;
  b.bind_address = "127.0.0.1";
  b.local_port = 0;
  b.remote_port = robot.value()->local_port();
  auto sim = can::CannelloniBus::open(b);
  ASSERT_TRUE(sim.ok());
  const can::CanFilter flt{0x060, 0x7E0, false};
  ASSERT_TRUE(robot.value()->set_filters(std::span(&flt, 1)));
  int got = 0;
  {
    AllocationWindow w;
    for (int i = 0; i < 20; ++i) {
      can::CanFrame f;
      f.id = static_cast<std::uint32_t>(0x060 + (i % 2) * 0x100);
      f.dlc = 8;
      ASSERT_EQ(sim.value()->send(f), can::CanResult::kOk);
      for (int k = 0; k < 200; ++k) {
        can::CanFrame r;
        if (robot.value()->receive(r) == can::CanResult::kOk) {
          ++got;
          break;
        }
        if (robot.value()->counters().rx_filtered > static_cast<std::uint64_t>(i / 2)) break;
        ::usleep(200);
      }
    }
    EXPECT_EQ(w.allocations(), 0u);
  }
  EXPECT_EQ(got, 10);
}

TEST(DriversIoNoAllocation, V4l2DequeueAndEStopEdges) {
  v4l2::testing::FakeDevice dev;
  for (std::uint32_t s = 0; s < 50; ++s)
    dev.script.push_back({v4l2::testing::FakeEvent::Kind::kFrame, s * 2, 1000 + s, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, false});
  v4l2::CameraConfig c;
  c.width = 64;
  c.height = 4;
  auto cam = v4l2::Camera::open(c, dev);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  std::vector<std::uint8_t> bgr(64 * 4 * 3);
  gpio::FakeEdgeLine line;
  gpio::EStopEdges edges(line);
  int frames = 0;
  {
    AllocationWindow w;
    v4l2::Frame f;
    while (cam.value()->next(0, f) == v4l2::CaptureResult::kFrame) {
      v4l2::to_bgr(f, bgr.data());
      cam.value()->release(f);
      ++frames;
      line.press(frames % 2 == 1, frames);
      (void)edges.drain();
    }
    EXPECT_EQ(w.allocations(), 0u);
  }
  EXPECT_EQ(frames, 50);
  EXPECT_EQ(cam.value()->counters().dropped, 49u);
  EXPECT_EQ(edges.edges(), 50u);
}

TEST(DriversIoNoAllocation, MavlinkTlogAndUdpParseDecodeConvert) {
  auto tlog = mavlink::TlogReplay::open(std::string(AG_TEST_DATA_DIR) + "/mavlink/ardupilot-sitl-quadplane-40s.tlog");
  ASSERT_TRUE(tlog.ok()) << tlog.error().message;
  auto udp = mavlink::UdpLink::open("127.0.0.1", 0);
  ASSERT_TRUE(udp.ok()) << udp.error().message;
  const int tx = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<std::uint16_t>(udp.value()->port()));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  mavlink::FrameParser parser;
  std::vector<std::uint8_t> buf(4096);
  double sum = 0;
  int attitudes = 0;
  {
    AllocationWindow w;
    for (TimeNs rec = 0;;) {
      const long n = tlog.value()->read(buf, rec);
      if (n < 0) break;
      (void)parser.feed(std::span(buf.data(), static_cast<std::size_t>(n)));
      parser.end_of_packet();
      // The live client's path: the same record through a real socket.
      ASSERT_EQ(::sendto(tx, buf.data(), static_cast<std::size_t>(n), 0, reinterpret_cast<sockaddr*>(&to), sizeof to), n);
      mavlink::Frame f;
      while (parser.next(f)) {
        mavlink::Attitude a;
        if (f.header.msgid != mavlink::kIdAttitude || !mavlink::decode(f.payload, a)) continue;
        sum += mavlink::frd_ned_to_flu_enu({a.roll, a.pitch, a.yaw, a.rollspeed, a.pitchspeed, a.yawspeed}).yaw;
        ++attitudes;
      }
      (void)udp.value()->read(buf, rec);
    }
    EXPECT_EQ(w.allocations(), 0u);
  }
  EXPECT_EQ(attitudes, 213);
  EXPECT_EQ(sum, sum) << "not NaN";
  ::close(tx);
}

}  // namespace
}  // namespace ag
