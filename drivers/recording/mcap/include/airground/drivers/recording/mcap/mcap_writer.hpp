// An MCAP file writer (https://mcap.dev/spec, version 0): zstd-compressed chunks with their message
// indexes, then a summary (schemas, channels, statistics, chunk and metadata indexes) with its summary
// offsets, and a footer; every CRC the spec defines is filled in. It knows nothing of robots: schemas,
// channels and message bytes are the caller's.
#pragma once

#include <cstdint>
#include <cstdio>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "airground/platform/result.hpp"

namespace ag::mcap {

// CRC-32 as MCAP uses it (ISO-HDLC: zlib's crc32, reflected polynomial 0xEDB88320). `crc` is a running
// value: crc32(b, crc32(a)) == crc32(a + b); start from 0.
[[nodiscard]] std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc = 0) noexcept;

struct WriterOptions {
  std::string profile{};                 // Header.profile: "" (ours: Foxglove's JSON well-known schemas)
  std::string library{"airground-mcap"};  // Header.library
  std::size_t chunk_size_bytes{1u << 20};  // a chunk is closed once its uncompressed records reach this
  int zstd_level{3};                     // 0 = store chunks uncompressed (compression "")
};

struct WriterStats {
  std::uint64_t messages{0};
  std::uint64_t chunks{0};
  std::uint64_t bytes{0};  // file size once closed
  std::map<std::uint16_t, std::uint64_t> channel_messages;  // channel id -> messages
};

class McapWriter {
 public:
  McapWriter() = default;
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;
  ~McapWriter();  // closes the file if it is open (errors are then lost: call close())

  // Creates `path` (truncating) and writes the magic and the Header. The error names the file.
  [[nodiscard]] Status open(const std::string& path, const WriterOptions& options = {});
  [[nodiscard]] bool is_open() const noexcept { return file_ != nullptr; }

  // Registers a schema (ids from 1) / a channel (ids from 0) and writes its record in the data section.
  // A channel's schema_id 0 means "no schema". Returns 0 for a schema / 0xFFFF for a channel on error.
  std::uint16_t add_schema(std::string_view name, std::string_view encoding, std::string_view data);
  std::uint16_t add_channel(std::uint16_t schema_id, std::string_view topic, std::string_view message_encoding,
                            const std::vector<std::pair<std::string, std::string>>& metadata = {});

  // One message on a registered channel; times in ns (log_time orders the file's indexes). The sequence
  // number is per channel, from 1.
  [[nodiscard]] Status write(std::uint16_t channel_id, std::uint64_t log_time_ns, std::uint64_t publish_time_ns,
                             std::span<const std::uint8_t> data);
  [[nodiscard]] Status write(std::uint16_t channel_id, std::uint64_t log_time_ns, std::string_view data) {
    return write(channel_id, log_time_ns, log_time_ns,
                 std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(data.data()), data.size()));
  }

  // A Metadata record (name, key-value pairs), indexed in the summary.
  [[nodiscard]] Status add_metadata(std::string_view name, const std::vector<std::pair<std::string, std::string>>& values);

  // Flushes the open chunk, writes DataEnd, the summary, its offsets and the footer, and closes the file.
  [[nodiscard]] Status close();

  [[nodiscard]] const WriterStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const std::string& path() const noexcept { return path_; }

 private:
  struct Schema {
    std::uint16_t id;
    std::string name, encoding, data;
  };
  struct Channel {
    std::uint16_t id, schema_id;
    std::string topic, encoding;
    std::vector<std::pair<std::string, std::string>> metadata;
    std::uint32_t sequence{0};
  };
  struct ChunkIndex {
    std::uint64_t start_time, end_time, chunk_offset, chunk_length;
    std::vector<std::pair<std::uint16_t, std::uint64_t>> index_offsets;
    std::uint64_t index_length, compressed_size, uncompressed_size;
  };
  struct MetadataIndex {
    std::uint64_t offset, length;
    std::string name;
  };

  Status put(std::span<const std::uint8_t> bytes);
  Status flush_chunk();
  Status fail(std::string what);

  std::FILE* file_{nullptr};
  std::string path_;
  WriterOptions options_;
  std::uint64_t offset_{0};
  std::uint32_t data_crc_{0};
  bool failed_{false};
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  // The open chunk: its uncompressed records and, per channel, (log time, offset in the chunk).
  std::vector<std::uint8_t> chunk_;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  std::uint64_t chunk_start_{0}, chunk_end_{0};
  std::vector<ChunkIndex> chunk_indexes_;
  std::vector<MetadataIndex> metadata_indexes_;
  std::uint64_t start_time_{0}, end_time_{0};
  WriterStats stats_;
};

// Standard base64 (RFC 4648, with padding): how Foxglove's JSON encoding carries `bytes` fields.
[[nodiscard]] std::string base64(std::span<const std::uint8_t> bytes);

}  // namespace ag::mcap
