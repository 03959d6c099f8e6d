// McapRotation: size-bounded MCAP files in one directory and a cap on the family's total.
#include "airground/drivers/recording/recorder/mcap_rotation.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <span>
#include <system_error>
#include <utility>
#include <vector>

namespace ag::mcap {

namespace fs = std::filesystem;

Status McapRotation::open(const RotationOptions& options, Declare declare) {
  opt_ = options;
  declare_ = std::move(declare);
  if (opt_.max_file_bytes == 0 || opt_.max_total_bytes < opt_.max_file_bytes)
    return Error::make(ErrorCode::kInvalidArgument, "recording in '" + opt_.dir + "': the total cap (" + std::to_string(opt_.max_total_bytes) +
                                                        " B) must be at least one file (" + std::to_string(opt_.max_file_bytes) + " B)");
  // A chunk is the unit a file grows by: keep it well under the file size so files end near their cap.
  opt_.writer.chunk_size_bytes = static_cast<std::size_t>(std::clamp<std::uint64_t>(opt_.max_file_bytes / 8, 16u << 10, opt_.writer.chunk_size_bytes));
  std::error_code ec;
  fs::create_directories(opt_.dir, ec);
  if (ec || !fs::is_directory(opt_.dir, ec))
    return Error::make(ErrorCode::kIo, "recording directory '" + opt_.dir + "' cannot be created: " + (ec ? ec.message() : "not a directory"));
  // Root ignores permission bits: only creating a file tells whether the directory takes files.
  const fs::path probe = fs::path(opt_.dir) / (".write-test-" + opt_.prefix);
  std::FILE* f = std::fopen(probe.c_str(), "wb");
  if (f == nullptr) return Error::make(ErrorCode::kIo, "recording directory '" + opt_.dir + "' is not writable");
  std::fclose(f);
  fs::remove(probe, ec);
  if (Status s = open_next(); !s) return s;
  return enforce_total_cap();
}

Status McapRotation::open_next() {
  std::string path;
  for (;; ++next_index_) {
    char name[32];
    std::snprintf(name, sizeof name, "-%03u.mcap", next_index_);
    path = (fs::path(opt_.dir) / (opt_.prefix + name)).string();
    std::error_code ec;
    if (!fs::exists(path, ec)) break;  // never overwrite an earlier run's file
  }
  ++next_index_;
  if (Status s = writer_.open(path, opt_.writer); !s) return s;
  ++stats_.files_opened;
  if (declare_) return declare_(writer_);
  return ok_status();
}

Status McapRotation::write(std::uint16_t channel_id, std::uint64_t log_time_ns, std::uint64_t publish_time_ns, std::string_view json) {
  if (!writer_.is_open()) return Error::make(ErrorCode::kIo, "recording in '" + opt_.dir + "' is closed");
  if (Status s = writer_.write(channel_id, log_time_ns, publish_time_ns,
                              std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(json.data()), json.size()));
      !s)
    return s;
  ++stats_.messages;
  largest_message_ = std::max<std::uint64_t>(largest_message_, json.size());
  std::error_code ec;
  const std::uintmax_t on_disk = fs::file_size(writer_.path(), ec);
  // On disk, plus the open chunk (under one chunk), plus the next message must fit: the file ends under
  // max_file_bytes but for its summary.
  if (ec || on_disk + opt_.writer.chunk_size_bytes + largest_message_ < opt_.max_file_bytes) return ok_status();
  if (Status s = writer_.close(); !s) return s;
  if (Status s = open_next(); !s) return s;
  return enforce_total_cap();
}

Status McapRotation::enforce_total_cap() {
  struct File {
    std::string name;
    std::uint64_t bytes;
    std::string start;   // the name up to its index: "<role>-<robot>-<UTC start>"
    unsigned long index;  // NNN (past 999 it grows a digit)
  };
  std::vector<File> files;
  std::uint64_t total = 0;
  std::error_code ec;
  for (const fs::directory_entry& e : fs::directory_iterator(opt_.dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(opt_.family, 0) != 0 || e.path().extension() != ".mcap") continue;
    std::error_code sec;
    const std::uint64_t bytes = e.file_size(sec);
    if (sec) continue;
    const std::size_t dash = name.rfind('-');
    const std::string digits = name.substr(dash + 1, name.size() - dash - 1 - 5);
    const unsigned long index = !digits.empty() && digits.size() <= 9 && digits.find_first_not_of("0123456789") == std::string::npos ? std::stoul(digits) : 0;
    files.push_back({name, bytes, name.substr(0, dash), index});
    total += bytes;
  }
  if (ec) return Error::make(ErrorCode::kIo, "recording directory '" + opt_.dir + "' cannot be listed: " + ec.message());
  // By start time, then by index: the oldest first.
  std::sort(files.begin(), files.end(), [](const File& a, const File& b) { return a.start != b.start ? a.start < b.start : a.index < b.index; });
  const std::string current = fs::path(writer_.path()).filename().string();
  for (const File& f : files) {
    if (total <= opt_.max_total_bytes) break;
    if (f.name == current) continue;
    if (!fs::remove(fs::path(opt_.dir) / f.name, ec) || ec)
      return Error::make(ErrorCode::kIo, "cannot delete the old recording '" + (fs::path(opt_.dir) / f.name).string() + "': " + ec.message());
    total -= f.bytes;
    ++stats_.files_deleted;
  }
  return ok_status();
}

Status McapRotation::close() {
  if (!writer_.is_open()) return ok_status();
  if (Status s = writer_.close(); !s) return s;
  return enforce_total_cap();
}

}  // namespace ag::mcap
