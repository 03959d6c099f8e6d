// Calibration workload: integer sort, float stencil and pointer chasing, the mix our stages do.
#include "airground/platform/calibration.hpp"

#include <algorithm>
#include <array>
#include <vector>

#include "airground/platform/clock.hpp"

namespace ag {

std::uint64_t calibration_workload() noexcept {
  constexpr std::size_t kN = 1 << 15;
  static std::vector<std::uint32_t> keys(kN);
  static std::vector<float> img(256 * 256);
  static std::vector<std::uint32_t> next(kN);
  // Integer sort of pseudo-random keys (xorshift, fixed seed).
  std::uint32_t x = 2463534242u;
  for (auto& k : keys) {
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    k = x;
  }
  std::sort(keys.begin(), keys.end());
  // A 3x3 float stencil, like filtering an image row by row.
  for (std::size_t i = 0; i < img.size(); ++i) img[i] = static_cast<float>((i * 2654435761u) & 0xff);
  float acc = 0.f;
  for (int pass = 0; pass < 4; ++pass)
    for (std::size_t r = 1; r < 255; ++r)
      for (std::size_t c = 1; c < 255; ++c) {
        const std::size_t i = r * 256 + c;
        const float v = 0.25f * img[i] + 0.125f * (img[i - 1] + img[i + 1] + img[i - 256] + img[i + 256]) +
                        0.0625f * (img[i - 257] + img[i - 255] + img[i + 255] + img[i + 257]);
        img[i] = v;
        acc += v;
      }
  // Pointer chasing through a random cycle: cache-miss bound like map lookups.
  for (std::size_t i = 0; i < kN; ++i) next[i] = static_cast<std::uint32_t>(i);
  for (std::size_t i = kN - 1; i > 0; --i) std::swap(next[i], next[keys[i] % i]);
  std::uint32_t p = 0;
  std::uint64_t sum = 0;
  for (std::size_t i = 0; i < 4 * kN; ++i) {
    p = next[p];
    sum += p;
  }
  return sum + keys[kN / 2] + static_cast<std::uint64_t>(acc);
}

Calibration calibrate(int runs) noexcept {
  std::array<TimeNs, 31> t{};
  runs = std::clamp(runs, 1, 31);
  volatile std::uint64_t sink = calibration_workload();  // warm caches and the static buffers
  for (int i = 0; i < runs; ++i) {
    const TimeNs a = thread_cpu_now();
    sink = sink + calibration_workload();
    t[static_cast<std::size_t>(i)] = thread_cpu_now() - a;
  }
  std::sort(t.begin(), t.begin() + runs);
  const TimeNs median = t[static_cast<std::size_t>(runs / 2)];
  return Calibration{median, static_cast<double>(median) / static_cast<double>(kCalibrationReferenceNs)};
}

}  // namespace ag
