// A recording split into MCAP files of bounded size in one directory, <prefix>-NNN.mcap, each closed
// as a complete file (summary, indexes) before the next opens, the oldest of the same robot deleted
// when the directory's total passes a cap. File work only: no robot knowledge, not for real-time threads.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "airground/drivers/recording/mcap/mcap_writer.hpp"
#include "airground/platform/result.hpp"

namespace ag::mcap {

struct RotationOptions {
  std::string dir;                 // created if missing; must be writable
  std::string prefix;              // "<role>-<robot>-<UTC start>"; files are <prefix>-NNN.mcap
  std::string family;              // files of earlier runs that count against the cap: "<role>-<robot>-"
  std::uint64_t max_file_bytes{512ull << 20};   // a file is closed before it would pass this (but for its summary)
  std::uint64_t max_total_bytes{8192ull << 20};  // the family's files in dir; the oldest go first
  WriterOptions writer{};
};

struct RotationStats {
  std::uint64_t files_opened{0};
  std::uint64_t files_deleted{0};
  std::uint64_t messages{0};
};

class McapRotation {
 public:
  // Registers the schemas and channels of a new file, in the same order each time (the ids must repeat).
  using Declare = std::function<Status(McapWriter&)>;

  // Checks the directory (created when missing; an error naming it when it cannot be written) and
  // opens the first file.
  [[nodiscard]] Status open(const RotationOptions& options, Declare declare);
  // One message (log times non-decreasing per channel); closes the file and opens the next when the
  // current one is full.
  [[nodiscard]] Status write(std::uint16_t channel_id, std::uint64_t log_time_ns, std::uint64_t publish_time_ns, std::string_view json);
  // Closes the current file (complete, with its summary).
  [[nodiscard]] Status close();

  [[nodiscard]] bool is_open() const noexcept { return writer_.is_open(); }
  [[nodiscard]] const std::string& current_path() const noexcept { return writer_.path(); }
  [[nodiscard]] const RotationStats& stats() const noexcept { return stats_; }

 private:
  Status open_next();
  Status enforce_total_cap();

  RotationOptions opt_;
  Declare declare_;
  McapWriter writer_;
  unsigned next_index_{0};
  std::uint64_t largest_message_{0};  // [bytes] of JSON so far: the next one may be as large
  RotationStats stats_;
};

}  // namespace ag::mcap
