// ErfNet's layers as ops with packed, BN-folded weights, built once at create() (see erfnet.cpp).
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "erfnet_internal.hpp"

namespace ag::seg {
using detail::kWinoChunk;
using detail::OpKind;
using detail::pair_count;

namespace {

constexpr double kBnEps = 1e-3;
constexpr int kDilations128[8] = {2, 4, 8, 16, 2, 4, 8, 16};

struct Bn {
  std::vector<double> scale, shift;
};

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

}  // namespace

void detail::add_layers(ErfNet::Impl& im, const ErfNetWeights& w) {
  // Encoder.
  add_down(im, w, "encoder.initial_block", im.input, 3, im.x2);
  add_down(im, w, "encoder.layers.0", im.x2, 16, im.x4);
  for (int i = 1; i <= 5; ++i) add_block(im, w, "encoder.layers." + std::to_string(i), im.x4, im.t4a, im.t4b, 1);
  add_down(im, w, "encoder.layers.6", im.x4, 64, im.x8);
  for (int i = 0; i < 8; ++i)
    add_block(im, w, "encoder.layers." + std::to_string(7 + i), im.x8, im.t8a, im.t8b, kDilations128[i]);
  // Decoder.
  add_up(im, w, "decoder.layers.0.conv", fold_bn(w, "decoder.layers.0.bn", 64), im.x8, &im.x4, 3, 64, true);
  add_block(im, w, "decoder.layers.1", im.x4, im.t4a, im.t4b, 1);
  add_block(im, w, "decoder.layers.2", im.x4, im.t4a, im.t4b, 1);
  add_up(im, w, "decoder.layers.3.conv", fold_bn(w, "decoder.layers.3.bn", 16), im.x4, &im.x2, 3, 16, true);
  add_block(im, w, "decoder.layers.4", im.x2, im.t2a, im.t2b, 1);
  add_block(im, w, "decoder.layers.5", im.x2, im.t2a, im.t2b, 1);
  add_up(im, w, "decoder.output_conv", identity_bn(im.classes), im.x2, nullptr, 2, im.classes, false);
}

}  // namespace ag::seg
