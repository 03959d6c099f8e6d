// The store on disk: an append-only journal of every record written or received, replayed at start.
//
// File: a sequence of entries, each  magic u32 "AGJ1" | body length u32 | CRC-32C of body u32 | body.
// Body: kind u8 (1 record, 2 epoch), then for a record origin u8, topic u32, seq u64, priority u8,
// stamp i64, payload; for an epoch the u32 boot epoch. All little-endian.
// A process killed at any instant leaves at worst a torn last entry: open() detects it (short entry or
// CRC mismatch), reports where, skips it, resynchronises on the next valid entry, then rewrites the file
// with only the live records (temporary file, fsync, rename), so the journal never grows without bound
// across restarts and never keeps a bad region.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "airground/comms/record_store.hpp"
#include "airground/platform/result.hpp"

namespace ag::comms {

struct JournalReport {
  std::size_t bytes{0};            // file size when opened
  std::size_t entries{0};          // valid entries read
  std::size_t records_loaded{0};   // records that ended up in the store
  std::size_t bad_regions{0};      // torn or corrupt stretches skipped
  std::size_t bad_bytes{0};        // bytes in them
  std::uint32_t previous_epoch{0}; // highest epoch found (0: new journal)
  std::string problems;            // one line per bad region: where and why
};

class Journal {
 public:
  static constexpr std::uint32_t kMagic = 0x314A4741u;  // "AGJ1"
  static constexpr std::uint8_t kRecordEntry = 1;
  static constexpr std::uint8_t kEpochEntry = 2;

  // Opens or creates `path`, loads its records into `store`, rewrites it compacted and starts a new boot
  // epoch > every earlier one and >= min_epoch (the caller passes wall-clock seconds so a robot whose disk
  // was wiped still starts above the epochs its peers remember). The epoch is on disk (fsync) on return.
  static Result<std::unique_ptr<Journal>> open(const std::string& path, RecordStore& store, std::uint32_t min_epoch,
                                               JournalReport& report);
  ~Journal();
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  // One write(2) of one entry into the page cache: survives the process being killed. No allocation.
  bool append(const RecordMeta& meta, std::span<const std::uint8_t> payload) noexcept;
  // fdatasync(2): survives power loss too (call at stop and from a non-real-time context).
  bool sync() noexcept;

  [[nodiscard]] std::uint32_t epoch() const noexcept { return epoch_; }
  [[nodiscard]] std::uint64_t appended() const noexcept { return appended_; }
  [[nodiscard]] std::uint64_t write_errors() const noexcept { return write_errors_; }
  [[nodiscard]] const std::string& path() const noexcept { return path_; }

  // Encodes one record entry into `out` (sized >= entry_size); returns the bytes used.
  static std::size_t encode_record(const RecordMeta& meta, std::span<const std::uint8_t> payload,
                                   std::span<std::uint8_t> out) noexcept;
  static constexpr std::size_t entry_size(std::size_t payload) noexcept { return 12 + 1 + 1 + 4 + 8 + 1 + 8 + payload; }

 private:
  Journal(std::string path, int fd, std::uint32_t epoch, std::size_t max_payload);
  bool write_all(std::span<const std::uint8_t> bytes) noexcept;

  std::string path_;
  int fd_{-1};
  std::uint32_t epoch_{0};
  std::vector<std::uint8_t> buf_;
  std::uint64_t appended_{0};
  std::uint64_t write_errors_{0};
};

}  // namespace ag::comms
