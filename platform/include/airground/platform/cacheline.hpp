// The cache-line size we pad to, pinned rather than taken from the ABI-unstable std constant.
#pragma once

#include <cstddef>

namespace ag {
// 64 B on the NUC, the Ryzen and Carmel; adjacent-line prefetch on x86 pairs lines, so rings pad 128.
inline constexpr std::size_t kCacheLine = 64;
inline constexpr std::size_t kFalseSharingRange = 128;
}  // namespace ag
