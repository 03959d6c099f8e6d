// The quadrotor cache (issue 27, "the study stays affordable"): a mission records its quadrotor's mapping
// output, a second mission with the same world, seed and quadrotor replays it into the quadrotor's comms
// stage, and the ground robots live through exactly the same mission: their true paths, LiDAR scans,
// odometry, visits, the regions and everything the base station heard are the same, and the map's class
// accuracy too, while the replay renders no camera frame. A truncated recording is refused at start; a
// second recorder of the same quadrotor flies it live instead.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "airground/sim/eval_mission.hpp"
#include "airground/sim/generator.hpp"
#include "mission_world.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

fs::path out_root() {
  const char* b = std::getenv("AG_BINARY_DIR");
  return fs::path(b != nullptr ? b : fs::temp_directory_path().string()) / "mission-uav-replay";
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// The base station's mission log without its wall-clock stamps, in sorted order (its web thread writes the
// records of one simulated instant in the order it gets to them).
std::vector<std::string> base_log(const fs::path& p) {
  std::vector<std::string> lines;
  std::ifstream f(p);
  for (std::string l; std::getline(f, l);) {
    const auto a = l.find("\"utc\":");
    if (a != std::string::npos) l.erase(a, l.find(',', a) + 1 - a);
    lines.push_back(l);
  }
  std::sort(lines.begin(), lines.end());
  return lines;
}

MissionOptions options(const fs::path& root, const std::string& run, const fs::path& cache) {
  MissionOptions o;
  o.world = (root / "world").string();
  o.out_dir = (root / run).string();
  o.ugvs = 2;
  o.seed = 3;
  o.uav_altitude_m = 60;
  o.lidar_columns = 512;
  o.max_duration_s = 150;  // the first regions appear at ~30 s: claims, routes and a visit or two
  o.record = RecordLevel::kLight;  // the CSV streams compared below
  o.threads = 2;
  o.progress = false;
  // The replay does not care what made the tiles; the oracles keep the live run short (ErfNet and the VO
  // on every frame would triple it).
  o.oracles = {"labels", "vo"};
  o.uav_cache = cache.string();
  return o;
}

TEST(UavReplay, AReplayedMissionEqualsTheLiveOneItWasRecordedFrom) {
  const fs::path root = out_root();
  fs::remove_all(root);
  fs::create_directories(root);
  const std::string saved = test::save_mission_world((root / "world").string());
  ASSERT_TRUE(saved.empty()) << saved;
  const fs::path cache = root / "cache";

  auto live = run_mission(options(root, "live", cache));
  ASSERT_TRUE(live.ok()) << live.error().message;
  EXPECT_EQ(live.value().uav_replay.mode, "recorded");
  const fs::path recording = live.value().uav_replay.file;
  ASSERT_TRUE(fs::exists(recording)) << recording;
  ASSERT_GT(live.value().regions_found, 0U) << "nothing to replay: the test needs regions in 150 s";

  auto replay = run_mission(options(root, "replay", cache));
  ASSERT_TRUE(replay.ok()) << replay.error().message;
  const MissionMetrics& a = live.value();
  const MissionMetrics& b = replay.value();
  EXPECT_EQ(b.uav_replay.mode, "replayed");
  EXPECT_EQ(b.uav_replay.file, recording.string());
  EXPECT_NEAR(b.uav_replay.recording_end_s, 150.0, 1.0);

  // The ground robots' mission, bit for bit.
  for (const char* f : {"truth_ugv1.csv", "truth_ugv2.csv", "lidar_ugv1.csv", "lidar_ugv2.csv", "odom_ugv1.csv", "odom_ugv2.csv",
                        "visits.csv", "regions.csv", "truth_uav.csv"})
    EXPECT_EQ(slurp(root / "live" / f), slurp(root / "replay" / f)) << f;
  EXPECT_EQ(base_log(root / "live" / "mission_log.jsonl"), base_log(root / "replay" / "mission_log.jsonl"));
  EXPECT_EQ(a.regions_found, b.regions_found);
  EXPECT_EQ(a.targets_visited, b.targets_visited);
  EXPECT_EQ(a.bytes_on_air, b.bytes_on_air);
  EXPECT_EQ(a.loc_error_mean_m, b.loc_error_mean_m);
  EXPECT_EQ(a.map_class_accuracy, b.map_class_accuracy);  // the recorded final map
  EXPECT_GT(b.map_class_accuracy, 0.5);

  // The replay rendered no frame and ran no mapping stage.
  const std::string summary = slurp(root / "replay" / "summary.json");
  EXPECT_NE(summary.find("\"camera_frames\": 0,"), std::string::npos) << summary.substr(0, 400);
  for (const auto& s : b.stages) {
    EXPECT_EQ(s.name.find("uav/ortho_map"), std::string::npos);
    EXPECT_EQ(s.name.find("uav/regions"), std::string::npos);
  }

  // A truncated recording is refused before the run starts, naming the file.
  const fs::path broken = root / "broken";
  fs::create_directories(broken);
  const std::string bytes = slurp(recording);
  const fs::path cut = broken / recording.filename();
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  fs::copy_file(recording.string() + ".map", cut.string() + ".map");
  auto bad = run_mission(options(root, "broken_run", broken));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find(cut.string()), std::string::npos) << bad.error().message;
  EXPECT_NE(bad.error().message.find("truncated"), std::string::npos) << bad.error().message;
  EXPECT_FALSE(fs::exists(root / "broken_run" / "metrics.json"));

  // A mission that starts while another one records the same quadrotor (a study's two slots on one seed)
  // flies it live and writes nothing: one writer per recording, by an flock on <recording>.lock.
  const fs::path busy = root / "busy";
  fs::create_directories(busy);
  const fs::path lock = busy / (recording.filename().string() + ".lock");
  const int fd = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);  // "the other mission"
  MissionOptions o = options(root, "busy_run", busy);
  o.max_duration_s = 10;
  auto second = run_mission(o);
  ::close(fd);
  ASSERT_TRUE(second.ok()) << second.error().message;
  EXPECT_EQ(second.value().uav_replay.mode, "live");
  EXPECT_NE(second.value().uav_replay.file.find("being recorded by another mission"), std::string::npos) << second.value().uav_replay.file;
  EXPECT_FALSE(fs::exists(busy / recording.filename()));
  EXPECT_FALSE(fs::exists(busy / (recording.filename().string() + ".part"))) << "it wrote into the other mission's part file";
}

}  // namespace
}  // namespace ag::sim
