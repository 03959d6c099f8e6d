// Frame-stream records: encoding, the writer, and the resynchronising reader.
#include "airground/drivers/camera/frame_stream/frame_stream.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "airground/platform/clock.hpp"

namespace ag::camera {

namespace {

// Slicing-by-8: eight bytes per step (a 1 MB image record is checked in well under a millisecond).
constexpr auto kCrcTables = [] {
  std::array<std::array<std::uint32_t, 256>, 8> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1U) != 0 ? 0xEDB88320U ^ (c >> 1) : c >> 1;
    t[0][i] = c;
  }
  for (std::size_t s = 1; s < 8; ++s)
    for (std::size_t i = 0; i < 256; ++i) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xFFU];
  return t;
}();

std::uint16_t get_u16(const std::uint8_t* p) noexcept { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
std::uint32_t get_u32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) | (static_cast<std::uint32_t>(p[2]) << 16) |
         (static_cast<std::uint32_t>(p[3]) << 24);
}
std::uint64_t get_u64(const std::uint8_t* p) noexcept { return get_u32(p) | (static_cast<std::uint64_t>(get_u32(p + 4)) << 32); }
double get_f64(const std::uint8_t* p) noexcept {
  const std::uint64_t u = get_u64(p);
  double d;
  std::memcpy(&d, &u, sizeof d);
  return d;
}

void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void put_u64(std::uint8_t* p, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void put_f64(std::uint8_t* p, double d) noexcept {
  std::uint64_t u;
  std::memcpy(&u, &d, sizeof u);
  put_u64(p, u);
}

// Header and CRC around a payload already written at out[kRecordHeaderSize...].
void seal_record(std::vector<std::uint8_t>& out, RecordType type, std::size_t payload) {
  std::uint8_t* p = out.data();
  std::memcpy(p, kFrameStreamMagic.data(), 4);
  put_u16(p + 4, kFrameStreamVersion);
  put_u16(p + 6, static_cast<std::uint16_t>(type));
  put_u32(p + 8, static_cast<std::uint32_t>(payload));
  put_u32(p + kRecordHeaderSize + payload, crc32(std::span<const std::uint8_t>(p, kRecordHeaderSize + payload)));
}

Error io_error(const std::string& what, int e) {
  return Error::make(e == EACCES || e == EPERM ? ErrorCode::kPermission : e == ENOENT || e == ENXIO ? ErrorCode::kUnavailable : ErrorCode::kIo,
                     what + ": " + std::strerror(e));
}

}  // namespace

std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc) noexcept {
  const auto& t = kCrcTables;
  std::uint32_t c = ~crc;
  const std::uint8_t* p = bytes.data();
  std::size_t n = bytes.size();
  for (; n >= 8; p += 8, n -= 8) {
    const std::uint32_t lo = get_u32(p) ^ c, hi = get_u32(p + 4);
    c = t[7][lo & 0xFFU] ^ t[6][(lo >> 8) & 0xFFU] ^ t[5][(lo >> 16) & 0xFFU] ^ t[4][lo >> 24] ^ t[3][hi & 0xFFU] ^
        t[2][(hi >> 8) & 0xFFU] ^ t[1][(hi >> 16) & 0xFFU] ^ t[0][hi >> 24];
  }
  for (; n > 0; ++p, --n) c = t[0][(c ^ *p) & 0xFFU] ^ (c >> 8);
  return ~c;
}

void encode_image_record(const CameraImageMsg& m, std::vector<std::uint8_t>& out) {
  out.resize(kRecordHeaderSize + kImagePayloadSize + kRecordCrcSize);
  std::uint8_t* p = out.data() + kRecordHeaderSize;
  put_u64(p, static_cast<std::uint64_t>(m.stamp));
  put_u32(p + 8, m.seq);
  put_u16(p + 12, static_cast<std::uint16_t>(kImageWidth));
  put_u16(p + 14, static_cast<std::uint16_t>(kImageHeight));
  p[16] = static_cast<std::uint8_t>(m.labels);
  p[17] = p[18] = p[19] = 0;
  std::memcpy(p + kImagePayloadHeaderSize, m.rgb.data(), m.rgb.size());
  std::memcpy(p + kImagePayloadHeaderSize + m.rgb.size(), m.cls.data(), m.cls.size());
  seal_record(out, RecordType::kImage, kImagePayloadSize);
}

void encode_vo_record(const VoMsg& m, std::vector<std::uint8_t>& out) {
  out.resize(kRecordHeaderSize + kVoPayloadSize + kRecordCrcSize);
  std::uint8_t* p = out.data() + kRecordHeaderSize;
  put_u64(p, static_cast<std::uint64_t>(m.stamp));
  put_u32(p + 8, m.segment);
  p[12] = m.tracking ? 1 : 0;
  p[13] = p[14] = p[15] = 0;
  const double pose[6] = {m.pose.x, m.pose.y, m.pose.z, m.pose.roll, m.pose.pitch, m.pose.yaw};
  for (int i = 0; i < 6; ++i) put_f64(p + 16 + 8 * i, pose[i]);
  seal_record(out, RecordType::kVo, kVoPayloadSize);
}

// --- writer ---------------------------------------------------------------------------------------

Result<FrameStreamWriter> FrameStreamWriter::open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_NONBLOCK | O_CLOEXEC, 0644);
  if (fd < 0) {
    const int e = errno;
    if (e == ENXIO) return Error::make(ErrorCode::kUnavailable, "frame stream " + path + ": no reader has the FIFO open yet (open the reader first)");
    return io_error("frame stream " + path + ": cannot open for writing", e);
  }
  return FrameStreamWriter(fd, path);
}

Result<FrameStreamWriter> FrameStreamWriter::from_fd(int fd, std::string name) {
  if (fd < 0) return Error::make(ErrorCode::kInvalidArgument, "frame stream: from_fd given fd " + std::to_string(fd));
  if (name.empty()) name = "fd " + std::to_string(fd);
  return FrameStreamWriter(fd, std::move(name));
}

FrameStreamWriter::FrameStreamWriter(FrameStreamWriter&& o) noexcept
    : fd_(o.fd_), path_(std::move(o.path_)), buf_(std::move(o.buf_)), offset_(o.offset_) {
  o.fd_ = -1;
}

FrameStreamWriter& FrameStreamWriter::operator=(FrameStreamWriter&& o) noexcept {
  if (this != &o) {
    close();
    fd_ = o.fd_;
    path_ = std::move(o.path_);
    buf_ = std::move(o.buf_);
    offset_ = o.offset_;
    o.fd_ = -1;
  }
  return *this;
}

FrameStreamWriter::~FrameStreamWriter() { close(); }

void FrameStreamWriter::close() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

Status FrameStreamWriter::write_image(const CameraImageMsg& m) {
  encode_image_record(m, buf_);
  return write_all(buf_);
}

Status FrameStreamWriter::write_vo(const VoMsg& m) {
  encode_vo_record(m, buf_);
  return write_all(buf_);
}

Status FrameStreamWriter::write_all(std::span<const std::uint8_t> bytes) {
  if (fd_ < 0) return Error::make(ErrorCode::kInvalidArgument, "frame stream " + path_ + ": writer is closed");
  // A reader that went away must be an error to return, not a SIGPIPE that ends the simulator: the
  // signal is blocked on this thread while writing and a SIGPIPE it raised is taken back.
  sigset_t pipe_set, old_set, pending;
  sigemptyset(&pipe_set);
  sigaddset(&pipe_set, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &pipe_set, &old_set);
  sigpending(&pending);
  const bool was_pending = sigismember(&pending, SIGPIPE) == 1;
  int err = 0;
  bool timed_out = false;
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      pollfd pf{fd_, POLLOUT, 0};
      int r;
      do r = ::poll(&pf, 1, 1000);
      while (r < 0 && errno == EINTR);
      if (r == 0) {
        timed_out = true;
        break;
      }
      if (r < 0) {
        err = errno;
        break;
      }
      continue;  // writable, or POLLERR/POLLHUP: the next write says which
    }
    err = n < 0 ? errno : EIO;
    break;
  }
  if (err == EPIPE && !was_pending) {
    const timespec zero{0, 0};
    (void)sigtimedwait(&pipe_set, nullptr, &zero);
  }
  pthread_sigmask(SIG_SETMASK, &old_set, nullptr);
  const std::uint64_t at = offset_ + done;
  offset_ = at;
  if (timed_out)
    return Error::make(ErrorCode::kTimeout, "frame stream " + path_ + ": the reader took nothing for 1 s (byte " + std::to_string(at) + ")");
  if (err != 0) {
    if (err == EPIPE) return Error::make(ErrorCode::kUnavailable, "frame stream " + path_ + ": the reader closed the FIFO (byte " + std::to_string(at) + ")");
    return io_error("frame stream " + path_ + ": write at byte " + std::to_string(at), err);
  }
  return ok_status();
}

// --- reader ---------------------------------------------------------------------------------------

// One whole record plus room to read ahead of it (a pipe delivers 64 KiB at a time).
constexpr std::size_t kReaderSlack = 64 * 1024;

FrameStreamReader::FrameStreamReader(int fd, std::string path, bool fifo)
    : fd_(fd), path_(std::move(path)), fifo_(fifo), buf_(std::make_unique_for_overwrite<std::uint8_t[]>(kMaxRecordSize + kReaderSlack)),
      cap_(kMaxRecordSize + kReaderSlack) {}

FrameStreamReader::~FrameStreamReader() {
  if (fd_ >= 0) ::close(fd_);
}

Result<std::unique_ptr<FrameStreamReader>> FrameStreamReader::open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return io_error("frame stream " + path + ": cannot open", errno);
  struct stat st {};
  if (::fstat(fd, &st) != 0 || (!S_ISFIFO(st.st_mode) && !S_ISREG(st.st_mode))) {
    ::close(fd);
    return Error::make(ErrorCode::kInvalidArgument, "frame stream " + path + ": neither a regular file nor a FIFO");
  }
  return std::unique_ptr<FrameStreamReader>(new FrameStreamReader(fd, path, S_ISFIFO(st.st_mode)));
}

void FrameStreamReader::skip_garbage(std::size_t n) noexcept {
  const std::size_t q = std::min(quiet_, n);
  quiet_ -= q;
  c_.garbage_bytes += n - q;
  begin_ += n;
}

void FrameStreamReader::fault(std::uint64_t& counter, const char* fmt, ...) noexcept {
  ++counter;
  const int k = std::snprintf(error_.data(), error_.size(), "frame stream %s: byte %llu: ", path_.c_str(),
                              static_cast<unsigned long long>(base_ + begin_));
  if (k > 0 && static_cast<std::size_t>(k) < error_.size()) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(error_.data() + k, error_.size() - static_cast<std::size_t>(k), fmt, ap);
    va_end(ap);
  }
}

void FrameStreamReader::resync(std::size_t claimed) noexcept {
  // Rescan from the byte after the record's first: a real record behind a false start is not lost.
  // The rest of what the dropped record claimed is not counted again as garbage.
  begin_ += 1;
  quiet_ = claimed > 0 ? claimed - 1 : 0;
}

FrameStreamReader::Parse FrameStreamReader::parse(CameraImageMsg& img, VoMsg& vo) noexcept {
  for (;;) {
    const std::size_t avail = end_ - begin_;
    if (skip_ > 0) {
      const std::size_t n = std::min(skip_, avail);
      begin_ += n;
      skip_ -= n;
      if (skip_ > 0) return Parse::kNeedMore;
      continue;
    }
    if (avail == 0) return Parse::kNeedMore;
    const std::uint8_t* p = buf_.get() + begin_;
    // Hunt for the magic: everything before a candidate that still matches is garbage.
    std::size_t i = 0;
    for (;;) {
      const void* a = std::memchr(p + i, kFrameStreamMagic[0], avail - i);
      if (a == nullptr) {
        i = avail;
        break;
      }
      i = static_cast<std::size_t>(static_cast<const std::uint8_t*>(a) - p);
      const std::size_t m = std::min<std::size_t>(4, avail - i);
      if (std::memcmp(p + i, kFrameStreamMagic.data(), m) == 0) break;
      ++i;
    }
    if (i > 0) {
      skip_garbage(i);
      continue;
    }
    if (avail < kRecordHeaderSize) return Parse::kNeedMore;
    const std::uint16_t version = get_u16(p + 4), type = get_u16(p + 6);
    const std::uint32_t len = get_u32(p + 8);
    const std::size_t claimed = std::min<std::size_t>(kRecordHeaderSize + std::size_t{len} + kRecordCrcSize, kMaxRecordSize);
    if (version != kFrameStreamVersion) {
      fault(c_.bad_records, "version %u (this reader takes %u)", version, kFrameStreamVersion);
      resync(claimed);
      continue;
    }
    if (type == static_cast<std::uint16_t>(RecordType::kImage)) {
      if (len < kImagePayloadHeaderSize) {
        fault(c_.bad_records, "image record of %u bytes", len);
        resync(kRecordHeaderSize);
        continue;
      }
      if (avail < kRecordHeaderSize + kImagePayloadHeaderSize) return Parse::kNeedMore;
      const std::uint32_t w = get_u16(p + kRecordHeaderSize + 12), h = get_u16(p + kRecordHeaderSize + 14);
      if (std::uint64_t{len} != kImagePayloadHeaderSize + std::uint64_t{w} * h * 4) {
        fault(c_.bad_records, "image record of %u bytes for %ux%u", len, w, h);
        resync(kRecordHeaderSize);
        continue;
      }
      if (w != static_cast<std::uint32_t>(kImageWidth) || h != static_cast<std::uint32_t>(kImageHeight)) {
        // A consistent header for another size (a recording made for another camera): skip it whole.
        fault(c_.bad_records, "image %ux%u, version 1 takes %dx%d", w, h, kImageWidth, kImageHeight);
        skip_ = kRecordHeaderSize + len + kRecordCrcSize;
        continue;
      }
    } else if (type == static_cast<std::uint16_t>(RecordType::kVo)) {
      if (len != kVoPayloadSize) {
        fault(c_.bad_records, "VO record of %u bytes (%zu expected)", len, kVoPayloadSize);
        resync(kRecordHeaderSize);
        continue;
      }
    } else {
      fault(c_.bad_records, "unknown record type %u", type);
      resync(claimed);
      continue;
    }
    const std::size_t total = kRecordHeaderSize + len + kRecordCrcSize;
    if (avail < total) return Parse::kNeedMore;
    const std::uint32_t want = get_u32(p + kRecordHeaderSize + len);
    const std::uint32_t got = crc32(std::span<const std::uint8_t>(p, kRecordHeaderSize + len));
    if (want != got) {
      fault(c_.crc_errors, "CRC-32 %08x, record says %08x", got, want);
      resync(total);
      continue;
    }
    const std::uint8_t* q = p + kRecordHeaderSize;
    if (type == static_cast<std::uint16_t>(RecordType::kImage)) {
      if (q[16] > static_cast<std::uint8_t>(LabelSource::kSegmentation)) {
        fault(c_.bad_records, "image labels %u unknown", q[16]);
        resync(total);
        continue;
      }
      img.stamp = static_cast<TimeNs>(get_u64(q));
      img.published = 0;
      img.seq = get_u32(q + 8);
      img.labels = static_cast<LabelSource>(q[16]);
      std::memcpy(img.rgb.data(), q + kImagePayloadHeaderSize, img.rgb.size());
      std::memcpy(img.cls.data(), q + kImagePayloadHeaderSize + img.rgb.size(), img.cls.size());
    } else {
      vo.stamp = static_cast<TimeNs>(get_u64(q));
      vo.published = 0;
      vo.segment = get_u32(q + 8);
      vo.tracking = q[12] != 0;
      vo.pose = Pose3{get_f64(q + 16), get_f64(q + 24), get_f64(q + 32), get_f64(q + 40), get_f64(q + 48), get_f64(q + 56)};
    }
    begin_ += total;
    quiet_ = 0;
    return type == static_cast<std::uint16_t>(RecordType::kImage) ? Parse::kImage : Parse::kVo;
  }
}

FrameStreamReader::ReadResult FrameStreamReader::next(CameraImageMsg& img, VoMsg& vo) noexcept {
  if (ended_) return ReadResult::kEnd;
  for (;;) {
    switch (parse(img, vo)) {
      case Parse::kImage: ++c_.images; return ReadResult::kImage;
      case Parse::kVo: ++c_.vo; return ReadResult::kVo;
      case Parse::kNeedMore: break;
    }
    // Room for a whole record after begin_ (the buffer holds one record plus the slack), so a read
    // always has space: parse() needs more only for a record that fits.
    if (begin_ == end_) {
      base_ += begin_;
      begin_ = end_ = 0;
    } else if (cap_ - begin_ < kMaxRecordSize) {
      std::memmove(buf_.get(), buf_.get() + begin_, end_ - begin_);
      base_ += begin_;
      end_ -= begin_;
      begin_ = 0;
    }
    const ssize_t n = ::read(fd_, buf_.get() + end_, cap_ - end_);
    if (n > 0) {
      seen_bytes_ = true;
      end_ += static_cast<std::size_t>(n);
      continue;
    }
    if (n == 0) {
      // A FIFO nobody has opened for writing yet also reads 0: that is not its end.
      if (fifo_ && !seen_bytes_) return ReadResult::kNone;
      if (end_ > begin_) {
        // The record at begin_ never finished: dropped, and what follows its first byte parsed again (a
        // whole record may hide behind it). A skipped record of another size was counted when skipped.
        fault(c_.bad_records, "truncated record: the stream ends %zu bytes into it", end_ - begin_);
        resync(end_ - begin_);
        continue;
      }
      ended_ = true;
      return ReadResult::kEnd;
    }
    if (errno == EINTR) continue;
    if (errno == EAGAIN) return ReadResult::kNone;
    ++c_.read_errors;
    std::snprintf(error_.data(), error_.size(), "frame stream %s: read at byte %llu: %s", path_.c_str(),
                  static_cast<unsigned long long>(base_ + end_), std::strerror(errno));
    ended_ = true;
    return ReadResult::kEnd;
  }
}

}  // namespace ag::camera
