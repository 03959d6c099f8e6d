// The NEON micro-kernel (aarch64, where Advanced SIMD is part of the base ISA): 4 output columns x 16
// output channels in 16 q-register accumulators; per input channel four weight loads and four
// broadcast loads feed sixteen FMAs.
#if defined(__aarch64__)
#include <arm_neon.h>

#include "kernels.hpp"

namespace ag::seg::detail {
namespace {

template <int T>
inline __attribute__((always_inline)) void tile(const ConvRow& a, int x0) noexcept {
  float32x4_t acc[static_cast<std::size_t>(T)][4];
  float32x4_t b[4];
  for (int k = 0; k < 4; ++k) b[k] = vld1q_f32(a.bias + 4 * k);
#pragma GCC unroll 8
  for (int p = 0; p < T; ++p)
    for (int k = 0; k < 4; ++k) acc[p][k] = b[k];
  const std::ptrdiff_t xin = static_cast<std::ptrdiff_t>(x0) * a.in_xstep;
  const int xs = a.in_xstep;
  for (int c = 0; c < a.n_icb; ++c) {
    for (int t = 0; t < a.ntaps; ++t) {
      const float* ip = a.taps[t] + c * a.in_cb_stride + xin;
      const float* wp = a.tap_w[t] + c * a.w_icb_stride;
#pragma GCC unroll 8
      for (int i = 0; i < kBlock; ++i) {
        float32x4_t w[4];
        for (int k = 0; k < 4; ++k) w[k] = vld1q_f32(wp + i * kGroup + 4 * k);
#pragma GCC unroll 8
        for (int p = 0; p < T; ++p) {
          const float32x4_t v = vld1q_dup_f32(ip + p * xs + i);
          for (int k = 0; k < 4; ++k) acc[p][k] = vfmaq_f32(acc[p][k], v, w[k]);
        }
      }
    }
  }
  const float32x4_t zero = vdupq_n_f32(0.0F);
#pragma GCC unroll 8
  for (int p = 0; p < T; ++p) {
    const std::ptrdiff_t off = static_cast<std::ptrdiff_t>(x0 + p) * a.out_xstep;
    for (int k = 0; k < 4; ++k) {
      const std::ptrdiff_t o = off + (k >> 1) * a.out_cb_stride + 4 * (k & 1);
      float32x4_t v = acc[p][k];
      if (a.res) v = vaddq_f32(v, vld1q_f32(a.res + o));
      if (a.relu) v = vmaxq_f32(v, zero);
      vst1q_f32(a.out + o, v);
    }
  }
}

}  // namespace

void conv_row_neon(const ConvRow& a) noexcept {
  constexpr int T = 4;
  int x = 0;
  for (; x + T <= a.nx; x += T) tile<T>(a, x);
  switch (a.nx - x) {
    case 3: tile<3>(a, x); break;
    case 2: tile<2>(a, x); break;
    case 1: tile<1>(a, x); break;
    default: break;
  }
}

}  // namespace ag::seg::detail
#endif
