// The segmentation stage: with labels = gt it relays keyframes unchanged; with labels = erfnet it
// replaces their classes by ErfNet's argmax, mapped to class ids by the weights' class names; bad
// weights stop the robot at start with a message naming the key and the file.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "airground/messages/classes.hpp"
#include "fixture.hpp"
#include "stage_rig.hpp"

namespace ag::seg {
namespace {

std::unique_ptr<KeyframeMsg> keyframe(std::uint32_t id) {
  auto kf = std::make_unique<KeyframeMsg>();
  kf->id = id;
  kf->stamp = 1'000'000 * static_cast<TimeNs>(id + 1);
  kf->body_pose = Pose3{1.0 * id, 2.0, 40.0, 0.0, 0.0, 0.3};
  kf->labels = LabelSource::kGroundTruth;
  std::uint32_t s = 7 + id;
  for (std::size_t i = 0; i < kf->rgb.size(); ++i) {
    s = s * 1664525U + 1013904223U;
    const std::size_t px = i / 3;
    kf->rgb[i] = static_cast<std::uint8_t>((px % kImageWidth) / 4 + (s >> 28));
  }
  for (std::size_t i = 0; i < kf->cls.size(); ++i) kf->cls[i] = static_cast<std::uint8_t>((i / 1000) % 7);
  return kf;
}

TEST(SegmentationStage, GroundTruthLabelsAreRelayedUnchanged) {
  auto rig = test::StageRig::make({});
  ASSERT_NE(rig, nullptr);
  EXPECT_FALSE(rig->stage->erfnet());
  for (std::uint32_t id = 0; id < 3; ++id) {
    auto kf = keyframe(id);
    EXPECT_EQ(rig->kf_w.push(*kf), 0U);
  }
  rig->step(0);
  EXPECT_EQ(rig->sink->received, 3);
  EXPECT_EQ(rig->stage->counters().relayed_gt, 3U);
  const auto want = keyframe(2);
  EXPECT_EQ(rig->sink->last->id, 2U);
  EXPECT_EQ(rig->sink->last->labels, LabelSource::kGroundTruth);
  EXPECT_EQ(rig->sink->last->cls, want->cls);
  EXPECT_EQ(rig->sink->last->rgb, want->rgb);
}

TEST(SegmentationStage, ErfNetLabelsAreTheNetworksArgmaxAsClassIds) {
#if defined(__aarch64__)
  GTEST_SKIP() << "640x400 frames are too slow under qemu; the NEON numerics are in test_numerics";
#endif
  // Weights whose logits are named in reverse table order: logit i is class 6 - i.
  ErfNetWeights w = test::fixture_weights();
  w.header.class_names = {"water", "vehicle", "building", "tree", "grass", "dirt", "road"};
  const std::string path = ::testing::TempDir() + "/seg_stage_named.agw";
  {
    const std::vector<std::uint8_t> bytes = serialize_weights(w, true);
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  auto rig = test::StageRig::make({"segmentation.labels=erfnet", "segmentation.weights=" + path, "segmentation.threads=2"});
  ASSERT_NE(rig, nullptr);
  ASSERT_TRUE(rig->stage->erfnet());
  auto kf = keyframe(5);
  EXPECT_EQ(rig->kf_w.push(*kf), 0U);
  rig->step(0);
  ASSERT_EQ(rig->sink->received, 1);
  const KeyframeMsg& got = *rig->sink->last;
  EXPECT_EQ(got.labels, LabelSource::kSegmentation);
  EXPECT_EQ(got.id, 5U);
  EXPECT_EQ(got.stamp, kf->stamp);
  EXPECT_EQ(got.rgb, kf->rgb);
  // The same frame through an engine of our own.
  auto net = ErfNet::create(w, ErfNetOptions{kImageWidth, kImageHeight, 1, KernelPath::kAuto});
  ASSERT_TRUE(net.ok());
  net.value()->run_rgb8(kf->rgb.data(), static_cast<std::size_t>(kImageWidth) * 3);
  std::size_t same = 0, changed = 0;
  for (std::size_t i = 0; i < kImagePixels; ++i) {
    same += got.cls[i] == 6 - net.value()->classes()[i] ? 1U : 0U;
    changed += got.cls[i] != kf->cls[i] ? 1U : 0U;
  }
  EXPECT_EQ(same, kImagePixels);
  EXPECT_GT(changed, kImagePixels / 2);  // the camera's classes were replaced
  EXPECT_EQ(rig->stage->counters().segmented, 1U);
  // One keyframe per step: a second and a third queued wait for the next steps.
  for (std::uint32_t id : {6U, 7U}) EXPECT_EQ(rig->kf_w.push(*keyframe(id)), 0U);
  rig->step(1);
  EXPECT_EQ(rig->sink->received, 2);
  rig->step(2);
  EXPECT_EQ(rig->sink->received, 3);
}

TEST(SegmentationStage, BadWeightsStopTheRobotAtStart) {
  std::string err;
  EXPECT_EQ(test::StageRig::make({"segmentation.labels=erfnet", "segmentation.weights=/nonexistent/w.agw"}, &err), nullptr);
  EXPECT_NE(err.find("segmentation.weights"), std::string::npos) << err;
  EXPECT_NE(err.find("/nonexistent/w.agw"), std::string::npos) << err;
  ErfNetWeights w = test::fixture_weights();
  w.header.class_names = {"road", "dirt", "grass", "tree", "building", "vehicle", "lava"};
  const std::string path = ::testing::TempDir() + "/seg_stage_lava.agw";
  {
    const std::vector<std::uint8_t> bytes = serialize_weights(w, true);
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  EXPECT_EQ(test::StageRig::make({"segmentation.labels=erfnet", "segmentation.weights=" + path}, &err), nullptr);
  EXPECT_NE(err.find("class 'lava' is not in the class table"), std::string::npos) << err;
}

}  // namespace
}  // namespace ag::seg
