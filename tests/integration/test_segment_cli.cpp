// airground-sim segment as a user runs it: the fixture image through the fixture weights gives the torch
// goldens in logits.npy (within 1e-3) and their argmax in classes.png; odd image sizes are padded and
// cropped back; bad weights and images are refused with exit status 1, bad usage with 2.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "process.hpp"

namespace ag::test {
namespace {

namespace fs = std::filesystem;

std::string sim_bin() { return binary_dir() + "/sim/airground-sim"; }
std::string tmp(const std::string& name) { return (fs::path(::testing::TempDir()) / ("segcli-" + name)).string(); }
std::string data(const std::string& name) { return source_dir() + "/tests/data/segmentation/" + name; }

std::vector<char> slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// The golden: width, height, classes, rgb, logits (tools/erfnet_goldens.py).
struct Golden {
  std::uint32_t w{0}, h{0}, c{0};
  std::vector<std::uint8_t> rgb;
  std::vector<float> logits;
};
Golden golden() {
  const std::vector<char> b = slurp(data("erfnet_random_c7_64x48.golden"));
  Golden g;
  if (b.size() < 20) return g;
  std::memcpy(&g.w, b.data() + 8, 4);
  std::memcpy(&g.h, b.data() + 12, 4);
  std::memcpy(&g.c, b.data() + 16, 4);
  const std::size_t px = std::size_t{g.w} * g.h;
  g.rgb.assign(b.begin() + 20, b.begin() + static_cast<std::ptrdiff_t>(20 + 3 * px));
  g.logits.resize(px * g.c);
  std::memcpy(g.logits.data(), b.data() + 20 + 3 * px, g.logits.size() * 4);
  return g;
}

// A float32 C-order .npy: its shape string and data.
bool read_npy(const std::string& p, std::string& header, std::vector<float>& v) {
  const std::vector<char> b = slurp(p);
  if (b.size() < 10 || std::memcmp(b.data(), "\x93NUMPY\x01\x00", 8) != 0) return false;
  std::uint16_t len = 0;
  std::memcpy(&len, b.data() + 8, 2);
  if ((10 + len) % 64 != 0) return false;
  header.assign(b.data() + 10, len);
  v.resize((b.size() - 10 - len) / 4);
  std::memcpy(v.data(), b.data() + 10 + len, v.size() * 4);
  return true;
}

TEST(SegmentCli, GoldenImageGivesTheTorchLogits) {
  const Golden g = golden();
  ASSERT_EQ(g.c, 7U);
  cv::Mat rgb(static_cast<int>(g.h), static_cast<int>(g.w), CV_8UC3, const_cast<std::uint8_t*>(g.rgb.data())), bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  const std::string img = tmp("golden.png"), out = tmp("out");
  ASSERT_TRUE(cv::imwrite(img, bgr));
  fs::remove_all(out);
  const auto r = run({sim_bin(), "segment", "--weights", data("erfnet_random_c7.agw"), "--image", img, "--out", out, "--threads", "2"}, 60);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("segmented in"), std::string::npos) << r.out;
  std::string header;
  std::vector<float> logits;
  ASSERT_TRUE(read_npy(out + "/logits.npy", header, logits));
  EXPECT_NE(header.find("'descr': '<f4'"), std::string::npos) << header;
  EXPECT_NE(header.find("'shape': (7, 48, 64)"), std::string::npos) << header;
  ASSERT_EQ(logits.size(), g.logits.size());
  double max_abs = 0;
  for (std::size_t i = 0; i < logits.size(); ++i) max_abs = std::max(max_abs, static_cast<double>(std::fabs(logits[i] - g.logits[i])));
  EXPECT_LE(max_abs, 1e-3);
  const cv::Mat cls = cv::imread(out + "/classes.png", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(cls.type(), CV_8U);
  ASSERT_EQ(cls.cols, 64);
  const std::size_t plane = std::size_t{g.w} * g.h;
  std::size_t agree = 0;
  for (std::size_t p = 0; p < plane; ++p) {
    std::size_t best = 0;
    for (std::size_t c = 1; c < 7; ++c)
      if (g.logits[c * plane + p] > g.logits[best * plane + p]) best = c;
    agree += cls.data[p] == best ? 1U : 0U;
  }
  EXPECT_GE(static_cast<double>(agree) / static_cast<double>(plane), 0.999);
  EXPECT_TRUE(fs::exists(out + "/classes_colour.png"));
}

TEST(SegmentCli, OddSizesArePaddedAndCroppedBack) {
  const Golden g = golden();
  cv::Mat rgb(static_cast<int>(g.h), static_cast<int>(g.w), CV_8UC3, const_cast<std::uint8_t*>(g.rgb.data()));
  const cv::Mat odd = rgb(cv::Rect(0, 0, 61, 45)).clone();
  const std::string img = tmp("odd.png"), out = tmp("odd");
  ASSERT_TRUE(cv::imwrite(img, odd));
  const auto r = run({sim_bin(), "segment", "--weights", data("erfnet_random_c7.agw"), "--image", img, "--out", out}, 60);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("padded to 64x48"), std::string::npos) << r.out;
  std::string header;
  std::vector<float> logits;
  ASSERT_TRUE(read_npy(out + "/logits.npy", header, logits));
  EXPECT_NE(header.find("(7, 45, 61)"), std::string::npos) << header;
  EXPECT_EQ(logits.size(), 7U * 45U * 61U);
  EXPECT_EQ(cv::imread(out + "/classes.png", cv::IMREAD_UNCHANGED).cols, 61);
}

TEST(SegmentCli, BadInputsAreRefused) {
  EXPECT_EQ(run({sim_bin(), "segment", "--help"}).exit_code, 0);
  EXPECT_EQ(run({sim_bin(), "segment", "--weights", "x"}).exit_code, 2);
  EXPECT_EQ(run({sim_bin(), "segment", "--weights", "x", "--image", "y", "--out", "z", "--threads", "0"}).exit_code, 2);
  const std::string garbage = tmp("garbage.agw");
  {
    std::ofstream f(garbage, std::ios::binary);
    f << "AGERFNET but nothing after";
  }
  const auto bad_w = run({sim_bin(), "segment", "--weights", garbage, "--image", garbage, "--out", tmp("bad")});
  EXPECT_EQ(bad_w.exit_code, 1);
  EXPECT_NE(bad_w.err.find(garbage), std::string::npos) << bad_w.err;
  const auto bad_img = run({sim_bin(), "segment", "--weights", data("erfnet_random_c7.agw"), "--image", garbage, "--out", tmp("bad")});
  EXPECT_EQ(bad_img.exit_code, 1);
  EXPECT_NE(bad_img.err.find("cannot read the image"), std::string::npos) << bad_img.err;
}

}  // namespace
}  // namespace ag::test
