// The quadrotor cache in a team run (RunOptions::uav_cache): record the live quadrotor's mapping output
// the first time, replay it into its comms stage after (sim/include/airground/sim/uav_replay.hpp).
#include <algorithm>

#include "airground/mission/stages.hpp"
#include "airground/aerial_mapping/stages.hpp"
#include "team.hpp"
#include "uav_recording.hpp"

namespace ag::sim::lockstep {

Status open_uav_cache(Team& t) {
  const RunOptions& opt = t.opt;
  if (opt.uav_cache.empty() || !opt.uav) return ok_status();
  if (!opt.gossip)
    return Error::make(ErrorCode::kInvalidArgument, "the quadrotor cache replays into the quadrotor's comms stage: it needs gossip (a mission)");
  if (opt.compute_time == ComputeTimeMode::kMeasured)
    return Error::make(ErrorCode::kInvalidArgument, "the quadrotor cache needs a repeatable run: --compute-time model or off, not measured");
  const std::uint64_t key = uav_replay_key(opt, *t.world);
  const fs::path path = uav_recording_path(opt.uav_cache, key);
  t.replay_info.file = path.string();
  t.replay_info.build = opt.uav_cache_build;
  std::error_code ec;
  const auto replay = [&]() -> Status {
    auto r = UavRecordReader::open(path, key);
    if (!r) return r.error();
    t.uav_play = std::move(r).value();
    t.replay_info.mode = "replayed";
    return ok_status();
  };
  if (fs::exists(path, ec)) return replay();  // a finished recording appears whole (renamed into place)
  if (!opt.uav_cache_build.empty())
    return Error::make(ErrorCode::kInvalidArgument, "--uav-cache-build " + opt.uav_cache_build + ": that build made no recording for this mission's world, seed, "
                                             "altitude and quadrotor settings in " + opt.uav_cache + " (" + path.filename().string() + ")");
  auto w = UavRecordWriter::create(path, key);
  if (!w && w.error().code == ErrorCode::kUnavailable) {
    // Another mission is recording this very quadrotor: fly it live here (the same results), record nothing.
    t.replay_info.mode = "live";
    t.replay_info.file = path.string() + " (being recorded by another mission)";
    return ok_status();
  }
  if (!w) return w.error();
  if (fs::exists(path, ec)) return replay();  // finished by the mission that held the lock a moment ago
  t.uav_rec = std::move(w).value();
  t.replay_info.mode = "recorded";
  return ok_status();
}

// The replayed quadrotor runs its status and comms stages, and the replay in place of everything that fed
// comms; a recorded one runs its whole table and the tap last. Both at the comms stage's rate.
void plug_uav_cache(Team& t, std::vector<StageSpec>& stages) {
  const auto comms = std::find_if(stages.begin(), stages.end(), [](const StageSpec& s) { return s.name == "comms"; });
  if (comms == stages.end() || (!t.uav_play && !t.uav_rec)) return;
  const double rate = comms->rate_hz;
  if (t.uav_rec) {
    stages.push_back(StageSpec{"sim_uav_tap", &UavTapStage::make, rate, 20'000, 1, -1, {},
                               "simulator: records what the quadrotor's comms stage reads (the quadrotor cache)"});
    return;
  }
  std::vector<StageSpec> kept;
  for (const StageSpec& s : stages) {
    if (s.name == "comms")
      kept.push_back(StageSpec{"sim_uav_replay", &UavReplayStage::make, rate, 20'000, 1, -1, {},
                               "simulator: the recorded map tiles and region batches (the quadrotor cache)"});
    if (s.name == "status" || s.name == "comms") kept.push_back(s);
  }
  stages = std::move(kept);
}

Status attach_uav_cache(Team& t) {
  RoleInstance* role = t.uav ? t.uav->role.get() : nullptr;
  if (role == nullptr) return ok_status();
  if (t.uav_rec) {
    auto* tap = find_stage<UavTapStage>(role);
    if (tap == nullptr) return Error::make(ErrorCode::kInternal, "the quadrotor cache: no tap stage in the quadrotor's table");
    tap->writer = t.uav_rec.get();
    tap->regions = find_stage<const mission::RegionsStage>(role);
    t.uav_tap = tap;
  }
  if (t.uav_play) {
    auto* rp = find_stage<UavReplayStage>(role);
    if (rp == nullptr) return Error::make(ErrorCode::kInternal, "the quadrotor cache: no replay stage in the quadrotor's table");
    rp->attach(t.uav_play.get());
  }
  return ok_status();
}

Status finish_uav_cache(Team& t, TimeNs ended) {
  UavReplayInfo& info = t.replay_info;
  if (t.uav_rec) {
    if (t.uav_tap != nullptr && t.uav_tap->drops() > 0)
      return Error::make(ErrorCode::kInternal, "the quadrotor cache: the tap missed " + std::to_string(t.uav_tap->drops()) + " messages; nothing recorded");
    const auto* om = find_stage<const mapping::OrthoMapStage>(t.uav->role.get());
    if (auto st = t.uav_rec->finish(ended, om != nullptr ? om->map().raster() : mapping::MapRaster{}); !st) return st;
    t.uav_rec.reset();
  }
  if (t.uav_play) {
    if (!t.uav_play->error().empty()) return Error::make(ErrorCode::kMalformed, t.uav_play->error());
    if (t.uav_play->kind() == UavRecordKind::kEnd) {
      info.recording_end_s = to_seconds(t.uav_play->time());
      info.last_output_s = to_seconds(t.uav_play->last_output());
      info.beyond_end_s = to_seconds(std::max<TimeNs>(0, ended - t.uav_play->time()));
    }
  }
  return ok_status();
}

}  // namespace ag::sim::lockstep
