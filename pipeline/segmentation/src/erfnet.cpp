// ErfNet's layer graph on our kernels: builds the op list and packed, BN-folded weights at create(),
// and runs it on preallocated activations (see erfnet.hpp). Every convolution is one ConvOp: a list of
// taps (row and column offsets in the input), an input step per output pixel (1, or 2 for the
// downsamplers), and where its output pixels land (every pixel, or one of the 2x2 phases of an
// upsampled map: that is how the transposed convolutions become sub-pixel convolutions).
// The graph is built in erfnet_build.cpp and run in erfnet_run.cpp.
#include "airground/segmentation/erfnet.hpp"

#include <algorithm>
#include <cstring>
#include <string>

#include "erfnet_internal.hpp"

#if defined(__aarch64__) && defined(__linux__)
#include <asm/hwcap.h>
#include <sys/auxv.h>
#endif

namespace ag::seg {
using detail::first_of_pair;
using detail::OpKind;
using detail::pair_count;

namespace {

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

  // Encoder and decoder.
  detail::add_layers(*im, weights);

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
  im->pool = std::make_unique<WorkerGroup>(opt.threads, opt.placement);
  return std::unique_ptr<ErfNet>(new ErfNet(std::move(im)));
}

const float* ErfNet::logits() const noexcept { return impl_->logits.get(); }
const std::uint8_t* ErfNet::classes() const noexcept { return impl_->classes_buf.data(); }
int ErfNet::width() const noexcept { return impl_->width; }
int ErfNet::height() const noexcept { return impl_->height; }
int ErfNet::num_classes() const noexcept { return impl_->classes; }
int ErfNet::threads() const noexcept { return impl_->pool->size(); }
const WorkerPlacementReport& ErfNet::placement() const noexcept { return impl_->pool->placement(); }
KernelPath ErfNet::path() const noexcept { return impl_->path; }
bool ErfNet::winograd() const noexcept { return impl_->winograd; }
double ErfNet::reference_macs() const noexcept { return erfnet_macs(impl_->width, impl_->height, impl_->classes); }
std::size_t ErfNet::memory_bytes() const noexcept { return impl_->bytes; }

}  // namespace ag::seg
