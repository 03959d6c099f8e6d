// The store's journal: replay with torn-entry detection and resync, compacting rewrite, appends.
#include "airground/comms/journal.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "airground/comms/bytes.hpp"

namespace ag::comms {

namespace {

constexpr std::size_t kHeader = 12;

std::string errno_text() { return std::strerror(errno); }

Result<std::vector<std::uint8_t>> read_file(const std::string& path) {
  std::vector<std::uint8_t> data;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return data;
    return Error::make(ErrorCode::kIo, "journal " + path + ": cannot open: " + errno_text());
  }
  std::uint8_t chunk[65536];
  for (;;) {
    const ssize_t n = ::read(fd, chunk, sizeof chunk);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string e = errno_text();
      ::close(fd);
      return Error::make(ErrorCode::kIo, "journal " + path + ": read failed: " + e);
    }
    if (n == 0) break;
    data.insert(data.end(), chunk, chunk + n);
  }
  ::close(fd);
  return data;
}

bool write_fd(int fd, const std::uint8_t* p, std::size_t n) noexcept {
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    p += w;
    n -= static_cast<std::size_t>(w);
  }
  return true;
}

std::size_t finish_entry(std::span<std::uint8_t> out, std::size_t body) noexcept {
  ByteWriter h(out.first(kHeader));
  h.u32(Journal::kMagic);
  h.u32(static_cast<std::uint32_t>(body));
  h.u32(crc32c(out.subspan(kHeader, body)));
  return kHeader + body;
}

std::size_t encode_epoch(std::uint32_t epoch, std::span<std::uint8_t> out) noexcept {
  ByteWriter w(out.subspan(kHeader));
  w.u8(Journal::kEpochEntry);
  w.u32(epoch);
  return finish_entry(out, w.size());
}

}  // namespace

std::size_t Journal::encode_record(const RecordMeta& meta, std::span<const std::uint8_t> payload,
                                   std::span<std::uint8_t> out) noexcept {
  if (out.size() < entry_size(payload.size())) return 0;
  ByteWriter w(out.subspan(kHeader));
  w.u8(kRecordEntry);
  w.u8(meta.key.origin);
  w.u32(meta.key.topic);
  w.u64(meta.seq);
  w.u8(meta.priority);
  w.i64(meta.stamp);
  w.bytes(payload);
  return finish_entry(out, w.size());
}

Journal::Journal(std::string path, int fd, std::uint32_t epoch, std::size_t max_payload)
    : path_(std::move(path)), fd_(fd), epoch_(epoch), buf_(entry_size(max_payload)) {}

Journal::~Journal() {
  if (fd_ >= 0) ::close(fd_);
}

Result<std::unique_ptr<Journal>> Journal::open(const std::string& path, RecordStore& store, std::uint32_t min_epoch,
                                               JournalReport& report) {
  report = JournalReport{};
  auto data_r = read_file(path);
  if (!data_r) return data_r.error();
  const std::vector<std::uint8_t>& data = data_r.value();
  report.bytes = data.size();
  const std::size_t max_body = 64 + store.limits().max_payload_bytes;

  std::size_t pos = 0;
  std::size_t bad_start = 0;
  bool in_bad = false;
  std::string bad_reason;
  auto close_bad = [&](std::size_t end) {
    if (!in_bad) return;
    in_bad = false;
    ++report.bad_regions;
    report.bad_bytes += end - bad_start;
    report.problems += "journal " + path + ": " + bad_reason + " at byte " + std::to_string(bad_start) + " of " +
                       std::to_string(data.size()) + ": skipped " + std::to_string(end - bad_start) + " bytes" +
                       (end == data.size() ? " (torn tail)" : ", resynchronised on the next valid entry") + "\n";
  };
  while (pos < data.size()) {
    const char* why = nullptr;
    std::size_t body_len = 0;
    if (data.size() - pos < kHeader) {
      why = "truncated entry header";
    } else {
      ByteReader h(std::span<const std::uint8_t>(data).subspan(pos, kHeader));
      std::uint32_t magic = 0, len = 0, crc = 0;
      h.u32(magic);
      h.u32(len);
      h.u32(crc);
      body_len = len;
      if (magic != kMagic) why = "bad entry magic";
      else if (len < 5 || len > max_body) why = "entry length out of range";
      else if (data.size() - pos - kHeader < len) why = "truncated entry";
      else if (crc32c(std::span<const std::uint8_t>(data).subspan(pos + kHeader, len)) != crc) why = "CRC mismatch";
    }
    if (why != nullptr) {
      if (!in_bad) {
        in_bad = true;
        bad_start = pos;
        bad_reason = why;
      }
      ++pos;  // resync byte by byte on the next magic whose entry checks out
      continue;
    }
    close_bad(pos);
    ByteReader b(std::span<const std::uint8_t>(data).subspan(pos + kHeader, body_len));
    std::uint8_t kind = 0;
    b.u8(kind);
    if (kind == kEpochEntry) {
      std::uint32_t e = 0;
      if (b.u32(e)) report.previous_epoch = std::max(report.previous_epoch, e);
    } else if (kind == kRecordEntry) {
      RecordMeta m;
      b.u8(m.key.origin);
      b.u32(m.key.topic);
      b.u64(m.seq);
      b.u8(m.priority);
      b.i64(m.stamp);
      const auto payload = b.bytes(b.remaining());
      if (b.ok() && m.key.origin != kNoRobot) (void)store.put(m, payload);
    }
    ++report.entries;
    pos += kHeader + body_len;
  }
  close_bad(data.size());
  report.records_loaded = store.size();

  const std::uint32_t epoch = std::max(report.previous_epoch + 1, min_epoch);
  // Rewrite: the live records and the new epoch into a temporary file, fsync, rename over the journal.
  const std::string tmp = path + ".tmp";
  const int tfd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (tfd < 0) return Error::make(ErrorCode::kIo, "journal " + tmp + ": cannot create: " + errno_text());
  std::vector<std::uint8_t> buf(entry_size(store.limits().max_payload_bytes));
  bool ok = true;
  for (RecordStore::Slot s = 0; s < store.size() && ok; ++s) {
    const std::size_t n = encode_record(store.meta(s), store.payload(s), buf);
    ok = write_fd(tfd, buf.data(), n);
  }
  if (ok) ok = write_fd(tfd, buf.data(), encode_epoch(epoch, buf));
  if (ok) ok = ::fsync(tfd) == 0;
  const std::string werr = errno_text();
  ::close(tfd);
  if (!ok) {
    ::unlink(tmp.c_str());
    return Error::make(ErrorCode::kIo, "journal " + tmp + ": write failed: " + werr);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0)
    return Error::make(ErrorCode::kIo, "journal " + path + ": rename from " + tmp + " failed: " + errno_text());
  // The rename itself must reach the disk: fsync the directory.
  const std::size_t slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    (void)::fsync(dfd);
    ::close(dfd);
  }
  const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (fd < 0) return Error::make(ErrorCode::kIo, "journal " + path + ": cannot reopen for append: " + errno_text());
  return std::unique_ptr<Journal>(new Journal(path, fd, epoch, store.limits().max_payload_bytes));
}

bool Journal::write_all(std::span<const std::uint8_t> bytes) noexcept {
  if (write_fd(fd_, bytes.data(), bytes.size())) return true;
  ++write_errors_;
  return false;
}

bool Journal::append(const RecordMeta& meta, std::span<const std::uint8_t> payload) noexcept {
  const std::size_t n = encode_record(meta, payload, buf_);
  if (n == 0) {
    ++write_errors_;
    return false;
  }
  const bool ok = write_all(std::span<const std::uint8_t>(buf_).first(n));
  if (ok) ++appended_;
  return ok;
}

bool Journal::sync() noexcept { return ::fdatasync(fd_) == 0; }

std::uint32_t crc32c(std::span<const std::uint8_t> data, std::uint32_t crc) noexcept {
  static constexpr auto kTable = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1u) ? (c >> 1) ^ 0x82F63B78u : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (const std::uint8_t b : data) crc = kTable[(crc ^ b) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

}  // namespace ag::comms
