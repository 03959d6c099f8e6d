// The team runner with the camera's sensor model on (noise, auto-exposure, motion blur, vignetting): the
// frames rendered ahead on a thread of their own are the frames a single thread renders when due.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "airground/sim/runner.hpp"

namespace ag::sim {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

enum class Camera { kShippedFile, kBuiltIn, kIdeal };

RunOptions run_in(const std::string& dir, int threads, Camera camera) {
  RunOptions o;
  o.out_dir = (fs::path(::testing::TempDir()) / dir).string();
  o.seed = 9;
  o.ugvs = 1;
  o.duration_s = 3;
  o.camera_scale = 0.25;
  o.camera_hz = 3;  // off the 50 Hz physics grid, as in TeamRunner.FramesRenderedAheadEqualFramesRenderedWhenDue
  o.lidar_columns = 512;
  o.record = RecordLevel::kFull;
  o.threads = threads;
  o.progress = false;
  if (camera == Camera::kShippedFile) {  // the shipped camera file: every effect on
    const fs::path cfg = fs::path(::testing::TempDir()) / "camera_sensor_cfg";
    fs::create_directories(cfg);
    fs::copy_file(fs::path(AG_SOURCE_DIR) / "config/sensors/camera.yaml", cfg / "camera.yaml", fs::copy_options::overwrite_existing);
    o.config_dir = cfg.string();
  } else if (camera == Camera::kIdeal) {  // a user's file switching every effect off
    const fs::path cfg = fs::path(::testing::TempDir()) / "camera_ideal_cfg";
    fs::create_directories(cfg);
    std::ofstream(cfg / "camera.yaml") << "camera_sensor:\n  noise: false\n  auto_exposure: false\n  motion_blur: false\n"
                                          "  vignetting: false\n";
    o.config_dir = cfg.string();
  }
  return o;
}

TEST(TeamRunnerCameraSensor, FramesRenderedAheadEqualFramesRenderedWhenDue) {
  auto one = run_team(run_in("cs_one", 1, Camera::kShippedFile));
  ASSERT_TRUE(one.ok()) << one.error().message;
  auto two = run_team(run_in("cs_two", 2, Camera::kShippedFile));
  ASSERT_TRUE(two.ok()) << two.error().message;
  ASSERT_GE(one->camera_frames, 9u);
  ASSERT_EQ(one->camera_frames, two->camera_frames);
  EXPECT_EQ(two->camera_frames_ahead, two->camera_frames - 1) << "a frame ahead was dropped: its shot did not match";
  const fs::path a = fs::path(::testing::TempDir()) / "cs_one", b = fs::path(::testing::TempDir()) / "cs_two";
  std::size_t frames = 0;
  for (const auto& e : fs::directory_iterator(a / "camera")) {
    const fs::path rel = fs::relative(e.path(), a);
    EXPECT_EQ(slurp(e.path()), slurp(b / rel)) << rel << " differs between one thread and two";
    ++frames;
  }
  EXPECT_EQ(frames, 2 * one->camera_frames);
  EXPECT_EQ(slurp(a / "camera_frames.csv"), slurp(b / "camera_frames.csv"));

  // With no camera file the robots get the same real camera (field mode); the ideal camera's frames differ.
  auto builtin = run_team(run_in("cs_builtin", 1, Camera::kBuiltIn));
  ASSERT_TRUE(builtin.ok()) << builtin.error().message;
  EXPECT_EQ(slurp(a / "camera" / "frame_000002_rgb.png"), slurp(fs::path(::testing::TempDir()) / "cs_builtin" / "camera" / "frame_000002_rgb.png"))
      << "the built-in camera is not the shipped file's";
  auto ideal = run_team(run_in("cs_ideal", 1, Camera::kIdeal));
  ASSERT_TRUE(ideal.ok()) << ideal.error().message;
  EXPECT_NE(slurp(a / "camera" / "frame_000002_rgb.png"), slurp(fs::path(::testing::TempDir()) / "cs_ideal" / "camera" / "frame_000002_rgb.png"));
}

}  // namespace
}  // namespace ag::sim
