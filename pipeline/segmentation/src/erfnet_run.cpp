// ErfNet's per-frame work: the input conversion, then per op one work item per output row (and channel
// group, or Winograd pair) on the thread pool, then the argmax.
#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "erfnet_internal.hpp"

namespace ag::seg {
using detail::ConvRow;
using detail::first_of_pair;
using detail::kWinoChunk;
using detail::OpKind;
using detail::pair_count;
using detail::PoolOp;

namespace {

// One channel block as a GCC vector (AVX on x86-64-v3, two q registers on NEON, SSE pairs otherwise): the
// Winograd transforms are plain arithmetic on whole blocks.
typedef float V8 __attribute__((vector_size(32), aligned(4)));  // NOLINT(modernize-use-using)
inline V8 ld8(const float* p) noexcept { return *reinterpret_cast<const V8*>(p); }
inline void st8(float* p, V8 v) noexcept { *reinterpret_cast<V8*>(p) = v; }

void conv_item(void* ctx, int item, int thread) noexcept {
  auto& im = *static_cast<ErfNet::Impl*>(ctx);
  const ConvOp& c = im.cur->conv;
  const Act& in = *c.in;
  const int oy = item / c.n_ocp, g = item % c.n_ocp;
  const float* w = im.packed.get() + c.w_offset +
                   static_cast<std::size_t>(g) * static_cast<std::size_t>(in.cb) * static_cast<std::size_t>(c.ntaps) * kBlock * kGroup;
  ConvRow r;
  for (int t = 0; t < c.ntaps; ++t) {
    const int iy = c.sy * oy + c.dy[t];
    if (iy < 0 || iy >= in.h) continue;
    r.taps[r.ntaps] = in.data + iy * in.row_stride + static_cast<std::ptrdiff_t>(in.pad + c.dx[t]) * kBlock;
    r.tap_w[r.ntaps] = w + static_cast<std::ptrdiff_t>(t) * kBlock * kGroup;
    ++r.ntaps;
  }
  r.in_cb_stride = in.cb_stride;
  r.w_icb_stride = static_cast<std::ptrdiff_t>(c.ntaps) * kBlock * kGroup;
  r.n_icb = in.cb;
  r.in_xstep = c.sx * kBlock;
  r.bias = im.packed.get() + c.b_offset + static_cast<std::size_t>(g) * kGroup;
  r.relu = c.relu;
  r.nx = c.ow;
  if (!c.to_logits) {
    const Act& out = *c.out;
    r.out = out.at(oy * c.ry + c.py, c.ocb_begin + 2 * g, c.px);
    r.out_cb_stride = out.cb_stride;
    r.out_xstep = c.rx * kBlock;
    r.res = c.residual ? r.out : nullptr;
    im.conv_fn(r);
    return;
  }
  float* s = im.scratch.get() + static_cast<std::size_t>(thread) * im.scratch_stride;
  r.out = s;
  r.out_cb_stride = kBlock;
  r.out_xstep = kGroup;
  im.conv_fn(r);
  const int n = std::min(kGroup, c.n_out - g * kGroup);
  const std::size_t plane = static_cast<std::size_t>(im.width) * static_cast<std::size_t>(im.height);
  const std::size_t row = static_cast<std::size_t>(oy * 2 + c.py) * static_cast<std::size_t>(im.width);
  for (int o = 0; o < n; ++o) {
    float* dst = im.logits.get() + static_cast<std::size_t>(g * kGroup + o) * plane + row + static_cast<std::size_t>(c.px);
    for (int x = 0; x < c.ow; ++x) dst[2 * x] = s[x * kGroup + o];
  }
}

// Runs the four products M_k = G_k U_k of one 16-channel group over `cols` columns of U, into M.
void wino_products(ErfNet::Impl& im, const ConvOp& c, int g, const float* u, std::ptrdiff_t u_cb_stride, std::ptrdiff_t u_k_stride,
                   float* m, int cols) noexcept {
  static constexpr float kZero[kGroup] = {};
  const float* w = im.packed.get() + c.w_offset + static_cast<std::size_t>(g) * static_cast<std::size_t>(c.in->cb) * 4 * kBlock * kGroup;
  for (int k = 0; k < 4; ++k) {
    ConvRow r;
    r.ntaps = 1;
    r.taps[0] = u + k * u_k_stride;
    r.tap_w[0] = w + static_cast<std::ptrdiff_t>(k) * kBlock * kGroup;
    r.in_cb_stride = u_cb_stride;
    r.w_icb_stride = 4 * kBlock * kGroup;
    r.n_icb = c.in->cb;
    r.in_xstep = kBlock;
    r.bias = kZero;
    r.out = m + static_cast<std::ptrdiff_t>(k) * kWinoChunk * kGroup;
    r.out_cb_stride = kBlock;
    r.out_xstep = kGroup;
    r.relu = false;
    r.nx = cols;
    im.conv_fn(r);
  }
}

// One output pair from the products: y0 = M0 + M1 + M2 + b at o0, y1 = M1 - M2 - M3 + b at o1; then the
// residual and ReLU. Branch-free inner loops over the 8 lanes of a block, so the compiler vectorises them.
template <bool Res, bool Relu, bool Second>
inline void wino_store(const float* m, const float* bias, float* o0, float* o1, std::ptrdiff_t cb_stride) noexcept {
  constexpr std::ptrdiff_t mk = static_cast<std::ptrdiff_t>(kWinoChunk) * kGroup;
  const V8 zero = {};
  for (int h = 0; h < 2; ++h) {
    const float* q = m + h * kBlock;
    const V8 b = ld8(bias + h * kBlock), m1 = ld8(q + mk), m2 = ld8(q + 2 * mk);
    V8 y0 = ld8(q) + m1 + m2 + b;
    if constexpr (Res) y0 += ld8(o0 + h * cb_stride);
    if constexpr (Relu) y0 = y0 > zero ? y0 : zero;
    st8(o0 + h * cb_stride, y0);
    if constexpr (Second) {
      V8 y1 = m1 - m2 - ld8(q + 3 * mk) + b;
      if constexpr (Res) y1 += ld8(o1 + h * cb_stride);
      if constexpr (Relu) y1 = y1 > zero ? y1 : zero;
      st8(o1 + h * cb_stride, y1);
    }
  }
}

template <bool Res, bool Relu>
inline void wino_store_pair(const float* m, const float* bias, float* o0, float* o1, std::ptrdiff_t cb_stride) noexcept {
  if (o1) wino_store<Res, Relu, true>(m, bias, o0, o1, cb_stride);
  else wino_store<Res, Relu, false>(m, bias, o0, o1, cb_stride);
}

inline void wino_store_any(const ConvOp& c, const float* m, const float* bias, float* o0, float* o1, std::ptrdiff_t cb_stride) noexcept {
  if (c.residual) {
    if (c.relu) wino_store_pair<true, true>(m, bias, o0, o1, cb_stride);
    else wino_store_pair<true, false>(m, bias, o0, o1, cb_stride);
  } else {
    if (c.relu) wino_store_pair<false, true>(m, bias, o0, o1, cb_stride);
    else wino_store_pair<false, false>(m, bias, o0, o1, cb_stride);
  }
}

// Vertical (3x1) Winograd: one item is the pair of rows (y, y + d).
void wino_v_item(void* ctx, int item, int thread) noexcept {
  auto& im = *static_cast<ErfNet::Impl*>(ctx);
  const ConvOp& c = im.cur->conv;
  const Act& in = *c.in;
  const Act& out = *c.out;
  const int d = c.dilation, y = first_of_pair(item, d), W = in.w;
  float* u = im.wscratch.get() + static_cast<std::size_t>(thread) * im.wscratch_stride;
  float* m = u + im.wscratch_m_offset;
  const std::ptrdiff_t ucb = static_cast<std::ptrdiff_t>(W) * kBlock, uk = ucb * in.cb;
  const float* zero = im.zero_row.get();
  auto row = [&](int r, int b) -> const float* { return r >= 0 && r < in.h ? in.at(r, b, 0) : zero; };
  for (int b = 0; b < in.cb; ++b) {
    const float* __restrict d0 = row(y - d, b);
    const float* __restrict d1 = row(y, b);
    const float* __restrict d2 = row(y + d, b);
    const float* __restrict d3 = row(y + 2 * d, b);
    float* __restrict u0 = u + b * ucb;
    float* __restrict u1 = u0 + uk;
    float* __restrict u2 = u1 + uk;
    float* __restrict u3 = u2 + uk;
    const int n = W * kBlock;
    for (int k = 0; k < n; k += kBlock) {
      const V8 a0 = ld8(d0 + k), a1 = ld8(d1 + k), a2 = ld8(d2 + k), a3 = ld8(d3 + k);
      st8(u0 + k, a0 - a2);
      st8(u1 + k, a1 + a2);
      st8(u2 + k, a2 - a1);
      st8(u3 + k, a1 - a3);
    }
  }
  const bool second = y + d < out.h;
  for (int g = 0; g < c.n_ocp; ++g) {
    const float* bias = im.packed.get() + c.b_offset + static_cast<std::size_t>(g) * kGroup;
    for (int x0 = 0; x0 < W; x0 += kWinoChunk) {
      const int n = std::min(kWinoChunk, W - x0);
      wino_products(im, c, g, u + x0 * kBlock, ucb, uk, m, n);
      for (int x = 0; x < n; ++x)
        wino_store_any(c, m + x * kGroup, bias, out.at(y, 2 * g, x0 + x), second ? out.at(y + d, 2 * g, x0 + x) : nullptr, out.cb_stride);
    }
  }
}

// Horizontal (1x3) Winograd: one item is a row; the pairs are columns (x, x + d).
void wino_h_item(void* ctx, int y, int thread) noexcept {
  auto& im = *static_cast<ErfNet::Impl*>(ctx);
  const ConvOp& c = im.cur->conv;
  const Act& in = *c.in;
  const Act& out = *c.out;
  const int d = c.dilation, J = pair_count(out.w, d);
  float* u = im.wscratch.get() + static_cast<std::size_t>(thread) * im.wscratch_stride;
  float* m = u + im.wscratch_m_offset;
  const std::ptrdiff_t ucb = static_cast<std::ptrdiff_t>(J) * kBlock, uk = ucb * in.cb;
  const std::ptrdiff_t dd = static_cast<std::ptrdiff_t>(d) * kBlock;
  for (int b = 0; b < in.cb; ++b) {
    const float* src = in.at(y, b, 0);  // zero padding of at least 2d columns on both sides
    float* u0 = u + b * ucb;
    int j = 0;
    for (int x1 = 0; j < J; x1 += 2 * d) {  // runs of d consecutive first-of-pair columns
      for (int x = x1; x < x1 + d && j < J; ++x, ++j) {
        const float* p = src + x * kBlock;
        float* q = u0 + j * kBlock;
        const V8 a0 = ld8(p - dd), a1 = ld8(p), a2 = ld8(p + dd), a3 = ld8(p + 2 * dd);
        st8(q, a0 - a2);
        st8(q + uk, a1 + a2);
        st8(q + 2 * uk, a2 - a1);
        st8(q + 3 * uk, a1 - a3);
      }
    }
  }
  for (int g = 0; g < c.n_ocp; ++g) {
    const float* bias = im.packed.get() + c.b_offset + static_cast<std::size_t>(g) * kGroup;
    for (int j0 = 0; j0 < J; j0 += kWinoChunk) {
      const int n = std::min(kWinoChunk, J - j0);
      wino_products(im, c, g, u + j0 * kBlock, ucb, uk, m, n);
      for (int j = 0; j < n; ++j) {
        const int x = first_of_pair(j0 + j, d);
        wino_store_any(c, m + j * kGroup, bias, out.at(y, 2 * g, x), x + d < out.w ? out.at(y, 2 * g, x + d) : nullptr, out.cb_stride);
      }
    }
  }
}

void pool_item(void* ctx, int y, int /*thread*/) noexcept {
  auto& im = *static_cast<ErfNet::Impl*>(ctx);
  const PoolOp& p = im.cur->pool;
  const Act& in = *p.in;
  const Act& out = *p.out;
  const float* scale = im.packed.get() + p.scale_offset;
  const float* shift = scale + in.channels;
  for (int c = 0; c < in.channels; ++c) {
    const int b = c / kBlock, l = c % kBlock;
    const int oc = p.c0 + c;
    const float* r0 = in.at(2 * y, b, 0) + l;
    const float* r1 = in.at(2 * y + 1, b, 0) + l;
    float* o = out.at(y, oc / kBlock, 0) + oc % kBlock;
    for (int x = 0; x < out.w; ++x) {
      const int k0 = 2 * x * kBlock, k1 = (2 * x + 1) * kBlock;
      const float m = std::max(std::max(r0[k0], r0[k1]), std::max(r1[k0], r1[k1]));
      o[x * kBlock] = std::max(0.0F, m * scale[c] + shift[c]);
    }
  }
}

void input_rgb8_item(void* ctx, int y, int) noexcept {
  auto& im = *static_cast<ErfNet::Impl*>(ctx);
  const std::uint8_t* src = im.rgb + static_cast<std::size_t>(y) * im.rgb_stride;
  float* dst = im.input.at(y, 0, 0);
  for (int x = 0; x < im.width; ++x)
    for (int c = 0; c < 3; ++c) dst[x * kBlock + c] = static_cast<float>(src[3 * x + c]) * im.norm_scale[c] + im.norm_shift[c];
}

void input_planar_item(void* ctx, int y, int) noexcept {
  auto& im = *static_cast<ErfNet::Impl*>(ctx);
  const std::size_t plane = static_cast<std::size_t>(im.width) * static_cast<std::size_t>(im.height);
  float* dst = im.input.at(y, 0, 0);
  for (int c = 0; c < 3; ++c) {
    const float* src = im.planar + static_cast<std::size_t>(c) * plane + static_cast<std::size_t>(y) * static_cast<std::size_t>(im.width);
    for (int x = 0; x < im.width; ++x) dst[x * kBlock + c] = src[x];
  }
}

void argmax_item(void* ctx, int y, int thread) noexcept {
  auto& im = *static_cast<ErfNet::Impl*>(ctx);
  const std::size_t plane = static_cast<std::size_t>(im.width) * static_cast<std::size_t>(im.height);
  const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(im.width);
  float* best = im.best.get() + static_cast<std::size_t>(thread) * static_cast<std::size_t>(im.width);
  std::uint8_t* cls = im.classes_buf.data() + row;
  const float* l0 = im.logits.get() + row;
  for (int x = 0; x < im.width; ++x) {
    best[x] = l0[x];
    cls[x] = 0;
  }
  for (int c = 1; c < im.classes; ++c) {
    const float* l = im.logits.get() + static_cast<std::size_t>(c) * plane + row;
    for (int x = 0; x < im.width; ++x) {
      if (l[x] > best[x]) {
        best[x] = l[x];
        cls[x] = static_cast<std::uint8_t>(c);
      }
    }
  }
}

void run_ops(ErfNet::Impl& im) noexcept {
  for (const Op& op : im.ops) {
    im.cur = &op;
    switch (op.kind) {
      case OpKind::kConv: im.pool->run(op.conv.oh * op.conv.n_ocp, conv_item, &im); break;
      case OpKind::kPool: im.pool->run(op.pool.out->h, pool_item, &im); break;
      case OpKind::kWinoV: im.pool->run(op.conv.n_items, wino_v_item, &im); break;
      case OpKind::kWinoH: im.pool->run(op.conv.n_items, wino_h_item, &im); break;
    }
  }
  im.pool->run(im.height, argmax_item, &im);
}

}  // namespace

void ErfNet::run_rgb8(const std::uint8_t* rgb, std::size_t stride_bytes) noexcept {
  impl_->rgb = rgb;
  impl_->rgb_stride = stride_bytes;
  impl_->pool->run(impl_->height, input_rgb8_item, impl_.get());
  run_ops(*impl_);
}

void ErfNet::run_planar(const float* chw) noexcept {
  impl_->planar = chw;
  impl_->pool->run(impl_->height, input_planar_item, impl_.get());
  run_ops(*impl_);
}

}  // namespace ag::seg
