// The quadrotor's recording: its zstd record stream, the final raster beside it, and the tap that writes it.
#include "uav_recording.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>
#include <zstd.h>

#include <cerrno>

#include <cinttypes>
#include <cstring>
#include <string>
#include <type_traits>

#include "airground/messages/channels.hpp"
#include "airground/platform/log.hpp"

namespace ag::sim {

namespace {

constexpr char kMagic[8] = {'A', 'G', 'U', 'A', 'V', 'R', 'P', '1'};
constexpr std::uint32_t kFormat = 1;
constexpr std::size_t kChunk = 1 << 20;  // bytes buffered before a zstd flush
constexpr int kZstdLevel = 3;

static_assert(std::is_trivially_copyable_v<MapTileMsg> && std::is_trivially_copyable_v<mission::RegionsMsg>,
              "the recording stores these messages as they lie in memory");

struct Header {
  char magic[8];
  std::uint32_t format;
  std::uint32_t tile_bytes, gossip_bytes, regions_bytes;
  std::uint64_t key;
};

// The gossip message up to its payload; the payload follows with `size` bytes.
constexpr std::size_t kGossipHead = offsetof(comms::GossipPublishMsg, payload);

std::string hex(std::uint64_t key) {
  char b[17];
  std::snprintf(b, sizeof b, "%016" PRIx64, key);
  return b;
}

}  // namespace

std::filesystem::path uav_recording_path(const std::filesystem::path& cache_dir, std::uint64_t key) {
  return cache_dir / ("uav-" + hex(key) + ".agur");
}

// ------------------------------------------------------------------------------------------- writer

Result<std::unique_ptr<UavRecordWriter>> UavRecordWriter::create(const std::filesystem::path& final_path, std::uint64_t key) {
  std::unique_ptr<UavRecordWriter> w(new UavRecordWriter());
  w->final_ = final_path;
  w->part_ = final_path;
  w->part_ += ".part";
  std::error_code ec;
  std::filesystem::create_directories(final_path.parent_path(), ec);
  std::filesystem::path lock = final_path;
  lock += ".lock";
  w->lock_fd_ = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (w->lock_fd_ < 0) return Error::make(ErrorCode::kIo, "cannot open " + lock.string() + ": " + std::strerror(errno));
  if (::flock(w->lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    if (errno == EWOULDBLOCK) return Error::make(ErrorCode::kUnavailable, "another process is recording " + final_path.string());
    return Error::make(ErrorCode::kIo, "cannot lock " + lock.string() + ": " + std::strerror(errno));
  }
  w->f_ = std::fopen(w->part_.c_str(), "wb");
  if (w->f_ == nullptr) return Error::make(ErrorCode::kIo, "cannot write the quadrotor recording " + w->part_.string() + ": " + std::strerror(errno));
  w->z_ = ZSTD_createCCtx();
  (void)ZSTD_CCtx_setParameter(w->z_, ZSTD_c_compressionLevel, kZstdLevel);
  w->in_.reserve(kChunk + sizeof(MapTileMsg) + 64);
  w->out_.resize(ZSTD_CStreamOutSize());
  Header h{};
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.format = kFormat;
  h.tile_bytes = sizeof(MapTileMsg);
  h.gossip_bytes = sizeof(comms::GossipPublishMsg);
  h.regions_bytes = sizeof(mission::RegionsMsg);
  h.key = key;
  w->put(&h, sizeof h);
  return w;
}

UavRecordWriter::~UavRecordWriter() {
  if (z_ != nullptr) ZSTD_freeCCtx(z_);
  if (f_ != nullptr) {
    std::fclose(f_);
    std::error_code ec;
    std::filesystem::remove(part_, ec);
  }
  if (lock_fd_ >= 0) ::close(lock_fd_);  // releases the flock
}

void UavRecordWriter::put(const void* p, std::size_t n) {
  const auto* b = static_cast<const std::uint8_t*>(p);
  in_.insert(in_.end(), b, b + n);
  if (in_.size() >= kChunk) flush(false);
}

void UavRecordWriter::flush(bool end) {
  ZSTD_inBuffer in{in_.data(), in_.size(), 0};
  for (;;) {
    ZSTD_outBuffer out{out_.data(), out_.size(), 0};
    const std::size_t left = ZSTD_compressStream2(z_, &out, &in, end ? ZSTD_e_end : ZSTD_e_continue);
    if (ZSTD_isError(left)) {
      failed_ = true;
      break;
    }
    if (out.pos > 0 && std::fwrite(out_.data(), 1, out.pos, f_) != out.pos) failed_ = true;
    if (end ? left == 0 : in.pos == in.size) break;
  }
  in_.clear();
}

void UavRecordWriter::record(UavRecordKind kind, TimeNs t) {
  const auto k = static_cast<std::uint8_t>(kind);
  put(&k, 1);
  put(&t, sizeof t);
  ++records_;
  if (kind == UavRecordKind::kTile || kind == UavRecordKind::kGossip) last_output_ = t;
}

void UavRecordWriter::tile(TimeNs t, const MapTileMsg& m) {
  record(UavRecordKind::kTile, t);
  put(&m, sizeof m);
}

void UavRecordWriter::gossip(TimeNs t, const comms::GossipPublishMsg& m) {
  record(UavRecordKind::kGossip, t);
  put(&m, kGossipHead);
  put(m.payload.data(), std::min<std::size_t>(m.size, m.payload.size()));
}

void UavRecordWriter::regions(TimeNs t, const mission::RegionsMsg& m) {
  record(UavRecordKind::kRegions, t);
  put(&m, sizeof m);
}

Status UavRecordWriter::finish(TimeNs end, const mapping::MapRaster& r) {
  record(UavRecordKind::kEnd, end);
  put(&last_output_, sizeof last_output_);
  flush(true);
  const bool closed = std::fclose(f_) == 0;
  f_ = nullptr;
  if (failed_ || !closed) return Error::make(ErrorCode::kIo, "writing the quadrotor recording " + part_.string() + " failed");
  // The raster: its grid, then the four layers.
  std::vector<std::uint8_t> raw;
  auto add = [&raw](const void* p, std::size_t n) {
    const auto* b = static_cast<const std::uint8_t*>(p);
    raw.insert(raw.end(), b, b + n);
  };
  add(&r.grid, sizeof r.grid);
  const std::uint64_t cells = r.cls.size();
  add(&cells, sizeof cells);
  add(r.cls.data(), r.cls.size());
  add(r.elevation.data(), r.elevation.size() * sizeof(float));
  add(r.rgb.data(), r.rgb.size());
  add(r.count.data(), r.count.size() * sizeof(std::uint32_t));
  std::vector<std::uint8_t> packed(ZSTD_compressBound(raw.size()));
  const std::size_t n = ZSTD_compress(packed.data(), packed.size(), raw.data(), raw.size(), kZstdLevel);
  std::filesystem::path map = final_;
  map += ".map";
  std::FILE* f = std::fopen(map.c_str(), "wb");
  const bool ok = !ZSTD_isError(n) && f != nullptr && std::fwrite(packed.data(), 1, n, f) == n;
  if (f != nullptr && std::fclose(f) != 0) return Error::make(ErrorCode::kIo, "writing " + map.string() + " failed");
  if (!ok) return Error::make(ErrorCode::kIo, "writing " + map.string() + " failed");
  std::error_code ec;
  std::filesystem::rename(part_, final_, ec);  // last: a recording without its map never appears
  if (ec) return Error::make(ErrorCode::kIo, "cannot rename " + part_.string() + ": " + ec.message());
  return ok_status();
}

// ------------------------------------------------------------------------------------------- reader

Result<std::unique_ptr<UavRecordReader>> UavRecordReader::open(const std::filesystem::path& path, std::uint64_t key) {
  // Read it through once first: a truncated or corrupt recording is refused before the run, not in it.
  auto check = open_once(path, key);
  if (!check) return check.error();
  UavRecordReader& c = *check.value();
  auto tile = std::make_unique<MapTileMsg>();
  auto gossip = std::make_unique<comms::GossipPublishMsg>();
  auto regions = std::make_unique<mission::RegionsMsg>();
  while (c.kind() != UavRecordKind::kEnd) {
    const bool ok = c.kind() == UavRecordKind::kTile ? c.take_tile(*tile) : c.kind() == UavRecordKind::kGossip ? c.take_gossip(*gossip) : c.take_regions(*regions);
    if (!ok) break;
  }
  if (!c.error().empty()) return Error::make(ErrorCode::kMalformed, c.error() + "; delete it to record it again");
  std::filesystem::path map = path;
  map += ".map";
  std::error_code ec;
  if (!std::filesystem::exists(map, ec)) return Error::make(ErrorCode::kIo, map.string() + " is missing (the recording's final map); delete " + path.string() + " to record it again");
  return open_once(path, key);
}

Result<std::unique_ptr<UavRecordReader>> UavRecordReader::open_once(const std::filesystem::path& path, std::uint64_t key) {
  std::unique_ptr<UavRecordReader> r(new UavRecordReader());
  r->path_ = path;
  r->f_ = std::fopen(path.c_str(), "rb");
  if (r->f_ == nullptr) return Error::make(ErrorCode::kIo, "cannot read the quadrotor recording " + path.string() + ": " + std::strerror(errno));
  r->z_ = ZSTD_createDCtx();
  r->in_.resize(ZSTD_DStreamInSize());
  r->out_.resize(ZSTD_DStreamOutSize());
  Header h{};
  if (!r->get(&h, sizeof h) || std::memcmp(h.magic, kMagic, sizeof kMagic) != 0 || h.format != kFormat)
    return Error::make(ErrorCode::kMalformed, path.string() + ": not a quadrotor recording of this format");
  if (h.tile_bytes != sizeof(MapTileMsg) || h.gossip_bytes != sizeof(comms::GossipPublishMsg) || h.regions_bytes != sizeof(mission::RegionsMsg))
    return Error::make(ErrorCode::kMalformed, path.string() + ": recorded by a build with other message layouts");
  if (h.key != key)
    return Error::make(ErrorCode::kInvalidArgument, path.string() + ": recorded for key " + hex(h.key) + ", this run's is " + hex(key));
  r->advance();
  if (!r->error_.empty()) return Error::make(ErrorCode::kMalformed, r->error_);
  return r;
}

UavRecordReader::~UavRecordReader() {
  if (z_ != nullptr) ZSTD_freeDCtx(z_);
  if (f_ != nullptr) std::fclose(f_);
}

bool UavRecordReader::get(void* p, std::size_t n) noexcept {
  auto* dst = static_cast<std::uint8_t*>(p);
  while (n > 0) {
    if (out_pos_ == out_end_) {
      // Decompress more: feed input until some output appears.
      for (;;) {
        if (in_pos_ == in_end_) {
          in_end_ = std::fread(in_.data(), 1, in_.size(), f_);
          in_pos_ = 0;
          if (in_end_ == 0) return false;
        }
        ZSTD_inBuffer in{in_.data(), in_end_, in_pos_};
        ZSTD_outBuffer out{out_.data(), out_.size(), 0};
        const std::size_t rc = ZSTD_decompressStream(z_, &out, &in);
        in_pos_ = in.pos;
        if (ZSTD_isError(rc)) return false;
        out_pos_ = 0;
        out_end_ = out.pos;
        if (out_end_ > 0) break;
      }
    }
    const std::size_t k = std::min(n, out_end_ - out_pos_);
    std::memcpy(dst, out_.data() + out_pos_, k);
    out_pos_ += k;
    dst += k;
    n -= k;
  }
  return true;
}

void UavRecordReader::advance() noexcept {
  std::uint8_t k = 0;
  if (!get(&k, 1) || !get(&time_, sizeof time_) || k < 1 || k > 4) {
    error_ = path_.string() + ": truncated or corrupt (no end record)";
    kind_ = UavRecordKind::kEnd;
    return;
  }
  kind_ = static_cast<UavRecordKind>(k);
  if (kind_ == UavRecordKind::kEnd && !get(&last_output_, sizeof last_output_)) error_ = path_.string() + ": truncated end record";
}

bool UavRecordReader::body(void* p, std::size_t n) noexcept {
  if (get(p, n)) return true;
  error_ = path_.string() + ": truncated or corrupt (a record is cut short at " + std::to_string(to_seconds(time_)) + " s)";
  kind_ = UavRecordKind::kEnd;
  return false;
}

bool UavRecordReader::take_tile(MapTileMsg& m) noexcept {
  if (kind_ != UavRecordKind::kTile || !body(&m, sizeof m)) return false;
  advance();
  return error_.empty();
}

bool UavRecordReader::take_gossip(comms::GossipPublishMsg& m) noexcept {
  if (kind_ != UavRecordKind::kGossip || !body(&m, kGossipHead)) return false;
  if (m.size > m.payload.size()) {
    error_ = path_.string() + ": corrupt (a gossip record longer than its message)";
    kind_ = UavRecordKind::kEnd;
    return false;
  }
  if (!body(m.payload.data(), m.size)) return false;
  advance();
  return error_.empty();
}

bool UavRecordReader::take_regions(mission::RegionsMsg& m) noexcept {
  if (kind_ != UavRecordKind::kRegions || !body(&m, sizeof m)) return false;
  advance();
  return error_.empty();
}

Result<mapping::MapRaster> UavRecordReader::raster() const {
  std::filesystem::path map = path_;
  map += ".map";
  std::FILE* f = std::fopen(map.c_str(), "rb");
  if (f == nullptr) return Error::make(ErrorCode::kIo, "cannot read " + map.string() + ": " + std::strerror(errno));
  std::vector<std::uint8_t> packed;
  std::uint8_t buf[1 << 16];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) packed.insert(packed.end(), buf, buf + n);
  std::fclose(f);
  const unsigned long long size = ZSTD_getFrameContentSize(packed.data(), packed.size());
  if (size == ZSTD_CONTENTSIZE_ERROR || size == ZSTD_CONTENTSIZE_UNKNOWN) return Error::make(ErrorCode::kMalformed, map.string() + ": not a zstd frame");
  std::vector<std::uint8_t> raw(size);
  const std::size_t n = ZSTD_decompress(raw.data(), raw.size(), packed.data(), packed.size());
  mapping::MapRaster r;
  std::uint64_t cells = 0;
  constexpr std::size_t kHead = sizeof(GridGeometry) + sizeof(std::uint64_t);
  if (ZSTD_isError(n) || n < kHead) return Error::make(ErrorCode::kMalformed, map.string() + ": corrupt");
  std::memcpy(&r.grid, raw.data(), sizeof r.grid);
  std::memcpy(&cells, raw.data() + sizeof r.grid, sizeof cells);
  if (n != kHead + cells * (1 + 4 + 3 + 4)) return Error::make(ErrorCode::kMalformed, map.string() + ": truncated");
  const std::uint8_t* p = raw.data() + kHead;
  r.cls.assign(p, p + cells);
  p += cells;
  r.elevation.resize(cells);
  std::memcpy(r.elevation.data(), p, cells * 4);
  p += cells * 4;
  r.rgb.assign(p, p + cells * 3);
  p += cells * 3;
  r.count.resize(cells);
  std::memcpy(r.count.data(), p, cells * 4);
  return r;
}

// ---------------------------------------------------------------------------------------------- tap

Status UavTapStage::init(StageContext& ctx) {
  auto t = ctx.channels.ring_tap<MapTileMsg, kMapTileRing>(chan::kMapTiles.name);
  if (!t) return t.error();
  tiles_ = t.value();
  auto g = ctx.channels.ring_tap<comms::GossipPublishMsg, comms::kGossipRing>(chan::kGossipOut.name);
  if (!g) return g.error();
  gossip_ = g.value();
  return ok_status();
}

void UavTapStage::step(TimeNs now) noexcept {
  if (writer == nullptr) return;
  for (const MapTileMsg* m = tiles_.front(); m != nullptr; m = tiles_.front()) {
    writer->tile(now, *m);
    tiles_.pop();
  }
  for (const comms::GossipPublishMsg* m = gossip_.front(); m != nullptr; m = gossip_.front()) {
    writer->gossip(now, *m);
    gossip_.pop();
  }
  if (regions != nullptr && regions->published().version != regions_version_) {
    regions_version_ = regions->published().version;
    writer->regions(now, regions->published());
  }
}

}  // namespace ag::sim
