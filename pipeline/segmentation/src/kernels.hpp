// The convolution micro-kernels' contract: one output row segment of one 16-channel output group.
// Layout of every activation: [row][channel block][column + padding][8 channels], so one pixel's 8
// channels of a block are contiguous and the pixels of a row follow each other.
#pragma once

#include <cstddef>

namespace ag::seg::detail {

inline constexpr int kBlock = 8;     // channels per block
inline constexpr int kGroup = 16;    // output channels per kernel call (two blocks)
inline constexpr int kMaxTaps = 9;

struct ConvRow {
  const float* taps[kMaxTaps]{};     // input at output column 0, input block 0, one per tap inside the image
  const float* tap_w[kMaxTaps]{};    // that tap's packed weights at input block 0: [8 in][16 out]
  int ntaps{0};
  std::ptrdiff_t in_cb_stride{0};    // [floats] between input channel blocks
  std::ptrdiff_t w_icb_stride{0};    // [floats] between input blocks in the packed weights
  int n_icb{0};
  int in_xstep{0};                   // [floats] at the input between consecutive output columns
  const float* bias{nullptr};        // 16 (BN folded)
  float* out{nullptr};               // output column 0, first of the two output blocks
  std::ptrdiff_t out_cb_stride{0};   // [floats] to the second output block
  int out_xstep{0};                  // [floats] between consecutive output columns
  const float* res{nullptr};         // residual, addressed like out (may be out itself), or null
  bool relu{false};
  int nx{0};                         // output columns
};

using ConvRowFn = void (*)(const ConvRow&) noexcept;

void conv_row_portable(const ConvRow& a) noexcept;
#if defined(__x86_64__)
void conv_row_avx2(const ConvRow& a) noexcept;
#endif
#if defined(__aarch64__)
void conv_row_neon(const ConvRow& a) noexcept;
#endif

}  // namespace ag::seg::detail
