// The quadrotor's recording (sim/include/airground/sim/uav_replay.hpp): one zstd stream of records in
// time order (a header with the cache key and the message sizes, then kind, time and body, then an end
// record), and beside it the final ortho-map raster. Written by the tap stage of a live run, read by the
// replay stage. The format is this build's: the key holds the executable's hash, so another build never
// reads it.
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <vector>

#include "airground/aerial_mapping/ortho_map.hpp"
#include "airground/mission/stages.hpp"
#include "airground/platform/result.hpp"
#include "airground/platform/stage.hpp"
#include "airground/sim/uav_replay.hpp"

struct ZSTD_CCtx_s;
struct ZSTD_DCtx_s;

namespace ag::sim {

enum class UavRecordKind : std::uint8_t { kTile = 1, kGossip = 2, kRegions = 3, kEnd = 4 };

// The recording's file name in a cache directory for a key.
[[nodiscard]] std::filesystem::path uav_recording_path(const std::filesystem::path& cache_dir, std::uint64_t key);

// Writes `<final>.part` while the run goes on; finish() adds the end record and the raster and renames
// it to `final`. A writer destroyed unfinished removes its part file (a failed run leaves no recording).
// One writer per recording: it holds an flock on `<final>.lock` from create() to its end (released by
// the kernel if the process dies), and create() fails with kUnavailable while another process holds it
// (two missions of a study starting the same quadrotor at once would otherwise write one part file).
class UavRecordWriter {
 public:
  static Result<std::unique_ptr<UavRecordWriter>> create(const std::filesystem::path& final_path, std::uint64_t key);
  ~UavRecordWriter();
  UavRecordWriter(const UavRecordWriter&) = delete;
  UavRecordWriter& operator=(const UavRecordWriter&) = delete;

  void tile(TimeNs t, const MapTileMsg& m);
  void gossip(TimeNs t, const comms::GossipPublishMsg& m);
  void regions(TimeNs t, const mission::RegionsMsg& m);
  Status finish(TimeNs end, const mapping::MapRaster& raster);
  [[nodiscard]] std::uint64_t records() const noexcept { return records_; }

 private:
  UavRecordWriter() = default;
  void put(const void* p, std::size_t n);
  void record(UavRecordKind kind, TimeNs t);
  void flush(bool end);
  std::filesystem::path final_, part_;
  int lock_fd_{-1};
  std::FILE* f_{nullptr};
  ZSTD_CCtx_s* z_{nullptr};
  std::vector<std::uint8_t> in_, out_;
  std::uint64_t records_{0};
  TimeNs last_output_{0};
  bool failed_{false};
};

// Reads a recording record by record; peek() shows the next one's kind and time, take() reads its body.
class UavRecordReader {
 public:
  // Opens `path` and checks its header against `key` and every record through to the end: a wrong key, a
  // truncated or corrupt file or a missing map is an error naming it.
  static Result<std::unique_ptr<UavRecordReader>> open(const std::filesystem::path& path, std::uint64_t key);
  ~UavRecordReader();
  UavRecordReader(const UavRecordReader&) = delete;
  UavRecordReader& operator=(const UavRecordReader&) = delete;

  // The next record's kind and time; kEnd at the end (its time: the recording's end).
  [[nodiscard]] UavRecordKind kind() const noexcept { return kind_; }
  [[nodiscard]] TimeNs time() const noexcept { return time_; }
  // Reads the next record's body into the matching message and moves on. False on a truncated file
  // (then kind() is kEnd and error() says where).
  bool take_tile(MapTileMsg& m) noexcept;
  bool take_gossip(comms::GossipPublishMsg& m) noexcept;
  bool take_regions(mission::RegionsMsg& m) noexcept;
  [[nodiscard]] TimeNs last_output() const noexcept { return last_output_; }  // valid at kEnd
  [[nodiscard]] const std::string& error() const noexcept { return error_; }
  // The final map of the recorded run (`<path>.map`), loaded once.
  Result<mapping::MapRaster> raster() const;

 private:
  UavRecordReader() = default;
  static Result<std::unique_ptr<UavRecordReader>> open_once(const std::filesystem::path& path, std::uint64_t key);
  bool get(void* p, std::size_t n) noexcept;
  bool body(void* p, std::size_t n) noexcept;  // get(), or the error naming the record
  void advance() noexcept;
  std::filesystem::path path_;
  std::FILE* f_{nullptr};
  ZSTD_DCtx_s* z_{nullptr};
  std::vector<std::uint8_t> in_, out_;
  std::size_t in_pos_{0}, in_end_{0}, out_pos_{0}, out_end_{0};
  UavRecordKind kind_{UavRecordKind::kEnd};
  TimeNs time_{0};
  TimeNs last_output_{0};
  std::string error_{};
};

// The recording's tap: last in the live quadrotor's table at its comms stage's rate, it reads what its
// comms stage reads (map_tiles, gossip_out) at the same steps, and the regions stage's published regions.
class UavTapStage final : public Stage {
 public:
  static std::unique_ptr<Stage> make() { return std::make_unique<UavTapStage>(); }
  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;
  // Messages the tap's own rings could not take (a recording with any is refused).
  [[nodiscard]] std::uint64_t drops() const noexcept { return tiles_.drops() + gossip_.drops(); }
  UavRecordWriter* writer{nullptr};
  const mission::RegionsStage* regions{nullptr};

 private:
  RingReader<MapTileMsg, kMapTileRing> tiles_{};
  RingReader<comms::GossipPublishMsg, comms::kGossipRing> gossip_{};
  std::uint32_t regions_version_{0};
};

}  // namespace ag::sim
