// The quadrotor's segmentation stage (thin wrapper over ErfNet), on keyframes only:
//   keyframes (from pose_graph) -> [labels = erfnet: ErfNet on the RGB, class ids by name] -> keyframes_labelled
// With labels = gt it relays the keyframes unchanged (the simulator's ground-truth classes stay available
// as a switch for evaluation). The ortho-mapper reads "keyframes_labelled" when its keyframes_channel
// says so. Everything is allocated in init(); step() never allocates.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "airground/messages/messages.hpp"
#include "airground/platform/config.hpp"
#include "airground/platform/param_binding.hpp"
#include "airground/platform/stage.hpp"
#include "airground/segmentation/erfnet.hpp"

namespace ag::seg {

struct SegmentationStageCounters {
  std::uint64_t keyframes_in{0};
  std::uint64_t segmented{0};
  std::uint64_t relayed_gt{0};
  std::uint64_t dropped_busy{0};  // the mapper's ring was full
};

struct SegmentationSettings {
  std::string labels{"gt"};  // gt|erfnet
  std::string weights{"/usr/share/airground/erfnet_c7.agw"};
  int threads{2};
  KernelPath kernel{KernelPath::kAuto};
};
inline constexpr ParamField<SegmentationSettings> kSegmentationStageFields[] = {
    field::text("labels", &SegmentationSettings::labels, "gt", "gt|erfnet", "keyframe classes: the camera driver's (simulator ground truth) or ErfNet's"),
    field::text("weights", &SegmentationSettings::weights, "/usr/share/airground/erfnet_c7.agw", "",
                "ErfNet weights file (docs/segmentation.md), used when labels = erfnet"),
    field::integer("threads", &SegmentationSettings::threads, 1, 16, "threads", "threads that run one ErfNet frame (the stage's plus workers)"),
    field::choice<&SegmentationSettings::kernel>("kernel", "auto|avx2|neon|portable",
                                                 {KernelPath::kAuto, KernelPath::kAvx2, KernelPath::kNeon, KernelPath::kPortable},
                                                 "ErfNet kernel path (auto: the fastest this CPU has)"),
};
inline constexpr auto kSegmentationStageParams = param_specs(kSegmentationStageFields);

class SegmentationStage final : public Stage {
 public:
  static constexpr std::span<const ParamSpec> kParams{kSegmentationStageParams};
  static std::unique_ptr<Stage> make() { return std::make_unique<SegmentationStage>(); }

  Status init(StageContext& ctx) override;
  void step(TimeNs now) noexcept override;

  [[nodiscard]] const SegmentationStageCounters& counters() const noexcept { return c_; }
  [[nodiscard]] bool erfnet() const noexcept { return net_ != nullptr; }

 private:
  std::unique_ptr<ErfNet> net_;
  std::array<std::uint8_t, 256> class_of_logit_{};  // logit index -> class id (config/classes.yaml)
  const Clock* clock_{nullptr};
  RingReader<KeyframeMsg, kKeyframeRing> in_;
  RingWriter<KeyframeMsg, kKeyframeRing> out_;
  std::unique_ptr<KeyframeMsg> msg_;
  SegmentationStageCounters c_;
};

}  // namespace ag::seg
