// ErfNet's layer graph on our kernels: builds the op list and packed, BN-folded weights at create(),
// and runs it on preallocated activations (see erfnet.hpp). Every convolution is one ConvOp: a list of
// taps (row and column offsets in the input), an input step per output pixel (1, or 2 for the
// downsamplers), and where its output pixels land (every pixel, or one of the 2x2 phases of an
// upsampled map: that is how the transposed convolutions become sub-pixel convolutions).
#include "airground/segmentation/erfnet.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "kernels.hpp"
#include "thread_pool.hpp"

#if defined(__aarch64__) && defined(__linux__)
#include <asm/hwcap.h>
#include <sys/auxv.h>
#endif

namespace ag::seg {
using detail::ConvRow;
using detail::kBlock;
using detail::kGroup;
using detail::kMaxTaps;

namespace {

constexpr double kBnEps = 1e-3;
constexpr int kDilations128[8] = {2, 4, 8, 16, 2, 4, 8, 16};

struct FreeDeleter {
  void operator()(float* p) const noexcept { std::free(p); }
};
using FloatBuf = std::unique_ptr<float, FreeDeleter>;

FloatBuf alloc_floats(std::size_t n) {
  const std::size_t bytes = ((n * sizeof(float) + 63) / 64) * 64;
  auto* p = static_cast<float*>(std::aligned_alloc(64, bytes == 0 ? 64 : bytes));
  if (p == nullptr) return FloatBuf{};
  std::memset(p, 0, bytes);
  return FloatBuf{p};
}

// One activation map: [row][channel block][column + pad][8].
struct Act {
  float* data{nullptr};
  int channels{0}, cb{0}, h{0}, w{0}, pad{0};
  std::ptrdiff_t cb_stride{0}, row_stride{0};
  [[nodiscard]] std::size_t floats() const { return static_cast<std::size_t>(row_stride) * static_cast<std::size_t>(h); }
  [[nodiscard]] float* at(int y, int b, int x) const {
    return data + y * row_stride + b * cb_stride + static_cast<std::ptrdiff_t>(pad + x) * kBlock;
  }
};

struct ConvOp {
  const Act* in{nullptr};
  Act* out{nullptr};
  bool residual{false}, relu{true}, to_logits{false};
  int sy{1}, sx{1};              // input step per output row / column
  int oh{0}, ow{0};              // output grid of this op
  int ry{1}, rx{1}, py{0}, px{0};  // output pixel (oy, ox) lands at (oy * ry + py, ox * rx + px)
  int ocb_begin{0};              // first output channel block written
  int n_ocp{0};                  // 16-channel output groups
  int n_out{0};                  // real output channels (logits: the class count)
  int ntaps{0};
  int dy[kMaxTaps]{}, dx[kMaxTaps]{};
  int dilation{1};               // Winograd ops: the 3-tap conv's dilation
  int n_items{0};                // Winograd ops: work items (pairs of rows, or rows)
  std::size_t w_offset{0}, b_offset{0};  // into the packed weight buffer
};

struct PoolOp {  // 2x2 max-pool of `in`, then the BN affine of those channels and ReLU, into out's channels c0..
  const Act* in{nullptr};
  Act* out{nullptr};
  int c0{0};
  std::size_t scale_offset{0};  // channels floats of scale, then channels floats of shift
};

// kWinoV / kWinoH: a 3x1 / 1x3 convolution by 1-D Winograd F(2,3) (see add_conv1d).
enum class OpKind : std::uint8_t { kConv, kPool, kWinoV, kWinoH };
struct Op {
  OpKind kind{OpKind::kConv};
  ConvOp conv;
  PoolOp pool;
};

struct Bn {
  std::vector<double> scale, shift;
};

}  // namespace

struct ErfNet::Impl {
  int width{0}, height{0}, classes{0};
  KernelPath path{KernelPath::kPortable};
  detail::ConvRowFn conv_fn{detail::conv_row_portable};
  float norm_scale[3]{}, norm_shift[3]{};
  std::unique_ptr<detail::ThreadPool> pool;

  std::vector<FloatBuf> buffers;
  std::size_t bytes{0};
  Act input, x2, t2a, t2b, x4, t4a, t4b, x8, t8a, t8b;
  FloatBuf packed;
  std::vector<float> staging;  // packed weights while building
  std::vector<Op> ops;
  FloatBuf logits, scratch, best;
  bool winograd{true};
  FloatBuf zero_row;                // one row of zeros (all blocks): Winograd's rows above and below the map
  FloatBuf wscratch;                // per thread: Winograd's transformed input U[4] then products M[4]
  std::size_t wscratch_stride{0}, wscratch_m_offset{0};
  std::vector<std::uint8_t> classes_buf;
  std::size_t scratch_stride{0};

  // Per-frame job context, set before each pool.run.
  const Op* cur{nullptr};
  const std::uint8_t* rgb{nullptr};
  std::size_t rgb_stride{0};
  const float* planar{nullptr};

  bool make_act(Act& a, int channels, int h, int w, int pad) {
    a.channels = channels;
    a.cb = (channels + kBlock - 1) / kBlock;
    a.h = h;
    a.w = w;
    a.pad = pad;
    a.cb_stride = static_cast<std::ptrdiff_t>(w + 2 * pad) * kBlock;
    a.row_stride = a.cb_stride * a.cb;
    FloatBuf b = alloc_floats(a.floats());
    if (!b) return false;
    a.data = b.get();
    bytes += a.floats() * sizeof(float);
    buffers.push_back(std::move(b));
    return true;
  }

  std::size_t stage_floats(std::size_t n) {
    const std::size_t off = staging.size();
    staging.resize(off + ((n + 15) / 16) * 16, 0.0F);
    return off;
  }

  // Packs weights(o, i, tap) (already BN-scaled) and bias(o) for op `c` with n_in real input channels.
  template <typename WFn, typename BFn>
  void pack(ConvOp& c, int n_in, int n_icb, WFn&& wfn, BFn&& bfn) {
    const std::size_t per_ocp = static_cast<std::size_t>(n_icb) * static_cast<std::size_t>(c.ntaps) * kBlock * kGroup;
    c.w_offset = stage_floats(per_ocp * static_cast<std::size_t>(c.n_ocp));
    c.b_offset = stage_floats(static_cast<std::size_t>(c.n_ocp) * kGroup);
    for (int g = 0; g < c.n_ocp; ++g) {
      for (int ib = 0; ib < n_icb; ++ib)
        for (int t = 0; t < c.ntaps; ++t)
          for (int ii = 0; ii < kBlock; ++ii)
            for (int oo = 0; oo < kGroup; ++oo) {
              const int o = g * kGroup + oo, i = ib * kBlock + ii;
              const std::size_t k = c.w_offset + static_cast<std::size_t>(g) * per_ocp +
                                    ((static_cast<std::size_t>(ib) * static_cast<std::size_t>(c.ntaps) + static_cast<std::size_t>(t)) * kBlock +
                                     static_cast<std::size_t>(ii)) * kGroup + static_cast<std::size_t>(oo);
              staging[k] = (o < c.n_out && i < n_in) ? static_cast<float>(wfn(o, i, t)) : 0.0F;
            }
      for (int oo = 0; oo < kGroup; ++oo) {
        const int o = g * kGroup + oo;
        staging[c.b_offset + static_cast<std::size_t>(o)] = o < c.n_out ? static_cast<float>(bfn(o)) : 0.0F;
      }
    }
  }
};

namespace {

const float* tensor(const ErfNetWeights& w, const std::string& name) {
  const WeightTensor* t = w.find(name);
  return t ? t->data.data() : nullptr;  // parse_weights guarantees presence and shape
}

Bn fold_bn(const ErfNetWeights& w, const std::string& p, int channels) {
  const float* g = tensor(w, p + ".weight");
  const float* b = tensor(w, p + ".bias");
  const float* m = tensor(w, p + ".running_mean");
  const float* v = tensor(w, p + ".running_var");
  Bn bn;
  bn.scale.resize(static_cast<std::size_t>(channels));
  bn.shift.resize(static_cast<std::size_t>(channels));
  for (std::size_t c = 0; c < static_cast<std::size_t>(channels); ++c) {
    bn.scale[c] = static_cast<double>(g[c]) / std::sqrt(static_cast<double>(v[c]) + kBnEps);
    bn.shift[c] = static_cast<double>(b[c]) - static_cast<double>(m[c]) * bn.scale[c];
  }
  return bn;
}

Bn identity_bn(int channels) {
  Bn bn;
  bn.scale.assign(static_cast<std::size_t>(channels), 1.0);
  bn.shift.assign(static_cast<std::size_t>(channels), 0.0);
  return bn;
}

// A same-resolution, stride-1 convolution (the blocks' 3x1 and 1x3 ones) from weights [o][i][kh][kw].
// Pairs of outputs (p, p + d) along the conv's axis that Winograd computes together: p with p mod 2d < d.
// Columns per Winograd chunk: the four products of one chunk (4 x 48 x 16 floats) stay in L1.
constexpr int kWinoChunk = 48;

// One channel block as a GCC vector (AVX on x86-64-v3, two q registers on NEON, SSE pairs otherwise): the
// Winograd transforms are plain arithmetic on whole blocks.
typedef float V8 __attribute__((vector_size(32), aligned(4)));  // NOLINT(modernize-use-using)
inline V8 ld8(const float* p) noexcept { return *reinterpret_cast<const V8*>(p); }
inline void st8(float* p, V8 v) noexcept { *reinterpret_cast<V8*>(p) = v; }

int first_of_pair(int j, int d) { return (j / d) * 2 * d + j % d; }
int pair_count(int n, int d) {
  int j = 0;
  while (first_of_pair(j, d) < n) ++j;
  return j;
}

void add_conv1d(ErfNet::Impl& im, const ErfNetWeights& w, const Act& in, Act& out, const std::string& conv, const Bn& bn,
                bool vertical, int dilation, bool residual) {
  if (im.winograd) {
    // 1-D Winograd F(2,3): outputs y0 = g0 d0 + g1 d1 + g2 d2 and y1 = g0 d1 + g1 d2 + g2 d3 (inputs d0..d3 at
    // offsets -d, 0, d, 2d) from four products M_k = G_k U_k per pair instead of six:
    //   U = (d0 - d2, d1 + d2, d2 - d1, d1 - d3),  G = (g0, (g0 + g1 + g2) / 2, (g0 - g1 + g2) / 2, g2),
    //   y0 = M0 + M1 + M2,  y1 = M1 - M2 - M3.
    // Each M_k is a channel-mixing product run by the same micro-kernel; bias, residual and ReLU are
    // applied when the pair is written.
    Op op;
    op.kind = vertical ? OpKind::kWinoV : OpKind::kWinoH;
    ConvOp& c = op.conv;
    c.in = &in;
    c.out = &out;
    c.residual = residual;
    c.oh = out.h;
    c.ow = out.w;
    c.n_out = out.channels;
    c.n_ocp = out.channels / kGroup;
    c.ntaps = 4;
    c.dilation = dilation;
    c.n_items = vertical ? pair_count(out.h, dilation) : out.h;
    const float* wt = tensor(w, conv + ".weight");
    const float* bs = tensor(w, conv + ".bias");
    const int ci = in.channels;
    im.pack(c, ci, in.cb,
            [&](int o, int i, int k) {
              const float* g = wt + (o * ci + i) * 3;
              const double g0 = g[0], g1 = g[1], g2 = g[2];
              const double gk = k == 0 ? g0 : k == 1 ? (g0 + g1 + g2) / 2 : k == 2 ? (g0 - g1 + g2) / 2 : g2;
              return gk * bn.scale[static_cast<std::size_t>(o)];
            },
            [&](int o) { return static_cast<double>(bs[o]) * bn.scale[static_cast<std::size_t>(o)] + bn.shift[static_cast<std::size_t>(o)]; });
    // Scratch per thread: U[4][cb][columns][8] and M[4][columns][16].
    const int cols = vertical ? out.w : pair_count(out.w, dilation);
    const std::size_t u = 4 * static_cast<std::size_t>(in.cb) * static_cast<std::size_t>(cols) * kBlock;
    const std::size_t m = 4 * static_cast<std::size_t>(kWinoChunk) * kGroup;
    im.wscratch_m_offset = std::max(im.wscratch_m_offset, u);
    im.wscratch_stride = std::max(im.wscratch_stride, m);  // M's size; the total is fixed after all ops
    im.ops.push_back(op);
    return;
  }
  Op op;
  ConvOp& c = op.conv;
  c.in = &in;
  c.out = &out;
  c.residual = residual;
  c.oh = out.h;
  c.ow = out.w;
  c.n_out = out.channels;
  c.n_ocp = out.channels / kGroup;
  c.ntaps = 3;
  for (int k = 0; k < 3; ++k) {
    (vertical ? c.dy : c.dx)[k] = (k - 1) * dilation;
  }
  const float* wt = tensor(w, conv + ".weight");
  const float* bs = tensor(w, conv + ".bias");
  const int ci = in.channels;
  im.pack(c, ci, in.cb,
          [&](int o, int i, int t) { return static_cast<double>(wt[(o * ci + i) * 3 + t]) * bn.scale[static_cast<std::size_t>(o)]; },
          [&](int o) { return static_cast<double>(bs[o]) * bn.scale[static_cast<std::size_t>(o)] + bn.shift[static_cast<std::size_t>(o)]; });
  im.ops.push_back(op);
}

void add_block(ErfNet::Impl& im, const ErfNetWeights& w, const std::string& p, Act& x, Act& ta, Act& tb, int dilation) {
  const int c = x.channels;
  const Bn id = identity_bn(c), bn1 = fold_bn(w, p + ".bn1", c), bn2 = fold_bn(w, p + ".bn2", c);
  add_conv1d(im, w, x, ta, p + ".conv3x1_1", id, true, 1, false);
  add_conv1d(im, w, ta, tb, p + ".conv1x3_1", bn1, false, 1, false);
  add_conv1d(im, w, tb, ta, p + ".conv3x1_2", id, true, dilation, false);
  add_conv1d(im, w, ta, x, p + ".conv1x3_2", bn2, false, dilation, true);
}

// Downsampler: 3x3 stride-2 conv to (out - in) channels, concatenated with the 2x2 max-pool; BN; ReLU.
void add_down(ErfNet::Impl& im, const ErfNetWeights& w, const std::string& p, const Act& in, int in_channels, Act& out) {
  const int conv_out = out.channels - in_channels;
  const Bn bn = fold_bn(w, p + ".bn", out.channels);
  Op op;
  ConvOp& c = op.conv;
  c.in = &in;
  c.out = &out;
  c.sy = c.sx = 2;
  c.oh = out.h;
  c.ow = out.w;
  c.n_out = conv_out;
  c.n_ocp = (conv_out + kGroup - 1) / kGroup;
  c.ntaps = 9;
  for (int t = 0; t < 9; ++t) {
    c.dy[t] = t / 3 - 1;
    c.dx[t] = t % 3 - 1;
  }
  const float* wt = tensor(w, p + ".conv.weight");
  const float* bs = tensor(w, p + ".conv.bias");
  im.pack(c, in_channels, in.cb,
          [&](int o, int i, int t) { return static_cast<double>(wt[(o * in_channels + i) * 9 + t]) * bn.scale[static_cast<std::size_t>(o)]; },
          [&](int o) { return static_cast<double>(bs[o]) * bn.scale[static_cast<std::size_t>(o)] + bn.shift[static_cast<std::size_t>(o)]; });
  im.ops.push_back(op);
  Op pop;
  pop.kind = OpKind::kPool;
  pop.pool.in = &in;
  pop.pool.out = &out;
  pop.pool.c0 = conv_out;
  pop.pool.scale_offset = im.stage_floats(2 * static_cast<std::size_t>(in_channels));
  for (int k = 0; k < in_channels; ++k) {
    const auto o = static_cast<std::size_t>(conv_out + k);
    im.staging[pop.pool.scale_offset + static_cast<std::size_t>(k)] = static_cast<float>(bn.scale[o]);
    im.staging[pop.pool.scale_offset + static_cast<std::size_t>(in_channels + k)] = static_cast<float>(bn.shift[o]);
  }
  im.ops.push_back(pop);
}

// Transposed conv (ConvTranspose2d weights [in][out][k][k], stride 2) as four sub-pixel convolutions at
// the input resolution, one per output phase (a, b). k = 3 with padding 1, output padding 1: the even
// output 2m takes kernel tap 1 at input m; the odd one 2m+1 takes tap 0 at m+1 and tap 2 at m. k = 2:
// output 2m+a takes tap a at m.
void add_up(ErfNet::Impl& im, const ErfNetWeights& w, const std::string& conv, const Bn& bn, const Act& in, Act* out, int k,
            int n_out, bool relu) {
  const float* wt = tensor(w, conv + ".weight");
  const float* bs = tensor(w, conv + ".bias");
  struct Tap {
    int kk, off;
  };
  std::vector<std::vector<Tap>> phase(2);
  if (k == 3) {
    phase[0] = {{1, 0}};
    phase[1] = {{0, 1}, {2, 0}};
  } else {
    phase[0] = {{0, 0}};
    phase[1] = {{1, 0}};
  }
  const int ci = in.channels;
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b) {
      Op op;
      ConvOp& c = op.conv;
      c.in = &in;
      c.out = out;
      c.to_logits = out == nullptr;
      c.relu = relu;
      c.oh = in.h;
      c.ow = in.w;
      c.ry = c.rx = 2;
      c.py = a;
      c.px = b;
      c.n_out = n_out;
      c.n_ocp = (n_out + kGroup - 1) / kGroup;
      std::vector<int> kys, kxs;
      for (const Tap& ty : phase[static_cast<std::size_t>(a)])
        for (const Tap& tx : phase[static_cast<std::size_t>(b)]) {
          c.dy[c.ntaps] = ty.off;
          c.dx[c.ntaps] = tx.off;
          kys.push_back(ty.kk);
          kxs.push_back(tx.kk);
          ++c.ntaps;
        }
      im.pack(c, ci, in.cb,
              [&](int o, int i, int t) {
                const auto ts = static_cast<std::size_t>(t);
                return static_cast<double>(wt[((i * n_out + o) * k + kys[ts]) * k + kxs[ts]]) * bn.scale[static_cast<std::size_t>(o)];
              },
              [&](int o) { return static_cast<double>(bs[o]) * bn.scale[static_cast<std::size_t>(o)] + bn.shift[static_cast<std::size_t>(o)]; });
      im.ops.push_back(op);
    }
}

detail::ConvRowFn kernel_for(KernelPath p) {
  switch (p) {
#if defined(__x86_64__)
    case KernelPath::kAvx2: return detail::conv_row_avx2;
#endif
#if defined(__aarch64__)
    case KernelPath::kNeon: return detail::conv_row_neon;
#endif
    default: return detail::conv_row_portable;
  }
}

// --- per-frame work items -------------------------------------------------------------------------

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

}  // namespace

std::string_view kernel_path_name(KernelPath p) noexcept {
  switch (p) {
    case KernelPath::kAuto: return "auto";
    case KernelPath::kPortable: return "portable";
    case KernelPath::kAvx2: return "avx2";
    case KernelPath::kNeon: return "neon";
  }
  return "?";
}

bool kernel_path_available(KernelPath p) noexcept {
  switch (p) {
    case KernelPath::kAuto:
    case KernelPath::kPortable: return true;
    case KernelPath::kAvx2:
#if defined(__x86_64__)
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
      return false;
#endif
    case KernelPath::kNeon:
#if defined(__aarch64__) && defined(__linux__)
      return (getauxval(AT_HWCAP) & HWCAP_ASIMD) != 0;
#elif defined(__aarch64__)
      return true;
#else
      return false;
#endif
  }
  return false;
}

KernelPath best_kernel_path() noexcept {
  if (kernel_path_available(KernelPath::kAvx2)) return KernelPath::kAvx2;
  if (kernel_path_available(KernelPath::kNeon)) return KernelPath::kNeon;
  return KernelPath::kPortable;
}

double erfnet_macs(int width, int height, int num_classes) noexcept {
  const double n2 = width / 2.0 * height / 2.0, n4 = n2 / 4.0, n8 = n4 / 4.0;
  auto nb = [](double c, double n) { return 4.0 * 3.0 * c * c * n; };
  return n2 * 13 * 3 * 9 + n4 * 48 * 16 * 9 + 5 * nb(64, n4) + n8 * 64 * 64 * 9 + 8 * nb(128, n8) + n8 * 128 * 64 * 9 +
         2 * nb(64, n4) + n4 * 64 * 16 * 9 + 2 * nb(16, n2) + n2 * 16 * num_classes * 4;
}

ErfNet::ErfNet(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ErfNet::~ErfNet() = default;

Result<std::unique_ptr<ErfNet>> ErfNet::create(const ErfNetWeights& weights, const ErfNetOptions& opt) {
  auto im = std::make_unique<Impl>();
  const WeightsHeader& h = weights.header;
  im->width = opt.width > 0 ? opt.width : static_cast<int>(h.input_width);
  im->height = opt.height > 0 ? opt.height : static_cast<int>(h.input_height);
  im->classes = static_cast<int>(h.num_classes);
  if (im->width <= 0 || im->height <= 0 || im->width % 8 || im->height % 8 || im->width > 16384 || im->height > 16384)
    return Error::make(ErrorCode::kInvalidArgument, "ErfNet input size " + std::to_string(im->width) + "x" + std::to_string(im->height) +
                                                        " must be positive multiples of 8 (height and width)");
  if (opt.threads < 1 || opt.threads > 64)
    return Error::make(ErrorCode::kInvalidArgument, "ErfNet thread count " + std::to_string(opt.threads) + " outside 1..64");
  if (im->classes < 1 || im->classes > 255)
    return Error::make(ErrorCode::kInvalidArgument, "ErfNet class count " + std::to_string(im->classes) + " outside 1..255 (classes are bytes)");
  // The weights must be the architecture's (what parse_weights checks); say so if built by hand.
  for (const TensorSpec& s : erfnet_tensor_specs(h.num_classes)) {
    const WeightTensor* t = weights.find(s.name);
    if (t == nullptr || t->dims != s.dims || t->data.size() != [&] {
          std::size_t n = 1;
          for (auto d : s.dims) n *= d;
          return n;
        }())
      return Error::make(ErrorCode::kInvalidArgument, "ErfNet weights lack tensor '" + s.name + "' of the right shape");
  }
  im->path = opt.path == KernelPath::kAuto ? best_kernel_path() : opt.path;
  if (!kernel_path_available(im->path))
    return Error::make(ErrorCode::kUnavailable, "ErfNet kernel path '" + std::string(kernel_path_name(im->path)) +
                                                    "' is not available on this CPU or build");
  im->conv_fn = kernel_for(im->path);
  for (int c = 0; c < 3; ++c) {
    im->norm_scale[c] = 1.0F / (255.0F * h.std[c]);
    im->norm_shift[c] = -h.mean[c] / h.std[c];
  }

  const int W = im->width, H = im->height;
  // Zero columns on both sides: the 3x3 convs read 1, the 1x3 ones d, Winograd's pairs 2d.
  im->winograd = opt.winograd;
  const int p1 = 2, p8 = 32;
  bool ok = im->make_act(im->input, 3, H, W, 1) && im->make_act(im->x2, 16, H / 2, W / 2, p1) && im->make_act(im->t2a, 16, H / 2, W / 2, p1) &&
            im->make_act(im->t2b, 16, H / 2, W / 2, p1) && im->make_act(im->x4, 64, H / 4, W / 4, p1) &&
            im->make_act(im->t4a, 64, H / 4, W / 4, p1) && im->make_act(im->t4b, 64, H / 4, W / 4, p1) &&
            im->make_act(im->x8, 128, H / 8, W / 8, p8) && im->make_act(im->t8a, 128, H / 8, W / 8, p8) &&
            im->make_act(im->t8b, 128, H / 8, W / 8, p8);
  if (!ok) return Error::make(ErrorCode::kUnavailable, "ErfNet: out of memory for the activations");

  // Encoder.
  add_down(*im, weights, "encoder.initial_block", im->input, 3, im->x2);
  add_down(*im, weights, "encoder.layers.0", im->x2, 16, im->x4);
  for (int i = 1; i <= 5; ++i) add_block(*im, weights, "encoder.layers." + std::to_string(i), im->x4, im->t4a, im->t4b, 1);
  add_down(*im, weights, "encoder.layers.6", im->x4, 64, im->x8);
  for (int i = 0; i < 8; ++i)
    add_block(*im, weights, "encoder.layers." + std::to_string(7 + i), im->x8, im->t8a, im->t8b, kDilations128[i]);
  // Decoder.
  add_up(*im, weights, "decoder.layers.0.conv", fold_bn(weights, "decoder.layers.0.bn", 64), im->x8, &im->x4, 3, 64, true);
  add_block(*im, weights, "decoder.layers.1", im->x4, im->t4a, im->t4b, 1);
  add_block(*im, weights, "decoder.layers.2", im->x4, im->t4a, im->t4b, 1);
  add_up(*im, weights, "decoder.layers.3.conv", fold_bn(weights, "decoder.layers.3.bn", 16), im->x4, &im->x2, 3, 16, true);
  add_block(*im, weights, "decoder.layers.4", im->x2, im->t2a, im->t2b, 1);
  add_block(*im, weights, "decoder.layers.5", im->x2, im->t2a, im->t2b, 1);
  add_up(*im, weights, "decoder.output_conv", identity_bn(im->classes), im->x2, nullptr, 2, im->classes, false);

  // Every column a tap reads must lie in the image or its zero padding.
  for (const Op& op : im->ops) {
    if (op.kind == OpKind::kWinoH) {
      const int last = first_of_pair(pair_count(op.conv.ow, op.conv.dilation) - 1, op.conv.dilation);
      if (op.conv.dilation > op.conv.in->pad || last + 2 * op.conv.dilation > op.conv.in->w - 1 + op.conv.in->pad)
        return Error::make(ErrorCode::kInternal, "ErfNet: a Winograd pair reads beyond the padding");
    }
    if (op.kind != OpKind::kConv) continue;
    const ConvOp& c = op.conv;
    for (int t = 0; t < c.ntaps; ++t) {
      const int lo = c.dx[t], hi = c.sx * (c.ow - 1) + c.dx[t];
      if (lo < -c.in->pad || hi > c.in->w - 1 + c.in->pad)
        return Error::make(ErrorCode::kInternal, "ErfNet: a convolution tap reads beyond the padding");
    }
  }

  im->packed = alloc_floats(im->staging.size());
  const std::size_t plane = static_cast<std::size_t>(W) * static_cast<std::size_t>(H);
  im->logits = alloc_floats(plane * static_cast<std::size_t>(im->classes));
  im->scratch_stride = static_cast<std::size_t>(W / 2) * kGroup;
  im->scratch = alloc_floats(im->scratch_stride * static_cast<std::size_t>(opt.threads));
  im->best = alloc_floats(static_cast<std::size_t>(W) * static_cast<std::size_t>(opt.threads));
  im->zero_row = alloc_floats(static_cast<std::size_t>(W) * kBlock + 64);
  im->wscratch_stride = ((im->wscratch_m_offset + im->wscratch_stride + 15) / 16) * 16;
  im->wscratch = alloc_floats(std::max<std::size_t>(16, im->wscratch_stride * static_cast<std::size_t>(opt.threads)));
  im->bytes += im->wscratch_stride * static_cast<std::size_t>(opt.threads) * sizeof(float);
  if (!im->packed || !im->logits || !im->scratch || !im->best || !im->wscratch || !im->zero_row) return Error::make(ErrorCode::kUnavailable, "ErfNet: out of memory");
  std::memcpy(im->packed.get(), im->staging.data(), im->staging.size() * sizeof(float));
  im->bytes += (im->staging.size() + plane * static_cast<std::size_t>(im->classes) + im->scratch_stride * static_cast<std::size_t>(opt.threads) +
                static_cast<std::size_t>(W) * static_cast<std::size_t>(opt.threads)) * sizeof(float) + plane;
  im->staging = {};
  im->classes_buf.assign(plane, 0);
  im->pool = std::make_unique<detail::ThreadPool>(opt.threads);
  return std::unique_ptr<ErfNet>(new ErfNet(std::move(im)));
}

namespace {
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

const float* ErfNet::logits() const noexcept { return impl_->logits.get(); }
const std::uint8_t* ErfNet::classes() const noexcept { return impl_->classes_buf.data(); }
int ErfNet::width() const noexcept { return impl_->width; }
int ErfNet::height() const noexcept { return impl_->height; }
int ErfNet::num_classes() const noexcept { return impl_->classes; }
int ErfNet::threads() const noexcept { return impl_->pool->threads(); }
KernelPath ErfNet::path() const noexcept { return impl_->path; }
bool ErfNet::winograd() const noexcept { return impl_->winograd; }
double ErfNet::reference_macs() const noexcept { return erfnet_macs(impl_->width, impl_->height, impl_->classes); }
std::size_t ErfNet::memory_bytes() const noexcept { return impl_->bytes; }

}  // namespace ag::seg
