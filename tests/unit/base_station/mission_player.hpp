// A small mission played over an in-process hub to a base station role: a quadrotor (robot 0) that
// publishes map tiles and regions, two ground robots (1, 2) that publish poses, a claim, visited and
// failed goals — every record encoded with the mission codec, as the robots encode them. The base is
// endpoint 3, registered as the inproc link of the instance "base".
#pragma once

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "airground/comms/gossip_node.hpp"
#include "airground/comms/link_hub.hpp"
#include "airground/comms/record_store.hpp"
#include "airground/comms/stage.hpp"
#include "airground/comms/tile_codec.hpp"
#include "airground/comms/wire.hpp"
#include "airground/mission/records.hpp"

namespace ag::base_station::test {

inline constexpr const char* kKeyHex = "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff";

struct TempDir {
  std::string path;
  TempDir() {
    char tmpl[] = "/tmp/ag_base_XXXXXX";
    path = ::mkdtemp(tmpl);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  [[nodiscard]] std::string file(const std::string& n) const { return path + "/" + n; }
};

inline std::string write_key(const std::string& path) {
  std::ofstream(path) << kKeyHex << "\n";
  ::chmod(path.c_str(), 0600);
  return path;
}

// Class of cell (row, col) of the player's tiles: tile (2, 1) is all water (6); elsewhere grass (2)
// with a road (0) along rows 30..33 and a vehicle (5) block in tile (0, 1).
inline std::uint8_t player_class(std::int32_t tx, std::int32_t ty, int row, int col) {
  if (tx == 2 && ty == 1) return 6;
  if (tx == 0 && ty == 1 && row >= 20 && row < 28 && col >= 16 && col < 28) return 5;
  if (row >= 30 && row < 34) return 0;
  return 2;
}

class MissionPlayer {
 public:
  static constexpr int kNodes = 4;
  static constexpr int kBase = 3;
  MissionPlayer() : hub_(kNodes, 0.0, 7) {
    const comms::TeamKey key = comms::TeamKey::from_hex(kKeyHex, "test").value();
    for (int i = 0; i < 3; ++i) {
      stores_.push_back(std::make_unique<comms::RecordStore>(comms::StoreLimits{1024, 8u << 20, 65536}));
      comms::GossipParams p;
      p.self = static_cast<comms::RobotId>(i);
      p.seed = 11 + static_cast<std::uint64_t>(i);
      p.digest_period_s = 0.2;
      nodes_.push_back(std::make_unique<comms::GossipNode>(p, key, *stores_.back(), 1, nullptr));
    }
    comms::register_inproc_link("base", &hub_.endpoint(kBase));
  }
  ~MissionPlayer() { comms::register_inproc_link("base", nullptr); }

  void tick(TimeNs now) {
    for (int i = 0; i < 3; ++i) nodes_[static_cast<std::size_t>(i)]->tick(now, hub_.endpoint(i));
  }
  comms::GossipNode& node(int i) { return *nodes_[static_cast<std::size_t>(i)]; }

  void tile(std::int32_t tx, std::int32_t ty, std::uint64_t version, TimeNs stamp) {
    auto t = std::make_unique<MapTileMsg>();
    t->tx = tx;
    t->ty = ty;
    t->version = version;
    t->stamp = stamp;
    for (int r = 0; r < kTileCells; ++r)
      for (int c = 0; c < kTileCells; ++c) {
        const std::size_t i = static_cast<std::size_t>(r * kTileCells + c);
        t->cls[i] = player_class(tx, ty, r, c);
        t->elevation[i] = 100.0f + 0.01f * static_cast<float>(r + c);
      }
    std::vector<std::uint8_t> buf(comms::TileCodec::max_payload_bytes());
    const std::size_t n = codec_.encode(*t, buf);
    ASSERT_GT(n, 0U);
    node(0).publish(comms::tile_topic(tx, ty), comms::default_priority(comms::TopicKind::kMapTile), stamp, {buf.data(), n});
  }
  void pose(int robot, double x, double y, double yaw, TimeNs stamp, LocalizationStatus st = LocalizationStatus::kTracking) {
    LocalizationMsg m;
    m.stamp = stamp;
    m.status = st;
    m.pose = Pose2{x, y, yaw};
    m.covariance[0] = 0.25;
    m.covariance[4] = 0.36;
    m.covariance[8] = 0.01;
    std::uint8_t buf[comms::kPosePayloadBytes];
    const std::size_t n = comms::CommsStage::encode_pose(m, buf);
    node(robot).publish(comms::make_topic(comms::TopicKind::kPose, 0), comms::default_priority(comms::TopicKind::kPose), stamp, {buf, n});
  }
  void record(int robot, comms::Topic topic, std::span<const std::uint8_t> bytes, TimeNs stamp) {
    node(robot).publish(topic, comms::default_priority(comms::topic_kind(topic)), stamp, bytes);
  }

  // The mission's regions, claim, visited and failed goal.
  static mission::RegionBatch regions() {
    mission::RegionBatch b;
    b.count = 3;
    b.batches = 1;
    b.regions_version = 1;
    b.regions[0] = mission::RegionRecord{11, 20.0f, 40.0f, 21.0f, 38.0f, 40, true};
    b.regions[1] = mission::RegionRecord{12, 45.0f, 15.0f, 44.0f, 13.0f, 24, true};
    b.regions[2] = mission::RegionRecord{13, 10.0f, 52.0f, 11.0f, 50.0f, 30, true};
    return b;
  }
  void publish_mission_records(TimeNs stamp) {
    std::uint8_t buf[1024];
    std::size_t n = mission::encode(regions(), buf);
    record(0, mission::regions_topic(0), {buf, n}, stamp);
    n = mission::encode(mission::ClaimRecord{mission::ClaimState::kGoing, 1, 11, 21.0f, 38.0f, 0.6f}, buf);
    record(1, mission::kClaimTopic, {buf, n}, stamp);
    mission::VisitedRecord v;
    v.count = 1;
    v.entries[0] = mission::VisitedEntry{12, 44.2f, 13.1f};
    n = mission::encode(v, buf);
    record(2, mission::kVisitedTopic, {buf, n}, stamp);
    n = mission::encode(mission::FailureRecord{mission::FailureReason::kNoRoute, 2, 13, 11.0f, 50.0f}, buf);
    record(2, mission::failure_topic(13), {buf, n}, stamp);
    n = mission::encode(mission::ObjectRecord{5, 4, 1, 11.0f, 42.0f, 0.2f, 0.01f, 0.3f}, buf);
    record(1, mission::object_topic(1), {buf, n}, stamp);
  }
  // Where the ground robots are at time t [s] of the mission (they drive slowly, then stand).
  static Pose2 robot_pose(int robot, double t) {
    const double s = std::min(t, 6.0);
    if (robot == 1) return Pose2{5.0 + 2.0 * s, 5.0 + 3.0 * s, std::atan2(3.0, 2.0)};
    return Pose2{5.0 + 6.0 * s, 20.0, 0.0};
  }

 private:
  comms::LinkHub hub_;
  comms::TileCodec codec_;
  std::vector<std::unique_ptr<comms::RecordStore>> stores_;
  std::vector<std::unique_ptr<comms::GossipNode>> nodes_;
};

}  // namespace ag::base_station::test
