// ErfNet inference on the CPU, written by hand: BN folded into the convolutions at load time, one generic
// direct-convolution micro-kernel over a channel-blocked layout (8 channels per block) with a fused
// bias / residual / ReLU epilogue, kernels for AVX2+FMA, NEON and portable C++ chosen at run time,
// transposed convolutions as sub-pixel convolutions, a platform WorkerGroup, and every buffer allocated in
// create(): run() never allocates.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string_view>

#include "airground/platform/result.hpp"
#include "airground/platform/worker_group.hpp"
#include "airground/segmentation/weights.hpp"

namespace ag::seg {

enum class KernelPath : std::uint8_t { kAuto, kPortable, kAvx2, kNeon };
std::string_view kernel_path_name(KernelPath p) noexcept;
// Whether this build and this CPU can run `p` (kAuto and kPortable always can).
bool kernel_path_available(KernelPath p) noexcept;
// The fastest available path.
KernelPath best_kernel_path() noexcept;

struct ErfNetOptions {
  int width{0}, height{0};  // [px] input size; 0 = the weights' input size; multiples of 8
  int threads{1};           // threads that run a frame (the caller plus threads - 1 workers), 1..64
  KernelPath path{KernelPath::kAuto};
  bool winograd{true};      // the 3x1 / 1x3 convolutions by 1-D Winograd F(2,3) (2/3 of the multiplies); false: direct
  WorkerPlacement placement{};  // the workers' priority and CPU: the calling stage's (StageContext::placement)
};

class ErfNet {
 public:
  static Result<std::unique_ptr<ErfNet>> create(const ErfNetWeights& weights, const ErfNetOptions& options);
  ~ErfNet();
  ErfNet(const ErfNet&) = delete;
  ErfNet& operator=(const ErfNet&) = delete;

  // One frame from interleaved 8-bit RGB (row stride in bytes), normalised by the header's
  // (v / 255 - mean) / std. Fills logits() and, through classes(), the argmax.
  void run_rgb8(const std::uint8_t* rgb, std::size_t stride_bytes) noexcept;
  // One frame from a normalised planar float image, 3 x height x width.
  void run_planar(const float* chw) noexcept;

  // The last frame's logits, num_classes x height x width (float32, planar).
  [[nodiscard]] const float* logits() const noexcept;
  // The last frame's per-pixel argmax (class index in logit order), height x width.
  [[nodiscard]] const std::uint8_t* classes() const noexcept;

  [[nodiscard]] int width() const noexcept;
  [[nodiscard]] int height() const noexcept;
  [[nodiscard]] int num_classes() const noexcept;
  [[nodiscard]] int threads() const noexcept;
  // What the workers applied of options.placement (a refusal leaves them on normal threads).
  [[nodiscard]] const WorkerPlacementReport& placement() const noexcept;
  [[nodiscard]] KernelPath path() const noexcept;
  [[nodiscard]] bool winograd() const noexcept;
  // Multiply-accumulates of one frame in the reference network (what GFLOP/s figures count, x2).
  [[nodiscard]] double reference_macs() const noexcept;
  // Bytes of activations, packed weights and scratch held.
  [[nodiscard]] std::size_t memory_bytes() const noexcept;

  struct Impl;

 private:
  explicit ErfNet(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// ErfNet's multiply-accumulates at an input size (convolutions as the reference computes them).
double erfnet_macs(int width, int height, int num_classes) noexcept;

}  // namespace ag::seg
