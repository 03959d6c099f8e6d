// The frame stream: the quadrotor's camera images and visual odometry as a byte stream of typed
// records, so a recording (a file) or a live producer on the same machine (the HIL simulator, through a
// FIFO) can stand in for the camera. Little-endian, version 1:
//
//   record   "AGFS"  u16 version (1)  u16 type (1 image, 2 VO)  u32 payload length  payload  u32 CRC-32
//            (IEEE, zlib's crc32, over the 12 header bytes and the payload)
//   image    i64 stamp_ns (CLOCK_MONOTONIC, exposure)  u32 seq  u16 width  u16 height  u8 labels
//            (LabelSource)  3 pad  rgb (width*height*3, RGB row-major)  cls (width*height class ids)
//            v1 readers take only kImageWidth x kImageHeight (640x400); other sizes are skipped, counted
//   VO       i64 stamp_ns  u32 segment  u8 tracking  3 pad  f64 x y z roll pitch yaw
//
// The writer (simulator, tools) may allocate; the reader (the camera stage's step) never allocates
// after open() and never blocks: it keeps one preallocated buffer and hands out one record per call.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "airground/messages/messages.hpp"
#include "airground/platform/result.hpp"

namespace ag::camera {

inline constexpr std::array<std::uint8_t, 4> kFrameStreamMagic{'A', 'G', 'F', 'S'};
inline constexpr std::uint16_t kFrameStreamVersion = 1;
enum class RecordType : std::uint16_t { kImage = 1, kVo = 2 };

inline constexpr std::size_t kRecordHeaderSize = 12;
inline constexpr std::size_t kRecordCrcSize = 4;
inline constexpr std::size_t kImagePayloadHeaderSize = 20;
inline constexpr std::size_t kImagePayloadSize = kImagePayloadHeaderSize + kImagePixels * 4;
inline constexpr std::size_t kVoPayloadSize = 64;
inline constexpr std::size_t kMaxRecordSize = kRecordHeaderSize + kImagePayloadSize + kRecordCrcSize;

// CRC-32 (IEEE 802.3, reflected 0xEDB88320: zlib's crc32); `crc` continues a running value.
[[nodiscard]] std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc = 0) noexcept;

// Whole records into a byte vector (the writer's encoding; tests build corrupt streams from it).
void encode_image_record(const CameraImageMsg& m, std::vector<std::uint8_t>& out);
void encode_vo_record(const VoMsg& m, std::vector<std::uint8_t>& out);

class FrameStreamWriter {
 public:
  // Opens `path` for writing (created, truncated). A FIFO is opened non-blocking: a FIFO without a
  // reader is an error (ENXIO) rather than a writer stuck in open(), so start the reader first.
  static Result<FrameStreamWriter> open(const std::string& path);
  // Takes ownership of an open descriptor (blocking or not); `name` names it in errors.
  static Result<FrameStreamWriter> from_fd(int fd, std::string name = {});

  FrameStreamWriter(FrameStreamWriter&& o) noexcept;
  FrameStreamWriter& operator=(FrameStreamWriter&& o) noexcept;
  FrameStreamWriter(const FrameStreamWriter&) = delete;
  FrameStreamWriter& operator=(const FrameStreamWriter&) = delete;
  ~FrameStreamWriter();

  // Write one whole record. A full non-blocking FIFO is waited for up to 1 s, then the error names the
  // path; a reader that went away is an error (EPIPE; SIGPIPE is not raised).
  Status write_image(const CameraImageMsg& m);
  Status write_vo(const VoMsg& m);
  void close() noexcept;
  [[nodiscard]] const std::string& path() const noexcept { return path_; }

 private:
  FrameStreamWriter(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  Status write_all(std::span<const std::uint8_t> bytes);
  int fd_{-1};
  std::string path_;
  std::vector<std::uint8_t> buf_;
  std::uint64_t offset_{0};
};

struct FrameStreamCounters {
  std::uint64_t images{0}, vo{0};   // records handed out
  std::uint64_t garbage_bytes{0};   // bytes outside any record, skipped while looking for "AGFS"
  std::uint64_t crc_errors{0};      // records whose CRC-32 did not match: dropped
  std::uint64_t bad_records{0};     // wrong version, unknown type, bad length, wrong image size, truncated: dropped
  std::uint64_t read_errors{0};     // read(2) failures other than EAGAIN/EINTR
};

class FrameStreamReader {
 public:
  enum class ReadResult : std::uint8_t { kImage, kVo, kNone, kEnd };

  // Opens `path` O_RDONLY | O_NONBLOCK (a FIFO opens without a writer) and sizes the buffer once.
  static Result<std::unique_ptr<FrameStreamReader>> open(const std::string& path);
  ~FrameStreamReader();
  FrameStreamReader(const FrameStreamReader&) = delete;
  FrameStreamReader& operator=(const FrameStreamReader&) = delete;

  // The next whole record: kImage (into `img`) or kVo (into `vo`); kNone when no whole record has
  // arrived yet; kEnd at the end of a file, or once a FIFO's writer has closed (and from then on).
  // A damaged record is dropped and counted and reading goes on. Never blocks, never allocates.
  ReadResult next(CameraImageMsg& img, VoMsg& vo) noexcept;

  [[nodiscard]] const FrameStreamCounters& counters() const noexcept { return c_; }
  // The last fault: the path, the byte offset of the record and what was wrong ("" when none).
  [[nodiscard]] std::string_view last_error() const noexcept { return std::string_view(error_.data()); }
  [[nodiscard]] bool is_fifo() const noexcept { return fifo_; }
  [[nodiscard]] const std::string& path() const noexcept { return path_; }
  [[nodiscard]] std::uint64_t offset() const noexcept { return base_ + begin_; }  // stream offset of the next byte to parse

 private:
  FrameStreamReader(int fd, std::string path, bool fifo);
  enum class Parse : std::uint8_t { kImage, kVo, kNeedMore };
  Parse parse(CameraImageMsg& img, VoMsg& vo) noexcept;
  void fault(std::uint64_t& counter, const char* fmt, ...) noexcept __attribute__((format(printf, 3, 4)));
  void resync(std::size_t claimed) noexcept;
  void skip_garbage(std::size_t n) noexcept;

  int fd_{-1};
  std::string path_;
  bool fifo_{false};
  std::unique_ptr<std::uint8_t[]> buf_;
  std::size_t cap_{0}, begin_{0}, end_{0};
  std::uint64_t base_{0};       // stream offset of buf_[0]
  std::size_t skip_{0};         // bytes of a skipped record (wrong image size) still to discard
  std::size_t quiet_{0};        // bytes of a dropped record not to count again as garbage while resyncing
  bool seen_bytes_{false}, ended_{false};
  std::array<char, 256> error_{};
  FrameStreamCounters c_;
};
using ReadResult = FrameStreamReader::ReadResult;

}  // namespace ag::camera
