// The C++ ErfNet against the torch reference (float64, same fp16-exact random weights and BN statistics,
// tools/erfnet_goldens.py) on every kernel path this CPU and build have: logits within 1e-3 absolute,
// the same argmax on at least 99.9% of pixels.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "airground/segmentation/erfnet.hpp"
#include "fixture.hpp"

namespace ag::seg {
namespace {

struct Compared {
  double max_abs{0};
  double argmax_agree{0};
};

Compared compare(const ErfNet& net, const test::Golden& g) {
  Compared c;
  const std::size_t plane = static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
  for (std::size_t i = 0; i < g.logits.size(); ++i)
    c.max_abs = std::max(c.max_abs, static_cast<double>(std::fabs(net.logits()[i] - g.logits[i])));
  std::size_t agree = 0;
  for (std::size_t p = 0; p < plane; ++p) agree += net.classes()[p] == g.argmax(p) ? 1U : 0U;
  c.argmax_agree = static_cast<double>(agree) / static_cast<double>(plane);
  return c;
}

class Numerics : public ::testing::TestWithParam<KernelPath> {};

TEST_P(Numerics, MatchesTorchOnEveryAvailablePath) {
  const KernelPath path = GetParam();
  if (!kernel_path_available(path)) GTEST_SKIP() << kernel_path_name(path) << " is not available here";
  const test::WeightsRef w{test::fixture_weights()};
  ASSERT_FALSE(w.value().tensors.empty());
  const test::Golden g = test::load_golden("erfnet_random_c7_64x48.golden");
  ASSERT_EQ(g.classes, 7);
  for (bool winograd : {true, false}) {
    for (int threads : {1, 2}) {
      if (!winograd && threads == 2) continue;  // threading is the same code for both (and qemu is slow)
      auto net = ErfNet::create(w.value(), ErfNetOptions{g.width, g.height, threads, path, winograd});
      ASSERT_TRUE(net.ok()) << net.error().message;
      ASSERT_EQ(net.value()->path(), path);
      net.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
      const Compared c = compare(*net.value(), g);
      std::printf("[%s, %s, %d thread(s)] max |logit - torch| = %.2e, argmax agreement %.4f\n", std::string(kernel_path_name(path)).c_str(),
                  winograd ? "winograd" : "direct", threads, c.max_abs, c.argmax_agree);
      EXPECT_LE(c.max_abs, 1e-3) << kernel_path_name(path) << " " << threads << " winograd " << winograd;
      EXPECT_GE(c.argmax_agree, 0.999) << kernel_path_name(path) << " " << threads << " winograd " << winograd;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Paths, Numerics, ::testing::Values(KernelPath::kPortable, KernelPath::kAvx2, KernelPath::kNeon),
                         [](const ::testing::TestParamInfo<KernelPath>& p) { return std::string(kernel_path_name(p.param)); });

TEST(Numerics, AutoPicksTheFastestPathAndPlanarInputAgrees) {
  const test::WeightsRef w{test::fixture_weights()};
  ASSERT_FALSE(w.value().tensors.empty());
  const test::Golden g = test::load_golden("erfnet_random_c7_64x48.golden");
  auto net = ErfNet::create(w.value(), ErfNetOptions{0, 0, 1, KernelPath::kAuto});  // size from the header (64x48)
  ASSERT_TRUE(net.ok()) << net.error().message;
  EXPECT_EQ(net.value()->path(), best_kernel_path());
  EXPECT_EQ(net.value()->width(), 64);
  EXPECT_EQ(net.value()->height(), 48);
#if defined(__x86_64__)
  if (kernel_path_available(KernelPath::kAvx2)) {
    EXPECT_EQ(best_kernel_path(), KernelPath::kAvx2);
  }
#elif defined(__aarch64__)
  EXPECT_EQ(best_kernel_path(), KernelPath::kNeon);
#endif
  const std::size_t plane = static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
  std::vector<float> chw(3 * plane);
  for (std::size_t p = 0; p < plane; ++p)
    for (std::size_t c = 0; c < 3; ++c) chw[c * plane + p] = static_cast<float>(g.rgb[p * 3 + c]) / 255.0F;
  net.value()->run_planar(chw.data());
  const Compared c = compare(*net.value(), g);
  EXPECT_LE(c.max_abs, 1e-3);
  EXPECT_GE(c.argmax_agree, 0.999);
}

TEST(Numerics, RepeatedFramesAndThreadCountsGiveIdenticalLogits) {
  const test::WeightsRef w{test::fixture_weights()};
  ASSERT_FALSE(w.value().tensors.empty());
  const test::Crop g = test::crop(test::load_golden("erfnet_random_c7_64x48.golden"), 32, 24);
  auto one = ErfNet::create(w.value(), ErfNetOptions{g.width, g.height, 1, KernelPath::kAuto});
  auto three = ErfNet::create(w.value(), ErfNetOptions{g.width, g.height, 3, KernelPath::kAuto});
  ASSERT_TRUE(one.ok() && three.ok());
  EXPECT_EQ(three.value()->threads(), 3);
  const std::size_t n = 7U * 32U * 24U;
  // A different image first, so that stale activations would show in the second frame.
  std::vector<std::uint8_t> other(g.rgb.rbegin(), g.rgb.rend());
  one.value()->run_rgb8(other.data(), static_cast<std::size_t>(g.width) * 3);
  const std::vector<float> first_other(one.value()->logits(), one.value()->logits() + n);
  one.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
  const std::vector<float> a(one.value()->logits(), one.value()->logits() + n);
  EXPECT_NE(a, first_other);
  three.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
  const std::vector<float> b(three.value()->logits(), three.value()->logits() + n);
  EXPECT_EQ(a, b);  // each output row is computed by one thread in a fixed order: bit-identical
  one.value()->run_rgb8(other.data(), static_cast<std::size_t>(g.width) * 3);
  EXPECT_EQ(std::vector<float>(one.value()->logits(), one.value()->logits() + n), first_other);
}

TEST(Numerics, HeaderNormalisationIsApplied) {
  const test::WeightsRef w{test::fixture_weights()};
  ASSERT_FALSE(w.value().tensors.empty());
  const test::Crop g = test::crop(test::load_golden("erfnet_random_c7_64x48.golden"), 32, 24);
  // mean 0.5, std 0.5 on RGB maps v/255 to 2 v/255 - 1: the same as feeding that planar image.
  ErfNetWeights shifted = w.value();
  for (int c = 0; c < 3; ++c) {
    shifted.header.mean[c] = 0.5F;
    shifted.header.std[c] = 0.5F;
  }
  auto a = ErfNet::create(shifted, ErfNetOptions{g.width, g.height, 1, KernelPath::kAuto});
  auto b = ErfNet::create(w.value(), ErfNetOptions{g.width, g.height, 1, KernelPath::kAuto});
  ASSERT_TRUE(a.ok() && b.ok());
  a.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
  const std::size_t plane = static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height);
  std::vector<float> chw(3 * plane);
  for (std::size_t p = 0; p < plane; ++p)
    for (std::size_t c = 0; c < 3; ++c) chw[c * plane + p] = 2.0F * static_cast<float>(g.rgb[p * 3 + c]) / 255.0F - 1.0F;
  b.value()->run_planar(chw.data());
  double max_abs = 0;
  const std::size_t n = 7 * plane;
  for (std::size_t i = 0; i < n; ++i)
    max_abs = std::max(max_abs, static_cast<double>(std::fabs(a.value()->logits()[i] - b.value()->logits()[i])));
  EXPECT_LE(max_abs, 1e-4);
  // and it is a different input from the plain 1/255 one
  const std::vector<float> shifted_logits(a.value()->logits(), a.value()->logits() + n);
  b.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
  double plain_diff = 0;
  for (std::size_t i = 0; i < n; ++i) plain_diff = std::max(plain_diff, static_cast<double>(std::fabs(shifted_logits[i] - b.value()->logits()[i])));
  EXPECT_GT(plain_diff, 1e-2);
}

TEST(Engine, RefusesBadSizesThreadsAndPaths) {
  const test::WeightsRef w{test::fixture_weights()};
  ASSERT_FALSE(w.value().tensors.empty());
  auto odd = ErfNet::create(w.value(), ErfNetOptions{60, 48, 1, KernelPath::kAuto});
  ASSERT_FALSE(odd.ok());
  EXPECT_NE(odd.error().message.find("multiples of 8"), std::string::npos) << odd.error().message;
  auto zero = ErfNet::create(w.value(), ErfNetOptions{64, 48, 0, KernelPath::kAuto});
  ASSERT_FALSE(zero.ok());
  EXPECT_NE(zero.error().message.find("thread"), std::string::npos);
#if defined(__x86_64__)
  auto neon = ErfNet::create(w.value(), ErfNetOptions{64, 48, 1, KernelPath::kNeon});
#else
  auto neon = ErfNet::create(w.value(), ErfNetOptions{64, 48, 1, KernelPath::kAvx2});
#endif
  ASSERT_FALSE(neon.ok());
  EXPECT_NE(neon.error().message.find("not available"), std::string::npos);
  ErfNetWeights broken = w.value();
  broken.tensors.pop_back();
  auto missing = ErfNet::create(broken, ErfNetOptions{64, 48, 1, KernelPath::kAuto});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("decoder.output_conv.bias"), std::string::npos) << missing.error().message;
}

TEST(Engine, MacCountIsTheReferences) {
  // tools/erfnet_reference.py: 12.99 GMAC at 640x400 with 20 classes.
  EXPECT_NEAR(erfnet_macs(640, 400, 20) / 1e9, 12.99, 0.01);
}

}  // namespace
}  // namespace ag::seg

namespace ag::seg {
namespace {

TEST(Numerics, WinogradAndDirectAreDifferentComputationsOfTheSameLogits) {
  const test::WeightsRef w{test::fixture_weights()};
  ASSERT_FALSE(w.value().tensors.empty());
  const test::Crop g = test::crop(test::load_golden("erfnet_random_c7_64x48.golden"), 32, 24);
  auto wino = ErfNet::create(w.value(), ErfNetOptions{g.width, g.height, 1, KernelPath::kAuto, true});
  auto direct = ErfNet::create(w.value(), ErfNetOptions{g.width, g.height, 1, KernelPath::kAuto, false});
  ASSERT_TRUE(wino.ok() && direct.ok());
  EXPECT_TRUE(wino.value()->winograd());
  EXPECT_FALSE(direct.value()->winograd());
  wino.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
  direct.value()->run_rgb8(g.rgb.data(), static_cast<std::size_t>(g.width) * 3);
  double max_abs = 0;
  std::size_t differ = 0;
  const std::size_t n = 7U * 32U * 24U;
  for (std::size_t i = 0; i < n; ++i) {
    const float a = wino.value()->logits()[i], b = direct.value()->logits()[i];
    max_abs = std::max(max_abs, static_cast<double>(std::fabs(a - b)));
    differ += a != b ? 1U : 0U;
  }
  std::printf("winograd vs direct: %zu of %zu logits differ in rounding, max %.2e\n", differ, n, max_abs);
  EXPECT_GT(differ, 0U);  // another summation order: the Winograd path did run
  EXPECT_LE(max_abs, 1e-4);
}

}  // namespace
}  // namespace ag::seg
