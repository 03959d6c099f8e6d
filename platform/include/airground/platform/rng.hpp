// Deterministic random numbers, one implementation for the whole tree (the simulator's models, the
// localizer's particle filter): the same seed gives the same stream on every platform and library.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "airground/platform/time.hpp"

namespace ag {

// splitmix64 (Steele, Lea, Flood 2014): expands one 64-bit seed into well-mixed state words.
[[nodiscard]] constexpr std::uint64_t splitmix64(std::uint64_t& state) noexcept {
  state += 0x9E3779B97F4A7C15ULL;
  std::uint64_t z = state;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// An independent seed for sub-stream `stream` of `seed` (per robot, per sensor, per process).
[[nodiscard]] constexpr std::uint64_t derive_seed(std::uint64_t seed, std::uint64_t stream) noexcept {
  std::uint64_t s = seed ^ (0xD1B54A32D192ED03ULL * (stream + 1));
  (void)splitmix64(s);
  return splitmix64(s);
}

// xoshiro256** (Blackman, Vigna 2018) with our own distributions: std:: distributions are not specified
// bit-for-bit and differ across standard libraries, which would break seeded mission repeatability.
class Rng {
 public:
  explicit constexpr Rng(std::uint64_t seed) noexcept {
    std::uint64_t sm = seed;
    for (auto& w : s_) w = splitmix64(sm);
  }

  [[nodiscard]] constexpr std::uint64_t next_u64() noexcept {
    const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return result;
  }

  // Uniform in [0, 1) with 53 random bits.
  [[nodiscard]] double uniform() noexcept { return static_cast<double>(next_u64() >> 11) * 0x1.0p-53; }
  [[nodiscard]] double uniform(double lo, double hi) noexcept { return lo + (hi - lo) * uniform(); }
  // Uniform integer in [0, n), n > 0 (rejection below the largest multiple of n: no modulo bias).
  [[nodiscard]] std::uint64_t below(std::uint64_t n) noexcept {
    const std::uint64_t threshold = (0 - n) % n;  // 2^64 mod n
    for (;;) {
      const std::uint64_t r = next_u64();
      if (r >= threshold) return r % n;
    }
  }
  [[nodiscard]] bool bernoulli(double p) noexcept { return uniform() < p; }

  // Standard normal by Box-Muller; the second value of each pair is kept for the next call.
  [[nodiscard]] double gaussian() noexcept {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    const double a = 2.0 * 3.14159265358979323846 * u2;
    spare_ = r * std::sin(a);
    has_spare_ = true;
    return r * std::cos(a);
  }
  [[nodiscard]] double gaussian(double mean, double sigma) noexcept { return mean + sigma * gaussian(); }

  // Exponential with the given rate [1/unit] (mean 1/rate); +inf for rate <= 0 ("never").
  [[nodiscard]] double exponential(double rate) noexcept {
    if (!(rate > 0.0)) return std::numeric_limits<double>::infinity();
    return -std::log1p(-uniform()) / rate;
  }

 private:
  static constexpr std::uint64_t rotl(std::uint64_t x, int k) noexcept { return (x << k) | (x >> (64 - k)); }

  std::uint64_t s_[4]{};
  double spare_{0.0};
  bool has_spare_{false};
};

// t + s seconds for event times drawn from exponential(): saturates at the largest TimeNs ("never").
[[nodiscard]] inline TimeNs time_after(TimeNs t, double s) noexcept {
  constexpr double kMaxNs = 9.0e18;
  const double ns = s * 1e9;
  if (!(ns < kMaxNs - static_cast<double>(t))) return std::numeric_limits<TimeNs>::max();
  return t + static_cast<TimeNs>(ns);
}

}  // namespace ag
