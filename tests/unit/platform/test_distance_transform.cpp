// The distance transform's row pass (platform/distance_transform.hpp) against brute force: sparse and
// dense sources, float and double, a sub-range of x, no source at all, and the 2-D transform it makes
// with a column pass.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "airground/platform/distance_transform.hpp"

namespace ag::dt {
namespace {

// min over sources q of (x - q)^2 + f[q], or -1 without a source.
double brute(const std::vector<int>& f, const std::vector<char>& src, int x) {
  double best = -1;
  for (std::size_t q = 0; q < f.size(); ++q)
    if (src[q] != 0) {
      const double d = static_cast<double>((x - static_cast<int>(q)) * (x - static_cast<int>(q)) + f[q]);
      if (best < 0 || d < best) best = d;
    }
  return best;
}

template <typename Scalar>
void check_random_lines(std::uint32_t seed) {
  std::mt19937 rng(seed);
  EnvelopeScratch<Scalar> s(300);
  int lines = 0, emitted = 0;
  for (int t = 0; t < 400; ++t) {
    const int n = 1 + static_cast<int>(rng() % 300);
    std::vector<int> f(static_cast<std::size_t>(n));
    std::vector<char> src(static_cast<std::size_t>(n));
    const unsigned density = 1 + rng() % 8;  // one sample in `density` is a source
    for (int q = 0; q < n; ++q) {
      f[static_cast<std::size_t>(q)] = static_cast<int>(rng() % 40) * static_cast<int>(rng() % 40);
      src[static_cast<std::size_t>(q)] = rng() % density == 0 ? 1 : 0;
    }
    const int x0 = static_cast<int>(rng() % static_cast<unsigned>(n)), x1 = x0 + static_cast<int>(rng() % static_cast<unsigned>(n - x0 + 1));
    std::vector<double> got(static_cast<std::size_t>(n), -2);
    const bool any = squared_distance_line(
        n, [&](std::int32_t q) { return src[static_cast<std::size_t>(q)] != 0; },
        [&](std::int32_t q) { return static_cast<Scalar>(f[static_cast<std::size_t>(q)]); }, x0, x1, s,
        [&](std::int32_t x, Scalar d2) { got[static_cast<std::size_t>(x)] = static_cast<double>(d2); });
    const bool has_source = std::any_of(src.begin(), src.end(), [](char c) { return c != 0; });
    ASSERT_EQ(any, has_source) << "line " << t;
    ++lines;
    for (int x = 0; x < n; ++x) {
      if (!has_source || x < x0 || x >= x1) {
        EXPECT_EQ(got[static_cast<std::size_t>(x)], -2) << "emitted outside [x0, x1) or without a source, line " << t << " x " << x;
        continue;
      }
      ++emitted;
      ASSERT_EQ(got[static_cast<std::size_t>(x)], brute(f, src, x)) << "line " << t << " x " << x << " n " << n;
    }
  }
  EXPECT_EQ(lines, 400);
  EXPECT_GT(emitted, 10000);
}

TEST(DistanceTransform, ARowPassEqualsBruteForceInDouble) { check_random_lines<double>(1); }
TEST(DistanceTransform, ARowPassEqualsBruteForceInFloat) { check_random_lines<float>(2); }

// Column pass (vertical distance to a feature) + the row pass = the exact 2-D squared distance.
TEST(DistanceTransform, WithAColumnPassItIsTheExactTwoDimensionalTransform) {
  constexpr int W = 61, H = 47;
  auto at = [](int c, int r) { return static_cast<std::size_t>(r * W + c); };
  std::mt19937 rng(7);
  std::vector<char> feature(W * H, 0);
  for (int i = 0; i < 25; ++i) feature[rng() % (W * H)] = 1;
  constexpr int kNone = 1 << 20;
  std::vector<int> col(W * H, kNone);
  for (int c = 0; c < W; ++c)
    for (int r = 0; r < H; ++r)
      for (int rr = 0; rr < H; ++rr)
        if (feature[at(c, rr)] != 0) col[at(c, r)] = std::min(col[at(c, r)], std::abs(rr - r));
  EnvelopeScratch<double> s(W);
  int checked = 0;
  for (int r = 0; r < H; ++r) {
    squared_distance_line(
        W, [&](std::int32_t q) { return col[at(q, r)] < kNone; },
        [&](std::int32_t q) { return static_cast<double>(col[at(q, r)]) * col[at(q, r)]; }, 0, W, s, [&](std::int32_t c, double d2) {
          int best = std::numeric_limits<int>::max();
          for (int fr = 0; fr < H; ++fr)
            for (int fc = 0; fc < W; ++fc)
              if (feature[at(fc, fr)] != 0) best = std::min(best, (fc - c) * (fc - c) + (fr - r) * (fr - r));
          EXPECT_EQ(d2, static_cast<double>(best)) << "cell " << c << ", " << r;
          ++checked;
        });
  }
  EXPECT_EQ(checked, W * H);
}

}  // namespace
}  // namespace ag::dt
