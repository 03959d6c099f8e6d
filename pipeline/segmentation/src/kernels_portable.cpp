// The portable micro-kernel: plain C++ over the same layout and packing as the SIMD ones (the reference
// the others are tested against, and the path for CPUs with neither AVX2 nor NEON).
#include "kernels.hpp"

namespace ag::seg::detail {
namespace {

template <int T>
void tile(const ConvRow& a, int x0, int nx) noexcept {
  float acc[static_cast<std::size_t>(T)][kGroup];
  for (int p = 0; p < T; ++p)
    for (int o = 0; o < kGroup; ++o) acc[p][o] = a.bias[o];
  const std::ptrdiff_t xin = static_cast<std::ptrdiff_t>(x0) * a.in_xstep;
  for (int c = 0; c < a.n_icb; ++c) {
    for (int t = 0; t < a.ntaps; ++t) {
      const float* ip = a.taps[t] + c * a.in_cb_stride + xin;
      const float* wp = a.tap_w[t] + c * a.w_icb_stride;
      for (int i = 0; i < kBlock; ++i) {
        const float* wi = wp + i * kGroup;
        for (int p = 0; p < nx; ++p) {
          const float v = ip[p * a.in_xstep + i];
          for (int o = 0; o < kGroup; ++o) acc[p][o] += v * wi[o];
        }
      }
    }
  }
  for (int p = 0; p < nx; ++p) {
    const std::ptrdiff_t off = static_cast<std::ptrdiff_t>(x0 + p) * a.out_xstep;
    for (int h = 0; h < 2; ++h) {
      float* o = a.out + off + h * a.out_cb_stride;
      const float* r = a.res ? a.res + off + h * a.out_cb_stride : nullptr;
      for (int k = 0; k < kBlock; ++k) {
        float v = acc[p][h * kBlock + k];
        if (r) v += r[k];
        if (a.relu && v < 0.0F) v = 0.0F;
        o[k] = v;
      }
    }
  }
}

}  // namespace

void conv_row_portable(const ConvRow& a) noexcept {
  constexpr int T = 4;
  int x = 0;
  for (; x + T <= a.nx; x += T) tile<T>(a, x, T);
  if (x < a.nx) tile<T>(a, x, a.nx - x);
}

}  // namespace ag::seg::detail
