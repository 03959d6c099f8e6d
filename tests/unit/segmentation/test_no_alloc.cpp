// ErfNet's frames never allocate once the engine is created (operator new counted by
// tests/common/counting_new.hpp), with one thread and with a worker pool.
#include <gtest/gtest.h>

#include <vector>

#include "airground/segmentation/erfnet.hpp"
#include "fixture.hpp"

#include "../../common/counting_new.hpp"

namespace ag::seg {
namespace {
using test_alloc::AllocationWindow;

TEST(NoAllocation, TheCounterSeesAllocations) {
  AllocationWindow w;
  std::vector<int> v(100);
  EXPECT_GE(w.allocations(), 1U);
}

TEST(NoAllocation, FramesOnEveryPathAndThreadCount) {
  auto w = load_weights(test::weights_path());
  ASSERT_TRUE(w.ok()) << w.error().message;
  const test::Crop g = test::crop(test::load_golden("erfnet_random_c7_64x48.golden"), 32, 24);
  std::vector<float> chw(3 * static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height), 0.25F);
  for (KernelPath p : {KernelPath::kPortable, best_kernel_path()}) {
    for (int threads : {1, 2}) {
      auto net = ErfNet::create(w.value(), ErfNetOptions{g.width, g.height, threads, p});
      ASSERT_TRUE(net.ok()) << net.error().message;
      net.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);  // warm-up, outside the window
      AllocationWindow window;
      net.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
      net.value()->run_planar(chw.data());
      EXPECT_EQ(window.allocations(), 0U) << kernel_path_name(p) << ", " << threads << " thread(s)";
    }
  }
}

}  // namespace
}  // namespace ag::seg

#include "stage_rig.hpp"

namespace ag::seg {
namespace {

TEST(NoAllocation, SegmentationStageStepsInBothModes) {
  const std::string path = test::weights_path();
  for (const char* mode : {"gt", "erfnet"}) {
#if defined(__aarch64__)
    if (std::string(mode) == "erfnet") continue;  // 640x400 frames: too slow under qemu (the engine is checked above)
#endif
    auto rig = test::StageRig::make({std::string("segmentation.labels=") + mode, "segmentation.weights=" + path, "segmentation.threads=2"});
    ASSERT_NE(rig, nullptr);
    auto kf = std::make_unique<KeyframeMsg>();
    EXPECT_EQ(rig->kf_w.push(*kf), 0U);
    rig->step(0);  // warm-up
    EXPECT_EQ(rig->kf_w.push(*kf), 0U);
    {
      test_alloc::AllocationWindow window;
      rig->stage->step(1);
      EXPECT_EQ(window.allocations(), 0U) << mode;
    }
    rig->sink->step(1);
    EXPECT_EQ(rig->sink->received, 2) << mode;
  }
}

}  // namespace
}  // namespace ag::seg
