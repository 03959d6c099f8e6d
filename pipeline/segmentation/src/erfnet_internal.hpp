// ErfNet's op graph and run-time state (ErfNet::Impl), shared by create() (erfnet.cpp), the graph builder
// (erfnet_build.cpp) and the per-frame work items (erfnet_run.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "airground/segmentation/erfnet.hpp"
#include "kernels.hpp"

namespace ag::seg {
namespace detail {

struct FreeDeleter {
  void operator()(float* p) const noexcept { std::free(p); }
};
using FloatBuf = std::unique_ptr<float, FreeDeleter>;

inline FloatBuf alloc_floats(std::size_t n) {
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

// kWinoV / kWinoH: a 3x1 / 1x3 convolution by 1-D Winograd F(2,3) (see add_conv1d in erfnet_build.cpp).
enum class OpKind : std::uint8_t { kConv, kPool, kWinoV, kWinoH };
struct Op {
  OpKind kind{OpKind::kConv};
  ConvOp conv;
  PoolOp pool;
};

// Columns per Winograd chunk: the four products of one chunk (4 x 48 x 16 floats) stay in L1.
constexpr int kWinoChunk = 48;

// Pairs of outputs (p, p + d) along the conv's axis that Winograd computes together: p with p mod 2d < d.
inline int first_of_pair(int j, int d) { return (j / d) * 2 * d + j % d; }
inline int pair_count(int n, int d) {
  int j = 0;
  while (first_of_pair(j, d) < n) ++j;
  return j;
}

// Appends ErfNet's layers (encoder, then decoder) to im.ops, their packed weights to im.staging.
void add_layers(ErfNet::Impl& im, const ErfNetWeights& w);

}  // namespace detail

// Short names for ErfNet::Impl and the erfnet*.cpp files.
using detail::Act;
using detail::alloc_floats;
using detail::ConvOp;
using detail::FloatBuf;
using detail::kBlock;
using detail::kGroup;
using detail::Op;

struct ErfNet::Impl {
  int width{0}, height{0}, classes{0};
  KernelPath path{KernelPath::kPortable};
  detail::ConvRowFn conv_fn{detail::conv_row_portable};
  float norm_scale[3]{}, norm_shift[3]{};
  std::unique_ptr<WorkerGroup> pool;

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

}  // namespace ag::seg
