// V4L2 capture against the fake device: negotiation read-back, sequence gaps, error buffers, EAGAIN,
// mid-exposure stamps, buffer recycling; pixel conversions (against OpenCV where available).
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "airground/drivers/camera/v4l2/camera.hpp"
#include "fake_device.hpp"

#if AG_HAVE_OPENCV
#include <opencv2/imgproc.hpp>
#endif

namespace ag::v4l2 {
namespace {

using testing::FakeDevice;
using testing::FakeEvent;

CameraConfig config() {
  CameraConfig c;
  c.width = 100;  // the fake rounds to 96
  c.height = 8;
  c.format = PixelFormat::kYuyv;
  c.fps = 30;
  c.buffers = 3;
  return c;
}

TEST(V4l2Camera, NegotiatesAndReadsBackTheDriversValues) {
  FakeDevice dev;
  auto cam = Camera::open(config(), dev);
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  EXPECT_EQ(cam.value()->width(), 96u);
  EXPECT_EQ(cam.value()->stride(), 96u * 2 + 64);
  EXPECT_EQ(cam.value()->image_size(), (96u * 2 + 64) * 8);
  EXPECT_DOUBLE_EQ(cam.value()->frame_interval_s(), 1.0 / 25);
  EXPECT_EQ(cam.value()->exposure(), 5 * kNsPerMs);
  EXPECT_EQ(cam.value()->buffer_count(), 3u);
  EXPECT_EQ(dev.queued.size(), 3u);
  EXPECT_EQ(dev.streamon, 1);
  cam.value().reset();
  EXPECT_EQ(dev.streamoff, 1);
  EXPECT_EQ(dev.unmaps, 3);
  EXPECT_EQ(dev.closes, 2);  // device and epoll
}

TEST(V4l2Camera, DropsErrorsAndGapsAreCountedAndStampsAreMidExposure) {
  FakeDevice dev;
  auto r = Camera::open(config(), dev);
  ASSERT_TRUE(r.ok()) << r.error().message;
  Camera& cam = *r.value();
  const std::uint32_t eof = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_EOF;
  dev.script = {
      {FakeEvent::Kind::kFrame, 10, 1'000'000, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_TSTAMP_SRC_SOE, false},
      {FakeEvent::Kind::kEagain, 0, 0, 0, false},
      {FakeEvent::Kind::kFrame, 11, 1'040'000, eof, false},
      {FakeEvent::Kind::kFrame, 12, 1'080'000, eof | V4L2_BUF_FLAG_ERROR, false},  // discarded
      {FakeEvent::Kind::kFrame, 15, 1'200'000, eof, false},                       // 13, 14 dropped
      {FakeEvent::Kind::kFrame, 16, 1'240'000, eof, true},                        // short: discarded
      {FakeEvent::Kind::kFrame, 17, 1'280'000, eof, false},
  };
  std::vector<std::uint32_t> seqs;
  std::vector<TimeNs> stamps;
  Frame f;
  while (cam.next(10 * kNsPerMs, f) == CaptureResult::kFrame) {
    std::uint32_t counter;
    std::memcpy(&counter, f.data.data() + f.stride * 3, 4);  // the fake's counter on line 3
    EXPECT_EQ(counter, f.sequence) << "the frame's pixels are its own buffer's";
    EXPECT_EQ(f.data.size(), cam.image_size());
    seqs.push_back(f.sequence);
    stamps.push_back(f.stamp);
    cam.release(f);
  }
  EXPECT_EQ(seqs, (std::vector<std::uint32_t>{10, 11, 15, 17}));
  EXPECT_EQ(cam.counters().frames, 4u);
  EXPECT_EQ(cam.counters().dropped, 2u);
  EXPECT_EQ(cam.counters().error_buffers, 1u);
  EXPECT_EQ(cam.counters().short_buffers, 1u);
  EXPECT_EQ(cam.counters().would_block, 1u);
  EXPECT_EQ(cam.counters().timeouts, 1u);
  // Start-of-exposure stamp + 2.5 ms; end-of-frame stamps - 2.5 ms.
  EXPECT_EQ(stamps[0], 1'000'000 * kNsPerUs + 2'500'000);
  EXPECT_EQ(stamps[1], 1'040'000 * kNsPerUs - 2'500'000);
  EXPECT_EQ(cam.counters().stamp_backwards, 0u);
  EXPECT_EQ(dev.queued.size(), 3u) << "every buffer went back to the driver";
  EXPECT_EQ(cam.state(), Camera::State::kStreaming);
}

TEST(V4l2Camera, HeldBuffersStarveTheDriverWithoutBreakingIt) {
  FakeDevice dev;
  auto r = Camera::open(config(), dev);
  ASSERT_TRUE(r.ok());
  for (std::uint32_t s = 0; s < 6; ++s) dev.script.push_back({FakeEvent::Kind::kFrame, s, 1000 + s, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, false});
  std::vector<Frame> held;
  Frame f;
  while (r.value()->next(0, f) == CaptureResult::kFrame) held.push_back(f);
  EXPECT_EQ(held.size(), 3u);  // all buffers held by the application
  for (const Frame& h : held) r.value()->release(h);
  while (r.value()->next(0, f) == CaptureResult::kFrame) {
    held.push_back(f);
    r.value()->release(f);
  }
  EXPECT_EQ(held.size(), 6u);
  EXPECT_EQ(r.value()->counters().dropped, 0u);
}

TEST(V4l2Camera, OpenErrorsNameDeviceAndStep) {
  FakeDevice dev;
  CameraConfig c = config();
  c.device = "/dev/video7";
  auto a = Camera::open(c, dev);
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.error().message.find("/dev/video7: open"), std::string::npos) << a.error().message;
  FakeDevice no_stream;
  no_stream.caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE;
  auto b = Camera::open(config(), no_stream);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.error().message.find("streaming"), std::string::npos);
  FakeDevice grey_only;
  grey_only.supported_fourcc = V4L2_PIX_FMT_GREY;
  auto d = Camera::open(config(), grey_only);
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.error().message.find("YUYV"), std::string::npos);
  FakeDevice one_buffer;
  one_buffer.granted_buffers = 1;
  EXPECT_FALSE(Camera::open(config(), one_buffer).ok());
  EXPECT_FALSE(parse_pixel_format("MJPG").ok());
  EXPECT_EQ(parse_pixel_format("GRBG8").value(), PixelFormat::kBayerGrbg8);
}

// A Bayer mosaic of one colour demosaics to that colour (a swapped pattern would not).
TEST(V4l2Convert, BayerPatternsGiveTheSceneColour) {
  for (PixelFormat fmt : {PixelFormat::kBayerRggb8, PixelFormat::kBayerGrbg8}) {
    const std::uint32_t w = 8, h = 6;
    std::vector<std::uint8_t> raw(w * h);
    for (std::uint32_t y = 0; y < h; ++y)
      for (std::uint32_t x = 0; x < w; ++x) {
        const bool ox = x & 1, oy = y & 1;
        const bool red = fmt == PixelFormat::kBayerRggb8 ? (!ox && !oy) : (ox && !oy);
        const bool blue = fmt == PixelFormat::kBayerRggb8 ? (ox && oy) : (!ox && oy);
        raw[y * w + x] = red ? 200 : blue ? 50 : 100;
      }
    Frame f;
    f.data = raw;
    f.width = w;
    f.height = h;
    f.stride = w;
    f.format = fmt;
    std::vector<std::uint8_t> bgr(w * h * 3), grey(w * h);
    to_bgr(f, bgr.data());
    to_grey(f, grey.data());
    for (std::size_t i = 0; i < w * h; ++i) {
      ASSERT_EQ(bgr[3 * i], 50) << to_string(fmt) << " pixel " << i;
      ASSERT_EQ(bgr[3 * i + 1], 100);
      ASSERT_EQ(bgr[3 * i + 2], 200);
      ASSERT_EQ(grey[i], (200 * 4899 + 100 * 9617 + 50 * 1868 + 8192) >> 14);
    }
  }
}

TEST(V4l2Convert, YuyvGreyAndStride) {
  const std::uint32_t w = 4, h = 2, stride = 12;  // 4 bytes padding per line
  std::vector<std::uint8_t> raw(stride * h, 0xEE);
  const std::uint8_t line[8] = {16, 128, 235, 128, 81, 90, 145, 240};  // black, white; then BT.601 red
  for (std::uint32_t y = 0; y < h; ++y) std::memcpy(raw.data() + y * stride, line, 8);
  Frame f;
  f.data = raw;
  f.width = w;
  f.height = h;
  f.stride = stride;
  f.format = PixelFormat::kYuyv;
  std::vector<std::uint8_t> bgr(w * h * 3), grey(w * h);
  to_bgr(f, bgr.data());
  to_grey(f, grey.data());
  EXPECT_EQ(bgr[0], 0);
  EXPECT_EQ(bgr[3], 255);
  EXPECT_EQ(bgr[4], 255);
  EXPECT_NEAR(bgr[6 + 2], 255, 2);  // red
  EXPECT_NEAR(bgr[6 + 1], 0, 2);
  EXPECT_EQ(grey[0], 16);
  EXPECT_EQ(grey[1], 235);
  EXPECT_EQ(grey[4 + 3], 145);
}

#if AG_HAVE_OPENCV
TEST(V4l2Convert, MatchesOpenCvCvtColor) {
  std::mt19937 rng(3);
  const int w = 64, h = 48;
  std::vector<std::uint8_t> raw(static_cast<std::size_t>(w) * h * 2);
  for (auto& b : raw) b = static_cast<std::uint8_t>(rng());
  Frame f;
  f.data = raw;
  f.width = w;
  f.height = h;
  f.format = PixelFormat::kYuyv;
  f.stride = 2 * w;
  std::vector<std::uint8_t> ours(static_cast<std::size_t>(w) * h * 3);
  to_bgr(f, ours.data());
  cv::Mat yuyv(h, w, CV_8UC2, raw.data()), ref;
  cv::cvtColor(yuyv, ref, cv::COLOR_YUV2BGR_YUYV);
  int worst = 0;
  for (std::size_t i = 0; i < ours.size(); ++i) worst = std::max(worst, std::abs(ours[i] - ref.data[i]));
  EXPECT_LE(worst, 1) << "YUYV";
  for (auto [fmt, code] : {std::pair{PixelFormat::kBayerRggb8, cv::COLOR_BayerRGGB2BGR}, std::pair{PixelFormat::kBayerGrbg8, cv::COLOR_BayerGRBG2BGR}}) {
    f.format = fmt;
    f.stride = w;
    to_bgr(f, ours.data());
    cv::Mat bayer(h, w, CV_8UC1, raw.data()), out;
    cv::cvtColor(bayer, out, code);
    int interior = 0;
    for (int y = 1; y < h - 1; ++y)
      for (int x = 1; x < w - 1; ++x)
        for (int c = 0; c < 3; ++c)
          interior = std::max(interior, std::abs(ours[static_cast<std::size_t>((y * w + x) * 3 + c)] - out.at<cv::Vec3b>(y, x)[c]));
    EXPECT_LE(interior, 1) << to_string(fmt);
  }
}
#endif

}  // namespace
}  // namespace ag::v4l2
