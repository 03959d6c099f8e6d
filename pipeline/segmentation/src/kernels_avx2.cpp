// The AVX2+FMA micro-kernel: 6 output columns x 16 output channels in 12 ymm accumulators; per input
// channel two weight loads and six broadcasts feed twelve FMAs. Compiled for avx2,fma by attribute, so
// it builds without -march flags; ErfNet only calls it when the CPU reports both.
#if defined(__x86_64__)
#include <immintrin.h>

#include "kernels.hpp"

namespace ag::seg::detail {
namespace {

template <int T>
__attribute__((target("avx2,fma"), always_inline)) inline void tile(const ConvRow& a, int x0) noexcept {
  __m256 acc0[static_cast<std::size_t>(T)], acc1[static_cast<std::size_t>(T)];
  const __m256 b0 = _mm256_loadu_ps(a.bias), b1 = _mm256_loadu_ps(a.bias + 8);
#pragma GCC unroll 8
  for (int p = 0; p < T; ++p) {
    acc0[p] = b0;
    acc1[p] = b1;
  }
  const std::ptrdiff_t xin = static_cast<std::ptrdiff_t>(x0) * a.in_xstep;
  const int xs = a.in_xstep;
  for (int c = 0; c < a.n_icb; ++c) {
    for (int t = 0; t < a.ntaps; ++t) {
      const float* ip = a.taps[t] + c * a.in_cb_stride + xin;
      const float* wp = a.tap_w[t] + c * a.w_icb_stride;
#pragma GCC unroll 8
      for (int i = 0; i < kBlock; ++i) {
        const __m256 w0 = _mm256_load_ps(wp + i * kGroup), w1 = _mm256_load_ps(wp + i * kGroup + 8);
#pragma GCC unroll 8
        for (int p = 0; p < T; ++p) {
          const __m256 v = _mm256_broadcast_ss(ip + p * xs + i);
          acc0[p] = _mm256_fmadd_ps(v, w0, acc0[p]);
          acc1[p] = _mm256_fmadd_ps(v, w1, acc1[p]);
        }
      }
    }
  }
  const __m256 zero = _mm256_setzero_ps();
#pragma GCC unroll 8
  for (int p = 0; p < T; ++p) {
    const std::ptrdiff_t off = static_cast<std::ptrdiff_t>(x0 + p) * a.out_xstep;
    __m256 v0 = acc0[p], v1 = acc1[p];
    if (a.res) {
      v0 = _mm256_add_ps(v0, _mm256_loadu_ps(a.res + off));
      v1 = _mm256_add_ps(v1, _mm256_loadu_ps(a.res + off + a.out_cb_stride));
    }
    if (a.relu) {
      v0 = _mm256_max_ps(v0, zero);
      v1 = _mm256_max_ps(v1, zero);
    }
    _mm256_storeu_ps(a.out + off, v0);
    _mm256_storeu_ps(a.out + off + a.out_cb_stride, v1);
  }
}

}  // namespace

__attribute__((target("avx2,fma"))) void conv_row_avx2(const ConvRow& a) noexcept {
  constexpr int T = 6;
  int x = 0;
  for (; x + T <= a.nx; x += T) tile<T>(a, x);
  switch (a.nx - x) {
    case 5: tile<5>(a, x); break;
    case 4: tile<4>(a, x); break;
    case 3: tile<3>(a, x); break;
    case 2: tile<2>(a, x); break;
    case 1: tile<1>(a, x); break;
    default: break;
  }
}

}  // namespace ag::seg::detail
#endif
