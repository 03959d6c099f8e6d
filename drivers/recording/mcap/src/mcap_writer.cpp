// MCAP writer: records are built little-endian in memory, chunks compressed with libzstd, and the file
// is written sequentially (no seeking back), so a robot can stream to it.
#include "airground/drivers/recording/mcap/mcap_writer.hpp"

#include <zstd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>

namespace ag::mcap {
namespace {

constexpr std::array<std::uint8_t, 8> kMagic{0x89, 'M', 'C', 'A', 'P', 0x30, '\r', '\n'};

enum Op : std::uint8_t {
  kHeader = 0x01, kFooter = 0x02, kSchema = 0x03, kChannel = 0x04, kMessage = 0x05, kChunk = 0x06,
  kMessageIndex = 0x07, kChunkIndex = 0x08, kStatistics = 0x0B, kMetadata = 0x0C, kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E, kDataEnd = 0x0F,
};

constexpr std::array<std::uint32_t, 256> make_crc_table() {
  std::array<std::uint32_t, 256> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? (0xEDB88320u ^ (c >> 1)) : (c >> 1);
    t[i] = c;
  }
  return t;
}
constexpr std::array<std::uint32_t, 256> kCrcTable = make_crc_table();

// Little-endian record content.
struct Bytes {
  std::vector<std::uint8_t> b;
  void u8(std::uint8_t v) { b.push_back(v); }
  void u16(std::uint16_t v) { le(v, 2); }
  void u32(std::uint32_t v) { le(v, 4); }
  void u64(std::uint64_t v) { le(v, 8); }
  void le(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void raw(std::span<const std::uint8_t> s) { b.insert(b.end(), s.begin(), s.end()); }
  void raw(std::string_view s) { b.insert(b.end(), s.begin(), s.end()); }
  void str(std::string_view s) {
    u32(static_cast<std::uint32_t>(s.size()));
    raw(s);
  }
  void string_map(const std::vector<std::pair<std::string, std::string>>& m) {
    std::uint32_t len = 0;
    for (const auto& [k, v] : m) len += static_cast<std::uint32_t>(8 + k.size() + v.size());
    u32(len);
    for (const auto& [k, v] : m) {
      str(k);
      str(v);
    }
  }
};

// opcode, content length, content.
std::vector<std::uint8_t> record(std::uint8_t op, const Bytes& content) {
  Bytes r;
  r.u8(op);
  r.u64(content.b.size());
  r.raw(content.b);
  return std::move(r.b);
}

}  // namespace

std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc) noexcept {
  std::uint32_t c = ~crc;
  for (std::uint8_t v : bytes) c = kCrcTable[(c ^ v) & 0xFFu] ^ (c >> 8);
  return ~c;
}

std::string base64(std::span<const std::uint8_t> in) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= in.size(); i += 3) {
    const std::uint32_t v = (std::uint32_t{in[i]} << 16) | (std::uint32_t{in[i + 1]} << 8) | in[i + 2];
    out += kAlphabet[(v >> 18) & 63u];
    out += kAlphabet[(v >> 12) & 63u];
    out += kAlphabet[(v >> 6) & 63u];
    out += kAlphabet[v & 63u];
  }
  if (i < in.size()) {
    const bool two = i + 1 < in.size();
    const std::uint32_t v = (std::uint32_t{in[i]} << 16) | (two ? std::uint32_t{in[i + 1]} << 8 : 0u);
    out += kAlphabet[(v >> 18) & 63u];
    out += kAlphabet[(v >> 12) & 63u];
    out += two ? kAlphabet[(v >> 6) & 63u] : '=';
    out += '=';
  }
  return out;
}

McapWriter::~McapWriter() {
  if (file_) (void)close();
}

Status McapWriter::fail(std::string what) {
  failed_ = true;
  return Error::make(ErrorCode::kIo, "mcap: " + path_ + ": " + std::move(what));
}

Status McapWriter::put(std::span<const std::uint8_t> bytes) {
  if (!file_) return Error::make(ErrorCode::kInvalidArgument, "mcap: write to a file that is not open");
  if (failed_) return Error::make(ErrorCode::kIo, "mcap: " + path_ + ": an earlier write failed");
  if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size()) return fail(std::string("write: ") + std::strerror(errno));
  data_crc_ = crc32(bytes, data_crc_);
  offset_ += bytes.size();
  return ok_status();
}

Status McapWriter::open(const std::string& path, const WriterOptions& options) {
  if (file_) return Error::make(ErrorCode::kInvalidArgument, "mcap: " + path_ + " is already open");
  path_ = path;
  options_ = options;
  file_ = std::fopen(path.c_str(), "wb");
  if (!file_) return Error::make(ErrorCode::kIo, "mcap: cannot create " + path + ": " + std::strerror(errno));
  offset_ = 0;
  data_crc_ = 0;
  failed_ = false;
  schemas_.clear();
  channels_.clear();
  chunk_.clear();
  chunk_index_.clear();
  chunk_indexes_.clear();
  metadata_indexes_.clear();
  stats_ = {};
  start_time_ = end_time_ = 0;
  if (Status s = put(kMagic); !s) return s;
  Bytes h;
  h.str(options.profile);
  h.str(options.library);
  return put(record(kHeader, h));
}

std::uint16_t McapWriter::add_schema(std::string_view name, std::string_view encoding, std::string_view data) {
  if (!file_ || schemas_.size() >= 0xFFFEu) return 0;
  const auto id = static_cast<std::uint16_t>(schemas_.size() + 1);
  schemas_.push_back(Schema{id, std::string(name), std::string(encoding), std::string(data)});
  Bytes c;
  c.u16(id);
  c.str(name);
  c.str(encoding);
  c.str(data);  // uint32 length-prefixed bytes
  return put(record(kSchema, c)) ? id : std::uint16_t{0};
}

std::uint16_t McapWriter::add_channel(std::uint16_t schema_id, std::string_view topic, std::string_view message_encoding,
                                      const std::vector<std::pair<std::string, std::string>>& metadata) {
  if (!file_ || channels_.size() >= 0xFFFFu || schema_id > schemas_.size()) return 0xFFFF;
  const auto id = static_cast<std::uint16_t>(channels_.size());
  channels_.push_back(Channel{id, schema_id, std::string(topic), std::string(message_encoding), metadata, 0});
  Bytes c;
  c.u16(id);
  c.u16(schema_id);
  c.str(topic);
  c.str(message_encoding);
  c.string_map(metadata);
  return put(record(kChannel, c)) ? id : std::uint16_t{0xFFFF};
}

Status McapWriter::write(std::uint16_t channel_id, std::uint64_t log_time_ns, std::uint64_t publish_time_ns,
                         std::span<const std::uint8_t> data) {
  if (!file_) return Error::make(ErrorCode::kInvalidArgument, "mcap: write to a file that is not open");
  if (channel_id >= channels_.size())
    return Error::make(ErrorCode::kInvalidArgument, "mcap: " + path_ + ": channel " + std::to_string(channel_id) + " was not added");
  Channel& ch = channels_[channel_id];
  if (chunk_index_.empty()) chunk_start_ = chunk_end_ = log_time_ns;
  chunk_start_ = std::min(chunk_start_, log_time_ns);
  chunk_end_ = std::max(chunk_end_, log_time_ns);
  if (stats_.messages == 0) start_time_ = end_time_ = log_time_ns;
  start_time_ = std::min(start_time_, log_time_ns);
  end_time_ = std::max(end_time_, log_time_ns);
  chunk_index_[channel_id].emplace_back(log_time_ns, chunk_.size());
  Bytes m;
  m.u8(kMessage);
  m.u64(2 + 4 + 8 + 8 + data.size());
  m.u16(channel_id);
  m.u32(++ch.sequence);
  m.u64(log_time_ns);
  m.u64(publish_time_ns);
  chunk_.insert(chunk_.end(), m.b.begin(), m.b.end());
  chunk_.insert(chunk_.end(), data.begin(), data.end());
  ++stats_.messages;
  ++stats_.channel_messages[channel_id];
  if (chunk_.size() >= options_.chunk_size_bytes) return flush_chunk();
  return ok_status();
}

Status McapWriter::flush_chunk() {
  if (chunk_index_.empty()) return ok_status();
  std::vector<std::uint8_t> packed;
  std::string_view compression;
  if (options_.zstd_level > 0) {
    packed.resize(ZSTD_compressBound(chunk_.size()));
    const std::size_t n = ZSTD_compress(packed.data(), packed.size(), chunk_.data(), chunk_.size(), options_.zstd_level);
    if (ZSTD_isError(n)) return fail(std::string("zstd: ") + ZSTD_getErrorName(n));
    packed.resize(n);
    compression = "zstd";
  } else {
    packed = chunk_;
  }
  Bytes c;
  c.u64(chunk_start_);
  c.u64(chunk_end_);
  c.u64(chunk_.size());
  c.u32(crc32(chunk_));
  c.str(compression);
  c.u64(packed.size());
  c.raw(packed);
  ChunkIndex ci{chunk_start_, chunk_end_, offset_, 0, {}, 0, packed.size(), chunk_.size()};
  const std::vector<std::uint8_t> rec = record(kChunk, c);
  ci.chunk_length = rec.size();
  if (Status s = put(rec); !s) return s;
  const std::uint64_t index_start = offset_;
  for (auto& [channel, entries] : chunk_index_) {
    std::stable_sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    Bytes mi;
    mi.u16(channel);
    mi.u32(static_cast<std::uint32_t>(entries.size() * 16));
    for (const auto& [t, off] : entries) {
      mi.u64(t);
      mi.u64(off);
    }
    ci.index_offsets.emplace_back(channel, offset_);
    if (Status s = put(record(kMessageIndex, mi)); !s) return s;
  }
  ci.index_length = offset_ - index_start;
  chunk_indexes_.push_back(std::move(ci));
  ++stats_.chunks;
  chunk_.clear();
  chunk_index_.clear();
  return ok_status();
}

Status McapWriter::add_metadata(std::string_view name, const std::vector<std::pair<std::string, std::string>>& values) {
  if (!file_) return Error::make(ErrorCode::kInvalidArgument, "mcap: metadata for a file that is not open");
  Bytes c;
  c.str(name);
  c.string_map(values);
  const std::vector<std::uint8_t> rec = record(kMetadata, c);
  metadata_indexes_.push_back(MetadataIndex{offset_, rec.size(), std::string(name)});
  return put(rec);
}

Status McapWriter::close() {
  if (!file_) return Error::make(ErrorCode::kInvalidArgument, "mcap: close of a file that is not open");
  Status st = flush_chunk();
  if (st) {
    Bytes de;
    de.u32(data_crc_);
    st = put(record(kDataEnd, de));
  }
  const std::uint64_t summary_start = offset_;
  data_crc_ = 0;  // from here the running CRC is the summary's
  struct Group {
    std::uint8_t op;
    std::uint64_t start, length;
  };
  std::vector<Group> groups;
  auto group = [&](std::uint8_t op, const std::vector<std::vector<std::uint8_t>>& recs) {
    if (recs.empty() || !st) return;
    const std::uint64_t start = offset_;
    for (const auto& r : recs)
      if (st) st = put(r);
    groups.push_back(Group{op, start, offset_ - start});
  };
  std::vector<std::vector<std::uint8_t>> recs;
  for (const Schema& s : schemas_) {
    Bytes c;
    c.u16(s.id);
    c.str(s.name);
    c.str(s.encoding);
    c.str(s.data);
    recs.push_back(record(kSchema, c));
  }
  group(kSchema, recs);
  recs.clear();
  for (const Channel& ch : channels_) {
    Bytes c;
    c.u16(ch.id);
    c.u16(ch.schema_id);
    c.str(ch.topic);
    c.str(ch.encoding);
    c.string_map(ch.metadata);
    recs.push_back(record(kChannel, c));
  }
  group(kChannel, recs);
  recs.clear();
  {
    Bytes c;
    c.u64(stats_.messages);
    c.u16(static_cast<std::uint16_t>(schemas_.size()));
    c.u32(static_cast<std::uint32_t>(channels_.size()));
    c.u32(0);  // attachments
    c.u32(static_cast<std::uint32_t>(metadata_indexes_.size()));
    c.u32(static_cast<std::uint32_t>(chunk_indexes_.size()));
    c.u64(start_time_);
    c.u64(end_time_);
    c.u32(static_cast<std::uint32_t>(stats_.channel_messages.size() * 10));
    for (const auto& [id, n] : stats_.channel_messages) {
      c.u16(id);
      c.u64(n);
    }
    recs.push_back(record(kStatistics, c));
  }
  group(kStatistics, recs);
  recs.clear();
  for (const ChunkIndex& ci : chunk_indexes_) {
    Bytes c;
    c.u64(ci.start_time);
    c.u64(ci.end_time);
    c.u64(ci.chunk_offset);
    c.u64(ci.chunk_length);
    c.u32(static_cast<std::uint32_t>(ci.index_offsets.size() * 10));
    for (const auto& [id, off] : ci.index_offsets) {
      c.u16(id);
      c.u64(off);
    }
    c.u64(ci.index_length);
    c.str(options_.zstd_level > 0 ? "zstd" : "");
    c.u64(ci.compressed_size);
    c.u64(ci.uncompressed_size);
    recs.push_back(record(kChunkIndex, c));
  }
  group(kChunkIndex, recs);
  recs.clear();
  for (const MetadataIndex& mi : metadata_indexes_) {
    Bytes c;
    c.u64(mi.offset);
    c.u64(mi.length);
    c.str(mi.name);
    recs.push_back(record(kMetadataIndex, c));
  }
  group(kMetadataIndex, recs);
  const std::uint64_t summary_offset_start = offset_;
  for (const Group& g : groups) {
    Bytes c;
    c.u8(g.op);
    c.u64(g.start);
    c.u64(g.length);
    if (st) st = put(record(kSummaryOffset, c));
  }
  if (st) {
    // The summary CRC runs through the footer's summary_offset_start field.
    Bytes f;
    f.u8(kFooter);
    f.u64(8 + 8 + 4);
    f.u64(summary_start);
    f.u64(summary_offset_start);
    st = put(f.b);
    Bytes tail;
    tail.u32(data_crc_);
    if (st) st = put(tail.b);
    if (st) st = put(kMagic);
  }
  stats_.bytes = offset_;
  if (std::fclose(file_) != 0 && st) st = fail(std::string("close: ") + std::strerror(errno));
  file_ = nullptr;
  return st;
}

}  // namespace ag::mcap
