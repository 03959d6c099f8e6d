// The frame stream (round trip, corruption, a FIFO written while read) and the camera stage in a
// two-stage role (real config and channels, a sink reading "camera" and "visual_odometry"): replay of
// files and of a FIFO created after start-up, recorded and arrival stamps, pacing, the V4L2 backend on
// the fake device of ../v4l2/fake_device.hpp (a known YUYV picture out as RGB at 640x400, a device
// failing and coming back), absent devices and files, and step() not allocating.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "airground/drivers/camera/stage/camera_stage.hpp"
#include "airground/drivers/camera/frame_stream/frame_stream.hpp"
#include "airground/messages/channels.hpp"
#include "airground/platform/role_instance.hpp"
#include "fake_device.hpp"

#if AG_COUNT_ALLOC
#include "../../../common/counting_new.hpp"
#endif

namespace ag::camera {
namespace {

// --- helpers --------------------------------------------------------------------------------------

// A fresh directory, removed with what the test wrote into it (recordings are megabytes) at exit.
std::string temp_dir() {
  struct Dirs {
    std::vector<std::string> made;
    ~Dirs() {
      std::error_code ec;
      for (const auto& d : made) std::filesystem::remove_all(d, ec);
    }
  };
  static Dirs dirs;
  std::string t = ::testing::TempDir() + "ag_camera_XXXXXX";
  EXPECT_NE(::mkdtemp(t.data()), nullptr);
  dirs.made.push_back(t);
  return t + "/";
}

std::unique_ptr<CameraImageMsg> make_image(std::uint32_t seq, TimeNs stamp, std::uint32_t seed) {
  auto m = std::make_unique<CameraImageMsg>();
  m->stamp = stamp;
  m->seq = seq;
  m->labels = LabelSource::kGroundTruth;
  std::mt19937 rng(seed);
  for (auto& b : m->rgb) b = static_cast<std::uint8_t>(rng());
  for (auto& c : m->cls) c = static_cast<std::uint8_t>(rng() % 20);
  return m;
}

VoMsg make_vo(std::uint32_t i, TimeNs stamp) {
  VoMsg v;
  v.stamp = stamp;
  v.segment = i / 4;
  v.tracking = i % 3 != 0;
  v.pose = Pose3{1.5 * i, -0.25 * i, 40.0 + i, 0.01 * i, -0.02 * i, 3.1 - 0.1 * i};
  return v;
}

bool same_image(const CameraImageMsg& a, const CameraImageMsg& b) {
  return a.stamp == b.stamp && a.seq == b.seq && a.labels == b.labels && a.rgb == b.rgb && a.cls == b.cls;
}

void expect_same_vo(const VoMsg& a, const VoMsg& b) {
  EXPECT_EQ(a.stamp, b.stamp);
  EXPECT_EQ(a.segment, b.segment);
  EXPECT_EQ(a.tracking, b.tracking);
  EXPECT_EQ(a.pose.x, b.pose.x);
  EXPECT_EQ(a.pose.y, b.pose.y);
  EXPECT_EQ(a.pose.z, b.pose.z);
  EXPECT_EQ(a.pose.roll, b.pose.roll);
  EXPECT_EQ(a.pose.pitch, b.pose.pitch);
  EXPECT_EQ(a.pose.yaw, b.pose.yaw);
}

void write_file(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream o(path, std::ios::binary);
  o.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

void append(std::vector<std::uint8_t>& out, const std::vector<std::uint8_t>& rec) { out.insert(out.end(), rec.begin(), rec.end()); }

// A record of any type, version and payload, with a correct CRC.
std::vector<std::uint8_t> raw_record(std::uint16_t version, std::uint16_t type, const std::vector<std::uint8_t>& payload) {
  std::vector<std::uint8_t> r = {'A', 'G', 'F', 'S'};
  auto u16 = [&](std::uint16_t v) { r.push_back(static_cast<std::uint8_t>(v)), r.push_back(static_cast<std::uint8_t>(v >> 8)); };
  auto u32 = [&](std::uint32_t v) {
    for (int i = 0; i < 4; ++i) r.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  };
  u16(version);
  u16(type);
  u32(static_cast<std::uint32_t>(payload.size()));
  r.insert(r.end(), payload.begin(), payload.end());
  u32(crc32(r));
  return r;
}

// Everything a reader gives until kEnd (or a limit of calls).
struct Drained {
  std::vector<std::unique_ptr<CameraImageMsg>> images;
  std::vector<VoMsg> vo;
  bool ended{false};
};
Drained drain(FrameStreamReader& r, int max_calls = 1000) {
  Drained d;
  auto img = std::make_unique<CameraImageMsg>();
  VoMsg vo;
  for (int i = 0; i < max_calls; ++i) {
    const ReadResult k = r.next(*img, vo);
    if (k == ReadResult::kImage) d.images.push_back(std::make_unique<CameraImageMsg>(*img));
    if (k == ReadResult::kVo) d.vo.push_back(vo);
    if (k == ReadResult::kEnd) {
      d.ended = true;
      break;
    }
  }
  return d;
}

// Keeps what the mapping stages would receive.
class Sink final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<Sink>(); }
  Status init(StageContext& ctx) override {
    auto c = ctx.channels.ring_reader(chan::kCamera);
    if (!c) return c.error();
    cam_ = c.value();
    auto v = ctx.channels.ring_reader(chan::kVisualOdometry);
    if (!v) return v.error();
    vo_ = v.value();
    return ok_status();
  }
  void step(TimeNs) noexcept override {
    while (CameraImageMsg* m = cam_.front()) {
      images.push_back(std::make_unique<CameraImageMsg>(*m));
      cam_.pop();
    }
    while (VoMsg* m = vo_.front()) {
      vo.push_back(*m);
      vo_.pop();
    }
  }
  std::vector<std::unique_ptr<CameraImageMsg>> images;
  std::vector<VoMsg> vo;

 private:
  RingReader<CameraImageMsg, kCameraRing> cam_;
  RingReader<VoMsg, kVoRing> vo_;
};

inline constexpr StageSpec kStages[] = {
    {"camera", &CameraStage::make, 20.0, 40'000, 40, -1, CameraStage::kParams, "the stage under test"},
    {"sink", &Sink::make, 20.0, 1'000, 20, -1, {}, "the mapping stages' place"},
};
inline constexpr RoleDescription kRole{"uav", "camera stage rig", kStages, {}};

struct Rig {
  SimClock clock{0};
  std::unique_ptr<RoleInstance> role;
  CameraStage* stage{nullptr};
  Sink* sink{nullptr};

  // Null (and `error` set) when the role refuses to start.
  static std::unique_ptr<Rig> make(const std::vector<std::string>& sets, TimeNs start = 0, std::string* error = nullptr) {
    auto rig = std::make_unique<Rig>();
    rig->clock.set(start);
    static const std::vector<ParamSection> schema = role_schema(kRole);
    Config cfg = Config::defaults(schema);
    EXPECT_TRUE(cfg.set("camera.vo_channel=visual_odometry").ok());  // the sink reads the recording's odometry there
    for (const std::string& s : sets) EXPECT_TRUE(cfg.set(s).ok()) << s;
    auto r = RoleInstance::create(kRole, cfg, rig->clock, "uav");
    if (!r.ok()) {
      if (error != nullptr) *error = r.error().message;
      return nullptr;
    }
    rig->role = std::move(r).value();
    rig->stage = find_stage<CameraStage>(rig->role.get());
    rig->sink = find_stage<Sink>(rig->role.get());
    return rig;
  }
  void step(TimeNs now) {
    clock.set(now);
    stage->step(now);
    sink->step(now);
  }
};

// The fake device for the stages made while it lives.
struct FakeCamera {
  v4l2::testing::FakeDevice dev;
  FakeCamera() { CameraStage::set_syscalls_for_tests(&dev); }
  ~FakeCamera() { CameraStage::set_syscalls_for_tests(nullptr); }
  FakeCamera(const FakeCamera&) = delete;
  FakeCamera& operator=(const FakeCamera&) = delete;
};

// --- the frame stream -----------------------------------------------------------------------------

TEST(FrameStream, Crc32IsZlibs) {
  const char* s = "123456789";
  const std::span<const std::uint8_t> b(reinterpret_cast<const std::uint8_t*>(s), 9);
  EXPECT_EQ(crc32(b), 0xCBF43926U);
  EXPECT_EQ(crc32(b.subspan(4), crc32(b.first(4))), 0xCBF43926U);  // running
  EXPECT_EQ(crc32({}), 0U);
}

TEST(FrameStream, RoundTripThroughAFile) {
  const std::string path = temp_dir() + "round_trip.agfs";
  std::vector<std::unique_ptr<CameraImageMsg>> images;
  std::vector<VoMsg> vo;
  {
    auto w = FrameStreamWriter::open(path);
    ASSERT_TRUE(w.ok()) << w.error().message;
    for (std::uint32_t i = 0; i < 3; ++i) {
      images.push_back(make_image(100 + i, 7'000'000'000 + i * 100'000'000LL, i));
      images.back()->labels = static_cast<LabelSource>(i);
      ASSERT_TRUE(w.value().write_image(*images.back()).ok());
      for (std::uint32_t k = 0; k < 2; ++k) {
        vo.push_back(make_vo(2 * i + k, images.back()->stamp + k * 50'000'000LL));
        ASSERT_TRUE(w.value().write_vo(vo.back()).ok());
      }
    }
  }
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(static_cast<std::size_t>(st.st_size), 3 * kMaxRecordSize + 6 * (kRecordHeaderSize + kVoPayloadSize + kRecordCrcSize));
  auto r = FrameStreamReader::open(path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_FALSE(r.value()->is_fifo());
  const Drained d = drain(*r.value());
  EXPECT_TRUE(d.ended);
  ASSERT_EQ(d.images.size(), 3u);
  ASSERT_EQ(d.vo.size(), 6u);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_TRUE(same_image(*d.images[i], *images[i])) << "image " << i;
  for (std::size_t i = 0; i < 6; ++i) expect_same_vo(d.vo[i], vo[i]);
  const FrameStreamCounters& c = r.value()->counters();
  EXPECT_EQ(c.images, 3u);
  EXPECT_EQ(c.vo, 6u);
  EXPECT_EQ(c.garbage_bytes + c.crc_errors + c.bad_records + c.read_errors, 0u);
  EXPECT_TRUE(r.value()->last_error().empty());
  CameraImageMsg img;
  VoMsg v;
  EXPECT_EQ(r.value()->next(img, v), ReadResult::kEnd);  // and it stays at the end
}

TEST(FrameStream, CorruptionLosesOnlyTheDamagedRecords) {
  const std::string path = temp_dir() + "corrupt.agfs";
  std::vector<std::uint8_t> s, rec;
  auto img0 = make_image(1, 1'000, 1), img1 = make_image(2, 2'000, 2), img2 = make_image(3, 3'000, 3);
  const VoMsg vo0 = make_vo(0, 1'500), vo1 = make_vo(1, 2'500), vo2 = make_vo(2, 3'500), vo3 = make_vo(3, 3'700);
  encode_image_record(*img0, rec);
  append(s, rec);
  // 37 bytes of garbage, with false starts of the magic in it and right before the next record.
  const std::string junk = "xxAGFxxAxxAGFxAGFZzzzzzzzzzzzzzzzzAAG";
  ASSERT_EQ(junk.size(), 37u);
  s.insert(s.end(), junk.begin(), junk.end());
  encode_vo_record(vo0, rec);
  append(s, rec);
  encode_image_record(*img1, rec);
  rec[kRecordHeaderSize + 5000] ^= 0x10;  // one flipped bit in the picture: the CRC catches it
  append(s, rec);
  encode_vo_record(vo1, rec);
  append(s, rec);
  // An image of another size, consistent and with a good CRC: skipped whole.
  std::vector<std::uint8_t> small(kImagePayloadHeaderSize + 320 * 200 * 4, 0x41);
  small[12] = 320 & 0xFF, small[13] = 320 >> 8, small[14] = 200, small[15] = 0;
  append(s, raw_record(1, 1, small));
  encode_vo_record(vo2, rec);
  append(s, rec);
  // A record of a later version and one of an unknown type (good CRCs): dropped.
  append(s, raw_record(2, 2, std::vector<std::uint8_t>(kVoPayloadSize, 0)));
  append(s, raw_record(1, 9, std::vector<std::uint8_t>(kVoPayloadSize, 0)));
  encode_vo_record(vo3, rec);
  append(s, rec);
  encode_image_record(*img2, rec);
  rec.resize(rec.size() / 2);  // the recording was cut off
  append(s, rec);
  write_file(path, s);

  auto r = FrameStreamReader::open(path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  const Drained d = drain(*r.value());
  EXPECT_TRUE(d.ended);
  ASSERT_EQ(d.images.size(), 1u);
  EXPECT_TRUE(same_image(*d.images[0], *img0));
  ASSERT_EQ(d.vo.size(), 4u);
  expect_same_vo(d.vo[0], vo0);
  expect_same_vo(d.vo[1], vo1);
  expect_same_vo(d.vo[2], vo2);
  expect_same_vo(d.vo[3], vo3);
  const FrameStreamCounters& c = r.value()->counters();
  EXPECT_EQ(c.garbage_bytes, 37u);  // the junk, and nothing of the dropped records
  EXPECT_EQ(c.crc_errors, 1u);
  EXPECT_EQ(c.bad_records, 4u);  // the 320x200 image, version 2, type 9, the truncated image
  EXPECT_EQ(c.read_errors, 0u);
  const std::string e(r.value()->last_error());
  EXPECT_NE(e.find(path), std::string::npos) << e;
  EXPECT_NE(e.find("truncated"), std::string::npos) << e;
  EXPECT_NE(e.find("byte " + std::to_string(s.size() - rec.size())), std::string::npos) << e;
}

TEST(FrameStream, EachFaultIsNamed) {
  const std::string dir = temp_dir();
  auto last_error_of = [&](const std::vector<std::uint8_t>& bytes, FrameStreamCounters& c) {
    write_file(dir + "one.agfs", bytes);
    auto r = FrameStreamReader::open(dir + "one.agfs");
    EXPECT_TRUE(r.ok());
    const Drained d = drain(*r.value());
    EXPECT_TRUE(d.ended);
    EXPECT_EQ(d.vo.size(), 1u);  // the good record after the bad one
    c = r.value()->counters();
    return std::string(r.value()->last_error());
  };
  std::vector<std::uint8_t> good;
  encode_vo_record(make_vo(5, 42), good);
  FrameStreamCounters c;
  std::vector<std::uint8_t> s;
  encode_vo_record(make_vo(4, 41), s);
  s[kRecordHeaderSize + 20] ^= 1;
  append(s, good);
  EXPECT_NE(last_error_of(s, c).find("CRC-32"), std::string::npos);
  EXPECT_EQ(c.crc_errors, 1u);
  s = raw_record(1, 2, std::vector<std::uint8_t>(kVoPayloadSize - 1, 0));  // a VO record one byte short
  append(s, good);
  EXPECT_NE(last_error_of(s, c).find("VO record of 63 bytes"), std::string::npos);
  EXPECT_EQ(c.bad_records, 1u);
  s = raw_record(3, 2, std::vector<std::uint8_t>(kVoPayloadSize, 0));
  append(s, good);
  EXPECT_NE(last_error_of(s, c).find("version 3"), std::string::npos);
  s = raw_record(1, 7, std::vector<std::uint8_t>(kVoPayloadSize, 0));
  append(s, good);
  EXPECT_NE(last_error_of(s, c).find("unknown record type 7"), std::string::npos);
  std::vector<std::uint8_t> big(kImagePayloadHeaderSize + 1280 * 800 * 4, 0);  // larger than the reader's buffer
  big[12] = 0, big[13] = 5, big[14] = 0x20, big[15] = 3;
  s = raw_record(1, 1, big);
  append(s, good);
  EXPECT_NE(last_error_of(s, c).find("image 1280x800"), std::string::npos);
  EXPECT_EQ(c.bad_records, 1u);
  EXPECT_EQ(c.garbage_bytes, 0u);
}

TEST(FrameStream, FifoReadWhileWritten) {
  const std::string path = temp_dir() + "camera.fifo";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  auto early = FrameStreamWriter::open(path);  // nobody reads yet: an error, not a writer stuck in open()
  ASSERT_FALSE(early.ok());
  EXPECT_NE(early.error().message.find(path), std::string::npos) << early.error().message;
  auto r = FrameStreamReader::open(path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  FrameStreamReader& reader = *r.value();
  EXPECT_TRUE(reader.is_fifo());
  auto img = std::make_unique<CameraImageMsg>();
  VoMsg vo;
  EXPECT_EQ(reader.next(*img, vo), ReadResult::kNone);  // no writer yet: not the end
  std::vector<std::unique_ptr<CameraImageMsg>> sent;
  for (std::uint32_t i = 0; i < 3; ++i) sent.push_back(make_image(i, 10 * i, 50 + i));
  std::string writer_error;
  std::thread writer([&] {
    auto w = FrameStreamWriter::open(path);
    if (!w.ok()) {
      writer_error = w.error().message;
      return;
    }
    for (std::uint32_t i = 0; i < 5; ++i) {
      const Status st = i % 2 == 0 ? w.value().write_image(*sent[i / 2]) : w.value().write_vo(make_vo(i, 10 * i + 5));
      if (!st.ok()) {
        writer_error = st.error().message;
        return;
      }
    }
  });  // closes when it goes out of scope
  std::vector<ReadResult> got;
  std::size_t images = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (std::chrono::steady_clock::now() < deadline) {
    const ReadResult k = reader.next(*img, vo);
    if (k == ReadResult::kNone) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    got.push_back(k);
    if (k == ReadResult::kImage) {
      EXPECT_TRUE(same_image(*img, *sent[images])) << "image " << images;
      ++images;
    }
    if (k == ReadResult::kVo) {
      EXPECT_EQ(vo.stamp, 10 * static_cast<TimeNs>(got.size() - 1) + 5);
    }
    if (k == ReadResult::kEnd) break;
  }
  writer.join();
  EXPECT_EQ(writer_error, "");
  ASSERT_EQ(got.size(), 6u);
  EXPECT_EQ(got, (std::vector<ReadResult>{ReadResult::kImage, ReadResult::kVo, ReadResult::kImage, ReadResult::kVo, ReadResult::kImage,
                                          ReadResult::kEnd}));
  EXPECT_EQ(reader.next(*img, vo), ReadResult::kEnd);
  EXPECT_EQ(reader.counters().garbage_bytes + reader.counters().crc_errors + reader.counters().bad_records, 0u);
}

TEST(FrameStream, AReaderThatLeftIsAnErrorNotASignal) {
  const std::string path = temp_dir() + "gone.fifo";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  auto r = FrameStreamReader::open(path);
  ASSERT_TRUE(r.ok());
  auto w = FrameStreamWriter::open(path);
  ASSERT_TRUE(w.ok()) << w.error().message;
  ASSERT_TRUE(w.value().write_vo(make_vo(0, 1)).ok());
  r.value().reset();
  const Status st = w.value().write_vo(make_vo(1, 2));  // EPIPE; without the guard SIGPIPE ends the test
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find(path), std::string::npos) << st.error().message;
}

TEST(FrameStream, AFullFifoTimesOutAfterOneSecond) {
  const std::string path = temp_dir() + "full.fifo";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  auto r = FrameStreamReader::open(path);  // opened, never read
  ASSERT_TRUE(r.ok());
  auto w = FrameStreamWriter::open(path);
  ASSERT_TRUE(w.ok());
  auto img = make_image(0, 0, 0);  // 1 MB: more than the pipe holds
  const auto t0 = std::chrono::steady_clock::now();
  const Status st = w.value().write_image(*img);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::kTimeout);
  EXPECT_NE(st.error().message.find(path), std::string::npos) << st.error().message;
  EXPECT_GE(s, 0.9);
  EXPECT_LT(s, 5.0);
}

// --- the resampler ----------------------------------------------------------------------------------

TEST(AreaResampler, AveragesTheAreaEachOutputPixelCovers) {
  // 3 x 2 BGR to 2 x 1: each output pixel covers 1.5 source columns and both rows.
  const std::uint8_t bgr[] = {10, 20, 30, 40, 50, 60, 70, 80, 90,     // row 0
                              30, 40, 50, 60, 70, 80, 90, 100, 110};  // row 1
  AreaResampler a;
  a.configure(3, 2, 2, 1);
  std::uint8_t rgb[6] = {};
  a.run(bgr, rgb);
  // Blue of output 0: (1 * 20 + 0.5 * 50) / 1.5 (column means 20, 50, 80) = 30; output 1: (0.5 * 50 + 80) / 1.5 = 70.
  EXPECT_EQ(rgb[2], 30);
  EXPECT_EQ(rgb[1], 40);
  EXPECT_EQ(rgb[0], 50);
  EXPECT_EQ(rgb[5], 70);
  EXPECT_EQ(rgb[4], 80);
  EXPECT_EQ(rgb[3], 90);
  // Enlarging is bilinear: 2 x 1 to 4 x 1.
  const std::uint8_t two[] = {0, 0, 0, 200, 200, 200};
  a.configure(2, 1, 4, 1);
  std::uint8_t out[12] = {};
  a.run(two, out);
  EXPECT_EQ(out[0], 0);
  EXPECT_EQ(out[3], 50);
  EXPECT_EQ(out[6], 150);
  EXPECT_EQ(out[9], 200);
}

// --- the stage: replay ------------------------------------------------------------------------------

// A recording of `n` images 100 ms apart from `t0`, each followed by 2 VO messages 50 ms apart.
std::vector<std::unique_ptr<CameraImageMsg>> write_recording(const std::string& path, int n, TimeNs t0, std::vector<VoMsg>& vo) {
  std::vector<std::unique_ptr<CameraImageMsg>> images;
  auto w = FrameStreamWriter::open(path);
  EXPECT_TRUE(w.ok());
  for (int i = 0; i < n; ++i) {
    const TimeNs t = t0 + i * 100 * kNsPerMs;
    images.push_back(make_image(static_cast<std::uint32_t>(i + 1), t, static_cast<std::uint32_t>(i)));
    EXPECT_TRUE(w.value().write_image(*images.back()).ok());
    for (int k = 0; k < 2; ++k) {
      vo.push_back(make_vo(static_cast<std::uint32_t>(2 * i + k), t + k * 50 * kNsPerMs));
      EXPECT_TRUE(w.value().write_vo(vo.back()).ok());
    }
  }
  return images;
}

TEST(CameraStage, ReplayPublishesImagesAndVoInOrder) {
  const std::string path = temp_dir() + "flight.agfs";
  std::vector<VoMsg> vo;
  const auto images = write_recording(path, 7, 3 * kNsPerS, vo);
  auto rig = Rig::make({"camera.source=replay", "camera.replay=" + path});
  ASSERT_NE(rig, nullptr);
  // The camera ring holds 4 and the stage gives at most 2 images a step: nothing may be lost to that.
  for (int i = 1; i <= 10 && !rig->stage->replay_finished(); ++i) rig->step(i * 50 * kNsPerMs);
  EXPECT_TRUE(rig->stage->replay_finished());
  ASSERT_EQ(rig->sink->images.size(), 7u);
  ASSERT_EQ(rig->sink->vo.size(), 14u);
  for (std::size_t i = 0; i < 7; ++i) {
    EXPECT_TRUE(same_image(*rig->sink->images[i], *images[i])) << "image " << i;  // recorded stamps kept
    EXPECT_GT(rig->sink->images[i]->published, 0);
  }
  for (std::size_t i = 0; i < 14; ++i) expect_same_vo(rig->sink->vo[i], vo[i]);
  const CameraStageCounters& c = rig->stage->counters();
  EXPECT_EQ(c.frames_published, 7u);
  EXPECT_EQ(c.vo_published, 14u);
  EXPECT_EQ(c.ring_full, 0u);
  EXPECT_EQ(c.device_errors, 0u);
  EXPECT_EQ(c.replay.images, 7u);
  EXPECT_EQ(c.replay.vo, 14u);
  rig->step(kNsPerS);  // finished: idle
  EXPECT_EQ(rig->sink->images.size(), 7u);
}

TEST(CameraStage, ADamagedRecordingLosesOnlyTheDamagedRecords) {
  const std::string path = temp_dir() + "damaged.agfs";
  std::vector<std::uint8_t> s, rec;
  auto a = make_image(1, 1'000, 1), b = make_image(2, 2'000, 2);
  encode_image_record(*a, rec);
  append(s, rec);
  s.insert(s.end(), 11, 0x55);
  encode_image_record(*b, rec);
  rec[rec.size() / 2] ^= 0xFF;
  append(s, rec);
  encode_vo_record(make_vo(0, 2'500), rec);
  append(s, rec);
  write_file(path, s);
  auto rig = Rig::make({"camera.source=replay", "camera.replay=" + path});
  ASSERT_NE(rig, nullptr);
  for (int i = 1; i <= 4; ++i) rig->step(i * 50 * kNsPerMs);
  EXPECT_TRUE(rig->stage->replay_finished());
  ASSERT_EQ(rig->sink->images.size(), 1u);
  EXPECT_TRUE(same_image(*rig->sink->images[0], *a));
  EXPECT_EQ(rig->sink->vo.size(), 1u);
  const CameraStageCounters& c = rig->stage->counters();
  EXPECT_EQ(c.replay.garbage_bytes, 11u);
  EXPECT_EQ(c.replay.crc_errors, 1u);
  EXPECT_EQ(c.device_errors, 0u);  // a damaged record is the recording's fault, not the device's
}

TEST(CameraStage, ArrivalStampsKeepTheIntervalsAndPaceFollowsThem) {
  const std::string path = temp_dir() + "other_boot.agfs";
  std::vector<VoMsg> vo;
  (void)write_recording(path, 4, 987 * kNsPerS, vo);  // stamped on another boot's clock
  const TimeNs start = 20 * kNsPerS;
  auto rig = Rig::make({"camera.source=replay", "camera.replay=" + path, "camera.stamps=arrival", "camera.pace=true"}, start);
  ASSERT_NE(rig, nullptr);
  // Steps every 20 ms: each record comes out in the first step at or after its recorded offset.
  for (TimeNs t = start + 10 * kNsPerMs; t < start + kNsPerS; t += 20 * kNsPerMs) rig->step(t);
  ASSERT_EQ(rig->sink->images.size(), 4u);
  ASSERT_EQ(rig->sink->vo.size(), 8u);
  const TimeNs first = start + 10 * kNsPerMs;  // the first record arrived in the first step
  for (std::size_t i = 0; i < 4; ++i) {
    const CameraImageMsg& m = *rig->sink->images[i];
    EXPECT_EQ(m.stamp, first + static_cast<TimeNs>(i) * 100 * kNsPerMs) << i;
    EXPECT_GE(m.published, m.stamp) << i;
    EXPECT_LT(m.published, m.stamp + 20 * kNsPerMs) << i;
  }
  for (std::size_t i = 0; i < 8; ++i) {
    EXPECT_EQ(rig->sink->vo[i].stamp, first + static_cast<TimeNs>(i / 2) * 100 * kNsPerMs + static_cast<TimeNs>(i % 2) * 50 * kNsPerMs) << i;
    EXPECT_GE(rig->sink->vo[i].published, rig->sink->vo[i].stamp) << i;
    EXPECT_LT(rig->sink->vo[i].published, rig->sink->vo[i].stamp + 20 * kNsPerMs) << i;
  }
}

TEST(CameraStage, ReplayFifoCreatedAfterStartIsOpenedWithinASecond) {
  const std::string path = temp_dir() + "hil.fifo";
  auto rig = Rig::make({"camera.source=replay", "camera.replay=" + path});
  ASSERT_NE(rig, nullptr);
  EXPECT_EQ(rig->stage->counters().device_errors, 1u);  // logged, counted, not fatal
  EXPECT_EQ(rig->stage->reader(), nullptr);
  rig->step(500 * kNsPerMs);
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  rig->step(900 * kNsPerMs);
  EXPECT_EQ(rig->stage->reader(), nullptr);  // retried once a second
  rig->step(1000 * kNsPerMs);
  ASSERT_NE(rig->stage->reader(), nullptr);
  EXPECT_TRUE(rig->stage->reader()->is_fifo());
  EXPECT_EQ(rig->stage->counters().reopens, 1u);
  EXPECT_EQ(rig->stage->counters().device_errors, 1u);
  auto img = make_image(9, 123 * kNsPerMs, 9);
  std::thread writer([&] {
    auto w = FrameStreamWriter::open(path);
    ASSERT_TRUE(w.ok()) << w.error().message;
    EXPECT_TRUE(w.value().write_vo(make_vo(0, 100 * kNsPerMs)).ok());
    EXPECT_TRUE(w.value().write_image(*img).ok());
    EXPECT_TRUE(w.value().write_vo(make_vo(1, 150 * kNsPerMs)).ok());
  });
  TimeNs t = 1000 * kNsPerMs;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (!rig->stage->replay_finished() && std::chrono::steady_clock::now() < deadline) {
    rig->step(t += 50 * kNsPerMs);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  writer.join();
  EXPECT_TRUE(rig->stage->replay_finished());  // the writer closed
  ASSERT_EQ(rig->sink->images.size(), 1u);
  EXPECT_TRUE(same_image(*rig->sink->images[0], *img));
  ASSERT_EQ(rig->sink->vo.size(), 2u);
  EXPECT_EQ(rig->sink->vo[1].stamp, 150 * kNsPerMs);
}

TEST(CameraStage, AbsentReplayFileOrDeviceIsCountedNotFatal) {
  auto replay = Rig::make({"camera.source=replay", "camera.replay=/nonexistent/flight.agfs"});
  ASSERT_NE(replay, nullptr);
  EXPECT_EQ(replay->stage->counters().device_errors, 1u);
  for (int i = 1; i <= 30; ++i) replay->step(i * 100 * kNsPerMs);
  EXPECT_EQ(replay->stage->counters().device_errors, 1u);  // the retries are not logged again
  EXPECT_TRUE(replay->sink->images.empty());
  EXPECT_TRUE(replay->sink->vo.empty());

  // The real system calls on a device node that does not exist.
  auto dev = Rig::make({"camera.source=v4l2", "camera.device=/dev/nonexistent-video9"});
  ASSERT_NE(dev, nullptr);
  EXPECT_EQ(dev->stage->counters().device_errors, 1u);
  EXPECT_EQ(dev->stage->camera(), nullptr);
  for (int i = 1; i <= 50; ++i) dev->step(i * 100 * kNsPerMs);
  EXPECT_EQ(dev->stage->counters().device_errors, 1u);
  EXPECT_EQ(dev->stage->counters().frames_published, 0u);
  EXPECT_TRUE(dev->sink->images.empty());

  auto none = Rig::make({"camera.source=none"});
  ASSERT_NE(none, nullptr);
  none->step(kNsPerS);
  EXPECT_TRUE(none->sink->images.empty());

  std::string error;
  EXPECT_EQ(Rig::make({"camera.source=replay"}, 0, &error), nullptr);  // replay of nothing: a config error
  EXPECT_NE(error.find("camera.replay"), std::string::npos) << error;
}

// --- the stage: V4L2 ----------------------------------------------------------------------------------

// YUYV of one colour for `pixels` pixels (pairs).
void yuyv_run(std::vector<std::uint8_t>& line, std::size_t pixels, std::uint8_t y, std::uint8_t u, std::uint8_t v) {
  for (std::size_t i = 0; i < pixels / 2; ++i) line.insert(line.end(), {y, u, y, v});
}

// The RGB the driver's own conversion gives for one YUYV colour.
std::array<std::uint8_t, 3> rgb_of(std::uint8_t y, std::uint8_t u, std::uint8_t v) {
  const std::uint8_t px[4] = {y, u, y, v};
  v4l2::Frame f;
  f.data = px;
  f.width = 2, f.height = 1, f.stride = 4;
  f.format = v4l2::PixelFormat::kYuyv;
  std::uint8_t bgr[6];
  v4l2::to_bgr(f, bgr);
  return {bgr[2], bgr[1], bgr[0]};
}

TEST(CameraStage, V4l2YuyvFrameComesOutAsRgbAt640x400) {
  FakeCamera fake;
  // Left half red, right half blue (BT.601 limited range), 1280 x 800.
  yuyv_run(fake.dev.line, 640, 81, 90, 240);
  yuyv_run(fake.dev.line, 640, 41, 240, 110);
  using v4l2::testing::FakeEvent;
  for (std::uint32_t i = 0; i < 3; ++i) fake.dev.script.push_back({FakeEvent::Kind::kFrame, 7 + i, 1'000'000 + i * 100'000});
  auto rig = Rig::make({"camera.source=v4l2", "camera.format=YUYV", "camera.width=1280", "camera.height=800"});
  ASSERT_NE(rig, nullptr);
  ASSERT_NE(rig->stage->camera(), nullptr);
  EXPECT_EQ(rig->stage->counters().device_errors, 0u);
  EXPECT_EQ(fake.dev.width, 1280u);
  EXPECT_EQ(fake.dev.height, 800u);
  rig->step(kNsPerS);
  EXPECT_EQ(rig->sink->images.size(), 2u);  // max_frames_per_step
  rig->step(kNsPerS + 50 * kNsPerMs);
  ASSERT_EQ(rig->sink->images.size(), 3u);
  const auto red = rgb_of(81, 90, 240), blue = rgb_of(41, 240, 110);
  EXPECT_GT(red[0], 240);
  EXPECT_LT(red[1], 10);
  EXPECT_LT(blue[1], 10);
  EXPECT_GT(blue[2], 230);
  for (std::size_t i = 0; i < 3; ++i) {
    const CameraImageMsg& m = *rig->sink->images[i];
    EXPECT_EQ(m.seq, i + 1);
    EXPECT_EQ(m.stamp, (1'000'000 + static_cast<TimeNs>(i) * 100'000) * kNsPerUs + 5 * kNsPerMs / 2);  // mid-exposure
    EXPECT_EQ(m.labels, LabelSource::kNone);
    int wrong = 0;
    for (int y = 0; y < kImageHeight; ++y)
      for (int x = 0; x < kImageWidth; ++x) {
        const std::uint8_t* p = m.rgb.data() + (static_cast<std::size_t>(y) * kImageWidth + static_cast<std::size_t>(x)) * 3;
        const auto& want = x < kImageWidth / 2 ? red : blue;
        if (p[0] != want[0] || p[1] != want[1] || p[2] != want[2]) ++wrong;
      }
    EXPECT_EQ(wrong, 0) << "image " << i;
    bool all_unknown = true;
    for (std::uint8_t c : m.cls) all_unknown = all_unknown && c == 255;
    EXPECT_TRUE(all_unknown);
  }
  EXPECT_EQ(rig->stage->counters().frames_published, 3u);
  EXPECT_EQ(fake.dev.queued.size(), 4u);  // every buffer back with the driver
}

TEST(CameraStage, V4l2FailureIsLoggedOnceAndReopenedEvery2s) {
  FakeCamera fake;
  using v4l2::testing::FakeEvent;
  fake.dev.script = {{FakeEvent::Kind::kFrame, 1, 1'000}, {FakeEvent::Kind::kError}};
  auto rig = Rig::make({"camera.source=v4l2"}, 10 * kNsPerS);
  ASSERT_NE(rig, nullptr);
  rig->step(11 * kNsPerS);
  EXPECT_EQ(rig->sink->images.size(), 1u);
  EXPECT_EQ(rig->stage->camera(), nullptr);  // DQBUF EIO: the camera failed
  EXPECT_EQ(rig->stage->counters().device_errors, 1u);
  fake.dev.path = "/dev/unplugged";  // gone for a while
  rig->step(12 * kNsPerS);
  rig->step(13 * kNsPerS);  // retried (2 s), absent
  EXPECT_EQ(rig->stage->camera(), nullptr);
  fake.dev.path = "/dev/video0";
  fake.dev.script = {{FakeEvent::Kind::kFrame, 1, 2'000}};
  rig->step(14 * kNsPerS);  // 1 s after the last try: not yet
  EXPECT_EQ(rig->stage->camera(), nullptr);
  rig->step(15 * kNsPerS);
  ASSERT_NE(rig->stage->camera(), nullptr);
  EXPECT_EQ(rig->stage->counters().reopens, 1u);
  EXPECT_EQ(rig->stage->counters().device_errors, 1u);
  rig->step(15 * kNsPerS + 50 * kNsPerMs);
  EXPECT_EQ(rig->sink->images.size(), 2u);
  EXPECT_EQ(rig->sink->images[1]->seq, 2u);
}

// --- no allocation ------------------------------------------------------------------------------------

#if AG_COUNT_ALLOC
TEST(CameraStage, StepDoesNotAllocate) {
  const std::string path = temp_dir() + "no_alloc.agfs";
  std::vector<VoMsg> vo;
  (void)write_recording(path, 8, kNsPerS, vo);
  auto rig = Rig::make({"camera.source=replay", "camera.replay=" + path});
  ASSERT_NE(rig, nullptr);
  rig->sink->images.reserve(16);
  rig->sink->vo.reserve(32);
  std::uint64_t allocations = 0;
  for (int i = 1; i <= 8; ++i) {
    const TimeNs t = i * 50 * kNsPerMs;
    {
      test_alloc::AllocationWindow w;
      rig->stage->step(t);
      allocations += w.allocations();
    }
    rig->sink->step(t);  // (the sink's copies allocate: not under test)
  }
  EXPECT_EQ(allocations, 0u) << "replay step() allocated";
  EXPECT_EQ(rig->sink->images.size(), 8u);
  EXPECT_EQ(rig->sink->vo.size(), 16u);

  FakeCamera fake;
  using v4l2::testing::FakeEvent;
  for (std::uint32_t i = 0; i < 6; ++i) fake.dev.script.push_back({FakeEvent::Kind::kFrame, i, 1'000 + i});
  fake.dev.script.push_back({FakeEvent::Kind::kError});
  auto live = Rig::make({"camera.source=v4l2"});
  ASSERT_NE(live, nullptr);
  auto steps = [&](int from, int to) {
    std::uint64_t n = 0;
    for (int i = from; i <= to; ++i) {
      test_alloc::AllocationWindow w;
      live->stage->step(i * kNsPerS);
      n += w.allocations();
    }
    return n;
  };
  EXPECT_EQ(steps(1, 3), 0u) << "v4l2 step() allocated while streaming";
  fake.dev.path = "/dev/unplugged";
  live->stage->step(4 * kNsPerS);  // the failure: the driver formats its error message (once per failure)
  EXPECT_EQ(steps(5, 12), 0u) << "v4l2 step() allocated while retrying an absent device";
  EXPECT_EQ(live->stage->counters().frames_published, 6u);
  EXPECT_EQ(live->stage->counters().device_errors, 1u);
}
#endif

}  // namespace
}  // namespace ag::camera

namespace ag::camera {
namespace {

// The simulator's backend (source: sim): frames the simulated camera commits come out of the stage in
// order and unchanged; a frame with no free slot is dropped and counted; a robot the simulator gave no
// camera is a configuration error naming it; the step does not allocate.
TEST(CameraStage, TheSimulatorsCameraFramesComeOutInOrderAndAFullLinkDrops) {
  std::string error;
  EXPECT_EQ(Rig::make({"camera.source=sim"}, 0, &error), nullptr);
  EXPECT_NE(error.find("camera.source is sim but the simulator gave robot 'uav' no camera"), std::string::npos) << error;

  SimCameraLink link(2);
  ASSERT_TRUE(register_sim_camera("uav", &link));
  auto rig = Rig::make({"camera.source=sim"});
  unregister_sim_camera("uav");
  ASSERT_NE(rig, nullptr);
  std::vector<std::unique_ptr<CameraImageMsg>> sent;
  for (std::uint32_t i = 0; i < 3; ++i) {
    auto img = make_image(i, 1'000 + i, i);
    CameraImageMsg* slot = link.begin_frame();
    if (i < 2) {
      ASSERT_NE(slot, nullptr) << i;
      *slot = *img;
      link.commit();
      sent.push_back(std::move(img));
    } else {
      EXPECT_EQ(slot, nullptr) << "both slots are taken until the stage steps";
    }
  }
  EXPECT_EQ(link.dropped(), 1u);
  {
#if AG_COUNT_ALLOC
    test_alloc::AllocationWindow w;
#endif
    rig->stage->step(50 * kNsPerMs);
#if AG_COUNT_ALLOC
    EXPECT_EQ(w.allocations(), 0u) << "sim step() allocated";
#endif
  }
  rig->sink->step(50 * kNsPerMs);
  ASSERT_EQ(rig->sink->images.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) EXPECT_TRUE(same_image(*rig->sink->images[i], *sent[i])) << "image " << i;
  EXPECT_EQ(rig->stage->counters().frames_published, 2u);
  EXPECT_EQ(link.front(), nullptr) << "the stage took both";
  ASSERT_NE(link.begin_frame(), nullptr) << "and freed their slots";
}

}  // namespace
}  // namespace ag::camera
