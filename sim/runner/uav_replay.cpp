// The quadrotor replay: the cache key of a run's quadrotor and the stage that replays its recording.
#include "airground/sim/uav_replay.hpp"

#include <cstdio>
#include <cstring>
#include <string_view>
#include <vector>

#include "airground/messages/channels.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/world.hpp"
#include "team_setup.hpp"
#include "uav_recording.hpp"

namespace ag::sim {

namespace {

// 64-bit FNV-1a over words (and the tail bytes): a cache key, not a defence against forgery.
class KeyHash {
 public:
  void bytes(const void* p, std::size_t n) noexcept {
    const auto* b = static_cast<const std::uint8_t*>(p);
    std::size_t i = 0;
    for (; i + 8 <= n; i += 8) {
      std::uint64_t w;
      std::memcpy(&w, b + i, 8);
      h_ = (h_ ^ w) * kPrime;
    }
    for (; i < n; ++i) h_ = (h_ ^ b[i]) * kPrime;
    h_ = (h_ ^ n) * kPrime;  // lengths too: "ab" + "c" differs from "a" + "bc"
  }
  void text(std::string_view s) noexcept { bytes(s.data(), s.size()); }
  template <typename T>
  void value(const T& v) noexcept {
    static_assert(std::is_arithmetic_v<T>);
    bytes(&v, sizeof v);
  }
  void mat(const cv::Mat& m) noexcept {
    value(m.rows);
    value(m.cols);
    value(m.type());
    for (int r = 0; r < m.rows; ++r) bytes(m.ptr(r), static_cast<std::size_t>(m.cols) * m.elemSize());
  }
  void file(const char* path) noexcept {
    std::FILE* f = std::fopen(path, "rb");
    if (f == nullptr) return;
    std::vector<std::uint8_t> buf(1 << 16);  // not static: two runs in one process may hash at once
    for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), f)) > 0;) bytes(buf.data(), n);
    std::fclose(f);
  }
  [[nodiscard]] std::uint64_t get() const noexcept { return h_; }

 private:
  static constexpr std::uint64_t kPrime = 0x100000001b3ULL;
  std::uint64_t h_{0xcbf29ce484222325ULL};
};

}  // namespace

std::uint64_t uav_replay_key(const RunOptions& o, const World& w) {
  KeyHash h;
  h.file(o.uav_cache_build.empty() ? "/proc/self/exe" : o.uav_cache_build.c_str());  // any rebuild makes new recordings
  h.text(w.header.name);
  h.value(w.header.grid.resolution);
  h.value(w.header.grid.width);
  h.value(w.header.grid.height);
  h.value(w.header.grid.origin_x);
  h.value(w.header.grid.origin_y);
  h.value(w.header.datum.lat_deg);
  h.value(w.header.datum.lon_deg);
  h.value(w.header.datum.height_m);
  h.mat(w.class_id);
  h.mat(w.height);
  h.mat(w.terrain);
  h.mat(w.albedo);
  // Every option the quadrotor's flight, sensors and stages see (team_setup.cpp set_up_uav).
  h.value(o.seed);
  h.value(o.physics_hz);
  h.value(o.camera_hz);
  h.value(o.camera_scale);
  h.value(o.uav_altitude_m);
  h.value(o.uav_speed_mps);
  h.value(o.survey_overlap);
  h.value(o.survey_margin_m);
  h.value(o.survey_x0);
  h.value(o.survey_y0);
  h.value(o.survey_x1);
  h.value(o.survey_y1);
  h.value(o.uav_return_home);
  h.value(o.gossip);  // whether comms reads map_tiles: the ortho-map's ring room
  h.text(o.config_dir);
  h.file(lockstep::erfnet_weights_path().c_str());  // new weights make new recordings
  for (const std::string& kv : o.uav_config) {
    h.text(kv);
    if (kv.rfind("segmentation.weights=", 0) == 0) h.file(kv.substr(kv.find('=') + 1).c_str());
  }
  h.text(o.oracles_json());
  h.value(static_cast<int>(o.compute_time));
  h.value(static_cast<int>(o.target_of("uav")));
  return h.get();
}

Status UavReplayStage::init(StageContext& ctx) {
  auto t = ctx.channels.ring_writer(chan::kMapTiles);
  if (!t) return t.error();
  tiles_out_ = t.value();
  auto g = ctx.channels.ring_writer(chan::kGossipOut);
  if (!g) return g.error();
  gossip_out_ = g.value();
  tile_ = std::make_unique<MapTileMsg>();
  gossip_ = std::make_unique<comms::GossipPublishMsg>();
  return ok_status();
}

void UavReplayStage::step(TimeNs now) noexcept {
  if (reader_ == nullptr) return;
  for (;;) {
    const UavRecordKind k = reader_->kind();
    if (k == UavRecordKind::kEnd || reader_->time() > now) return;
    switch (k) {
      case UavRecordKind::kTile:
        if (tiles_out_.free_slots() == 0) {  // cannot happen when comms reads as it did live; held, not lost
          ++ring_full_;
          return;
        }
        if (!reader_->take_tile(*tile_)) return;
        (void)tiles_out_.push(*tile_);
        ++tiles_;
        break;
      case UavRecordKind::kGossip:
        if (gossip_out_.free_slots() == 0) {
          ++ring_full_;
          return;
        }
        if (!reader_->take_gossip(*gossip_)) return;
        (void)gossip_out_.push(*gossip_);
        ++batches_;
        break;
      case UavRecordKind::kRegions:
        if (!reader_->take_regions(*regions_)) return;
        break;
      case UavRecordKind::kEnd:
        return;
    }
  }
}

Result<mapping::MapRaster> UavReplayStage::final_map() const {
  if (reader_ == nullptr) return Error::make(ErrorCode::kInternal, "the replay stage has no recording");
  return reader_->raster();
}

}  // namespace ag::sim
