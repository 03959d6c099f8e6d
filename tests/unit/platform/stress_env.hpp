// Shared by the two-thread stress tests: the item count (AG_STRESS_ITEMS) and a polite spin-wait.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <thread>

namespace ag::test {

// AG_STRESS_ITEMS overrides the default so slow runs (qemu, ThreadSanitizer) can use fewer items.
inline std::uint64_t stress_items(std::uint64_t default_items) {
  const char* env = std::getenv("AG_STRESS_ITEMS");
  if (env == nullptr || *env == '\0') return default_items;
  char* end = nullptr;
  const unsigned long long v = std::strtoull(env, &end, 10);
  return (end != nullptr && *end == '\0' && v > 0) ? static_cast<std::uint64_t>(v) : default_items;
}

// Busy-waits briefly, then yields: the machines running these have few cores shared with other jobs,
// and a pure spin would starve the other side when both land on one core.
class Backoff {
 public:
  void pause() noexcept {
    if (++spins_ < 256) {
#if defined(__x86_64__) || defined(__i386__)
      __builtin_ia32_pause();
#elif defined(__aarch64__)
      asm volatile("yield" ::: "memory");
#endif
    } else {
      spins_ = 0;
      std::this_thread::yield();
    }
  }
  void reset() noexcept { spins_ = 0; }

 private:
  unsigned spins_{0};
};

// splitmix64 finaliser: a different-looking payload for every index, so stale or torn slots show.
constexpr std::uint64_t mix(std::uint64_t x) noexcept {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

}  // namespace ag::test
