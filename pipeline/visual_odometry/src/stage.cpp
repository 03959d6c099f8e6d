// The vo stage: camera frames and the autopilot's attitude in, VoMsg out.
#include "airground/visual_odometry/stage.hpp"

#include <cmath>

#include "airground/aerial_mapping/stages.hpp"
#include "airground/messages/channels.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/platform/log.hpp"

namespace ag::vo {

Status VoStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  VoParams p = load_params(v, kVoFields);
  p.camera = mapping::load_camera_calibration(ctx.config);
  const VoStageSettings own = load_params(v, kVoStageFields);
  max_gap_ = static_cast<TimeNs>(own.attitude_max_gap_s * 1e9);
  max_wait_ = static_cast<TimeNs>(own.attitude_max_wait_s * 1e9);
  frames_per_step_ = own.frames_per_step;
  vo_ = std::make_unique<VisualOdometry>(p);
  clock_ = &ctx.clock;
  auto cam = ctx.channels.ring_reader(chan::kCamera);
  if (!cam) return cam.error();
  camera_ = cam.value();
  auto att = ctx.channels.ring_reader(chan::kAttitude);
  if (!att) return att.error();
  attitude_ = att.value();
  auto out = ctx.channels.ring_writer(chan::kVisualOdometry.with_name(own.output_channel));
  if (!out) return out.error();
  out_ = out.value();
  return ok_status();
}

bool VoStage::attitude_at(TimeNs t, Eigen::Matrix3d& R) const noexcept {
  if (history_size_ == 0) return false;
  const std::size_t cap = history_.size();
  const AttitudeMsg* before = nullptr;
  const AttitudeMsg* after = nullptr;
  for (std::size_t k = 0; k < history_size_; ++k) {  // newest first
    const AttitudeMsg& m = history_[(history_head_ + cap - 1 - k) % cap];
    if (m.stamp >= t) after = &m;
    if (m.stamp <= t) {
      before = &m;
      break;
    }
  }
  auto rot = [](const AttitudeMsg& m) { return rotation_matrix(m.roll, m.pitch, m.yaw); };
  if (before && after && after->stamp - before->stamp <= 2 * max_gap_) {
    const double a = after->stamp == before->stamp ? 0.0 : static_cast<double>(t - before->stamp) / static_cast<double>(after->stamp - before->stamp);
    const Eigen::Quaterniond qa(rot(*before)), qb(rot(*after));
    R = qa.slerp(a, qb).toRotationMatrix();
    return true;
  }
  const AttitudeMsg* near = before ? before : after;
  if (near && std::llabs(near->stamp - t) <= max_gap_) {
    R = rot(*near);
    return true;
  }
  return false;
}

void VoStage::step(TimeNs now) noexcept {
  while (const AttitudeMsg* a = attitude_.front()) {
    history_[history_head_] = *a;
    history_head_ = (history_head_ + 1) % history_.size();
    history_size_ = std::min(history_size_ + 1, history_.size());
    ++c_.attitude_samples;
    attitude_.pop();
  }
  const TimeNs newest_att = history_size_ ? history_[(history_head_ + history_.size() - 1) % history_.size()].stamp : -1;
  for (int k = 0; k < frames_per_step_; ++k) {
    const CameraImageMsg* img = camera_.front();
    if (img == nullptr) break;
    // The attitude after the frame is due shortly; wait for it a little (frames keep their order).
    if (newest_att < img->stamp && history_size_ > 0 && now - img->stamp < max_wait_) break;
    Eigen::Matrix3d R;
    const bool have = attitude_at(img->stamp, R);
    ++(have ? c_.frames_with_attitude : c_.frames_without_attitude);
    const VoFrame f = vo_->process(img->stamp, img->rgb.data(), have ? std::optional<Eigen::Matrix3d>(R) : std::nullopt);
    ++c_.frames;
    add_work(1.0);  // one frame tracked (compute-time model)
    VoMsg m;
    m.stamp = img->stamp;
    m.segment = f.segment;
    m.tracking = f.tracking;
    if (f.tracking) {
      ++c_.tracked;
      m.pose = to_pose3(f.body_in_segment);
      if (f.new_segment) AG_LOG_INFO("vo", "vo: tracking (segment %u) from t=%.2f s, %d tracks", f.segment, to_seconds(img->stamp), f.tracked);
    } else {
      ++c_.lost;
      if (was_tracking_) AG_LOG_WARN("vo", "vo: tracking lost at t=%.2f s (frame %llu): restarting", to_seconds(img->stamp), static_cast<unsigned long long>(c_.frames));
    }
    was_tracking_ = f.tracking;
    c_.keyframes += f.keyframe ? 1 : 0;
    c_.segments += f.new_segment ? 1 : 0;
    m.published = clock_->now();
    if (out_.push(m) != 0) ++c_.frames_dropped_busy;
    camera_.pop();
  }
}

void VoStage::stop() noexcept {
  using ull = unsigned long long;
  AG_LOG_INFO("vo", "vo: frames=%llu tracked=%llu lost=%llu keyframes=%llu segments=%llu with_attitude=%llu without_attitude=%llu attitude_samples=%llu dropped_busy=%llu",
              ull(c_.frames), ull(c_.tracked), ull(c_.lost), ull(c_.keyframes), ull(c_.segments), ull(c_.frames_with_attitude),
              ull(c_.frames_without_attitude), ull(c_.attitude_samples), ull(c_.frames_dropped_busy));
}

}  // namespace ag::vo
