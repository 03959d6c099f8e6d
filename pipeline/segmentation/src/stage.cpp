// The segmentation stage (see stage.hpp).
#include "airground/segmentation/stage.hpp"

#include <cstring>
#include <string>

#include "airground/messages/channels.hpp"
#include "airground/messages/classes.hpp"
#include "airground/platform/log.hpp"

namespace ag::seg {

Status SegmentationStage::init(StageContext& ctx) {
  const SegmentationSettings cfg = load_params(ctx.params(), kSegmentationStageFields);
  clock_ = &ctx.clock;
  if (cfg.labels == "erfnet") {
    const std::string& path = cfg.weights;
    auto w = load_weights(path);
    if (!w) return Error::make(ErrorCode::kConfig, "segmentation.weights: " + w.error().message);
    const WeightsHeader& h = w.value().header;
    const ClassTable& table = ClassTable::builtin();
    // Logit i is the class named class_names[i]; without names, class id i (config/classes.yaml order).
    for (std::uint32_t i = 0; i < h.num_classes; ++i) {
      if (!h.class_names.empty()) {
        const auto id = table.by_name(h.class_names[i]);
        if (!id) return Error::make(ErrorCode::kConfig, "segmentation.weights: " + path + ": class '" + h.class_names[i] + "' is not in the class table");
        class_of_logit_[i] = raw(*id);
      } else {
        if (!table.valid_id(static_cast<std::uint8_t>(i)) || i == raw(ClassId::kUnknown))
          return Error::make(ErrorCode::kConfig, "segmentation.weights: " + path + ": " + std::to_string(h.num_classes) +
                                                     " unnamed classes, more than the class table's");
        class_of_logit_[i] = static_cast<std::uint8_t>(i);
      }
    }
    ErfNetOptions eo{kImageWidth, kImageHeight, cfg.threads, cfg.kernel};
    eo.placement = ctx.placement;  // the workers take this stage's priority and CPU
    auto net = ErfNet::create(w.value(), eo);
    if (!net) return Error::make(ErrorCode::kConfig, "segmentation: " + net.error().message);
    if (!net.value()->placement().warning.empty())
      AG_LOG_WARN("segmentation", "ErfNet %s", net.value()->placement().warning.c_str());
    net_ = std::move(net.value());
  }
  auto in = ctx.channels.ring_reader(chan::kKeyframes);
  if (!in) return in.error();
  in_ = in.value();
  auto out = ctx.channels.ring_writer(chan::kKeyframesLabelled);
  if (!out) return out.error();
  out_ = out.value();
  msg_ = std::make_unique<KeyframeMsg>();
  return ok_status();
}

void SegmentationStage::step(TimeNs /*now*/) noexcept {
  if (net_ == nullptr) {  // relay everything: a reader that falls behind makes pose_graph skip keyframes
    while (KeyframeMsg* kf = in_.front()) {
      ++c_.keyframes_in;
      ++c_.relayed_gt;
      if (out_.push(*kf) != 0) ++c_.dropped_busy;
      in_.pop();
    }
    return;
  }
  // One keyframe per step: a frame of ErfNet is the stage's whole budget.
  KeyframeMsg* kf = in_.front();
  if (kf == nullptr) return;
  ++c_.keyframes_in;
  KeyframeMsg& m = *msg_;
  m.stamp = kf->stamp;
  m.id = kf->id;
  m.segment = kf->segment;
  m.body_pose = kf->body_pose;
  std::memcpy(m.rgb.data(), kf->rgb.data(), m.rgb.size());
  in_.pop();
  net_->run_rgb8(m.rgb.data(), static_cast<std::size_t>(kImageWidth) * 3);
  const std::uint8_t* cls = net_->classes();
  for (std::size_t i = 0; i < kImagePixels; ++i) m.cls[i] = class_of_logit_[cls[i]];
  m.labels = LabelSource::kSegmentation;
  m.published = clock_->now();
  ++c_.segmented;
  add_work(1.0);  // one ErfNet forward pass (compute-time model)
  if (out_.push(m) != 0) ++c_.dropped_busy;
}

}  // namespace ag::seg
