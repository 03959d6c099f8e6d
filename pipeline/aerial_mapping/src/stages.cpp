// The UAV's mapping stages: pose graph + keyframes, and stereo + ortho-map.
#include "airground/aerial_mapping/stages.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "airground/messages/channels.hpp"
#include "airground/messages/pose_math.hpp"
#include "airground/platform/clock.hpp"
#include "airground/platform/log.hpp"

namespace ag::mapping {

namespace {

constexpr std::size_t kDepthSampleStride = 64;  // every 64th stereo point estimates the ground depth

Eigen::Isometry3d interpolate_pose(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, double alpha) noexcept {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  const Eigen::Quaterniond qa(a.linear()), qb(b.linear());
  t.linear() = qa.slerp(alpha, qb).toRotationMatrix();
  t.translation() = (1.0 - alpha) * a.translation() + alpha * b.translation();
  return t;
}

double cpu_ms_since(TimeNs t0) noexcept { return static_cast<double>(thread_cpu_now() - t0) * 1e-6; }
}  // namespace

PinholeCamera load_camera_calibration(const Config& config) {
  const SectionView v(config, "camera_calibration");
  PinholeCamera c = load_params(v, kCameraIntrinsicsFields);
  load_params(v, std::span<const ParamField<PinholeCamera>>(kCameraTangentialFields), c);
  const NadirDistortion d = load_params(v, kNadirDistortionFields);
  c.k1 = d.k1;
  c.k2 = d.k2;
  c.width = kImageWidth;
  c.height = kImageHeight;
  return c;
}

// ---------------------------------------------------------------------------------------------------
// pose_graph

Status PoseGraphStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  PoseGraphParams p = load_params(v, kPoseGraphSolveFields);
  load_params(v, std::span<const ParamField<PoseGraphParams>>(kPoseGraphFactorFields), p);
  PoseGraphStageSettings own = load_params(v, kPoseGraphStageFields);
  load_params(v, std::span<const ParamField<PoseGraphStageSettings>>(kPoseGraphBetweenRotationFields), own);
  p.between_sigma_rad = own.between_sigma_rad;
  keyframe_distance_m_ = own.keyframe_distance_m;
  segment_settle_m_ = own.segment_settle_m;
  max_image_wait_s_ = own.max_image_wait_s;
  graph_ = std::make_unique<PoseGraph>(p);
  clock_ = &ctx.clock;

  auto cam = ctx.channels.ring_reader(chan::kCamera);
  if (!cam) return cam.error();
  camera_ = cam.value();
  auto vo = ctx.channels.ring_reader(chan::kVisualOdometry);
  if (!vo) return vo.error();
  vo_ = vo.value();
  auto gps = ctx.channels.ring_reader(chan::kGps);
  if (!gps) return gps.error();
  gps_ = gps.value();
  auto kf = ctx.channels.ring_writer(chan::kKeyframes);
  if (!kf) return kf.error();
  keyframes_out_ = kf.value();
  auto poses = ctx.channels.latest_writer(chan::kKeyframePoses);
  if (!poses) return poses.error();
  poses_out_ = poses.value();
  kf_ = std::make_unique<KeyframeMsg>();
  poses_msg_ = std::make_unique<KeyframePosesMsg>();
  keyframe_refs_.reserve(1U << 16);
  return ok_status();
}

bool PoseGraphStage::interpolate(TimeNs t, KeyframeRef& ref, std::uint32_t& segment) const noexcept {
  constexpr TimeNs kMaxGap = kNsPerS / 2;  // odometry further apart than this is a gap, not a bracket
  const std::size_t cap = history_.size();
  for (std::size_t k = 0; k + 1 < history_size_ + 1 && k < history_size_; ++k) {
    const NodeRef& b = history_[(history_head_ + cap - 1 - k) % cap];  // newest first
    if (b.stamp < t) return false;                                      // t is after every node left
    if (b.stamp == t) {
      ref = KeyframeRef{b.node, b.node, 0.0, t};
      segment = b.segment;
      return true;
    }
    if (k + 1 >= history_size_) return false;
    const NodeRef& a = history_[(history_head_ + cap - 2 - k) % cap];
    if (a.stamp > t) continue;
    if (a.segment != b.segment || b.stamp - a.stamp > kMaxGap) return false;
    ref = KeyframeRef{a.node, b.node, static_cast<double>(t - a.stamp) / static_cast<double>(b.stamp - a.stamp), t};
    segment = b.segment;
    return true;
  }
  return false;
}

Eigen::Isometry3d PoseGraphStage::pose_of(const KeyframeRef& r) const noexcept {
  if (r.a == r.b) return graph_->pose(r.a);
  return interpolate_pose(graph_->pose(r.a), graph_->pose(r.b), r.alpha);
}

Eigen::Isometry3d PoseGraphStage::keyframe_pose(std::uint32_t id) const noexcept {
  return id < keyframe_refs_.size() ? pose_of(keyframe_refs_[id]) : Eigen::Isometry3d::Identity();
}

TimeNs PoseGraphStage::keyframe_stamp(std::uint32_t id) const noexcept {
  return id < keyframe_refs_.size() ? keyframe_refs_[id].stamp : 0;
}

void PoseGraphStage::publish_poses(TimeNs now) noexcept {
  KeyframePosesMsg& m = *poses_msg_;
  const auto count = static_cast<std::uint32_t>(std::min<std::size_t>(keyframe_refs_.size(), KeyframePosesMsg::kCapacity));
  m.stamp = now;
  m.solve = static_cast<std::uint32_t>(++solves_published_);
  m.first_id = static_cast<std::uint32_t>(keyframe_refs_.size()) - count;
  m.count = count;
  for (std::uint32_t i = 0; i < count; ++i) m.poses[i] = to_pose3(pose_of(keyframe_refs_[m.first_id + i]));
  const NodeId last = graph_->last();
  m.segment = last == kNoNode ? 0 : graph_->segment_of(last);
  m.initialised = graph_->initialised();
  m.scale = m.initialised ? graph_->scale(m.segment) : 0.0;
  m.published = clock_->now();
  poses_out_.publish(m);
}

void PoseGraphStage::step(TimeNs now) noexcept {
  while (const GpsMsg* g = gps_.front()) {
    if (g->fix_type >= 2) {
      graph_->add_gps(g->stamp, Eigen::Vector3d(g->east_m, g->north_m, g->up_m), g->h_accuracy_m);
      last_fix_ = Eigen::Vector3d(g->east_m, g->north_m, g->up_m);
      have_fix_ = true;
    } else
      ++c_.gps_no_fix;
    gps_.pop();
  }
  while (const VoMsg* v = vo_.front()) {
    if (!v->tracking) {
      ++c_.odometry_lost;
    } else {
      const NodeId id = graph_->add_frame(v->stamp, v->segment, v->pose);
      if (id != kNoNode) {
        history_[history_head_] = NodeRef{v->stamp, id, v->segment};
        history_head_ = (history_head_ + 1) % history_.size();
        history_size_ = std::min(history_size_ + 1, history_.size());
      }
    }
    vo_.pop();
  }
  const bool solved = graph_->update();
  if (solved) add_work(1.0);  // one graph solve (compute-time model)

  while (const CameraImageMsg* img = camera_.front()) {
    if (img->stamp <= last_image_stamp_) {
      ++c_.frames_out_of_order;
      camera_.pop();
      continue;
    }
    const TimeNs newest = history_size_ ? history_[(history_head_ + history_.size() - 1) % history_.size()].stamp : -1;
    if (newest < img->stamp) {  // the odometry after the image has not arrived yet
      if (to_seconds(now - img->stamp) <= max_image_wait_s_) break;
      ++c_.frames_without_odometry;
      camera_.pop();
      continue;
    }
    KeyframeRef ref;
    std::uint32_t segment = 0;
    if (!interpolate(img->stamp, ref, segment)) {
      ++c_.frames_without_odometry;
      camera_.pop();
      continue;
    }
    last_image_stamp_ = img->stamp;
    ++c_.frames_in;
    if (!graph_->segment_initialised(segment)) {
      ++c_.frames_before_init;
      camera_.pop();
      continue;
    }
    // A segment after a tracking loss starts with the previous one's scale, a guess: its keyframes'
    // baselines, and so every stereo depth, would be off by the guess's error (metres at 40 m). Wait
    // until GPS has seen it travel segment_settle_m, which pins its scale in the graph.
    if (!have_seg_ || segment != seg_) {
      const bool first = !have_seg_;
      have_seg_ = true;
      seg_ = segment;
      seg_settled_ = first || segment_settle_m_ <= 0;  // the first segment is pinned by the climb and the priors
      seg_origin_ = last_fix_;
      if (!have_fix_) seg_settled_ = true;
    }
    if (!seg_settled_) {
      if ((last_fix_ - seg_origin_).norm() < segment_settle_m_) {
        ++c_.frames_settling;
        camera_.pop();
        continue;
      }
      seg_settled_ = true;
    }
    const Eigen::Isometry3d pose = pose_of(ref);
    if (have_kf_ && segment == last_kf_segment_ && (pose.translation() - last_kf_position_).norm() < keyframe_distance_m_) {
      camera_.pop();
      continue;
    }
    KeyframeMsg& kf = *kf_;
    kf.stamp = img->stamp;
    kf.id = next_id_;
    kf.segment = segment;
    kf.body_pose = to_pose3(pose);
    kf.labels = img->labels;
    std::memcpy(kf.rgb.data(), img->rgb.data(), kf.rgb.size());
    std::memcpy(kf.cls.data(), img->cls.data(), kf.cls.size());
    kf.published = clock_->now();
    camera_.pop();
    if (keyframes_out_.push(kf) != 0) {  // the mapper is behind: skip this one, the next frame will do
      ++c_.frames_dropped_busy;
      continue;
    }
    keyframe_refs_.push_back(ref);
    ++next_id_;
    ++c_.frames_keyframed;
    have_kf_ = true;
    last_kf_segment_ = segment;
    last_kf_position_ = pose.translation();
  }
  if (solved) publish_poses(now);
}

// ---------------------------------------------------------------------------------------------------
// ortho_map

Status OrthoMapStage::init(StageContext& ctx) {
  const SectionView v = ctx.params();
  StereoParams sp = load_params(v, kStereoMinDisparityFields);
  load_params(v, std::span<const ParamField<StereoParams>>(kStereoFields), sp);
  OrthoMapStageSettings own = load_params(v, kStereoRangeFields);
  load_params(v, std::span<const ParamField<OrthoMapStageSettings>>(kStereoPairingFields), own);
  load_params(v, std::span<const ParamField<OrthoMapStageSettings>>(kOrthoMapStageFields), own);
  sp.num_disparities = own.num_disparities;
  if (sp.num_disparities % 16 != 0)
    return Error::make(ErrorCode::kConfig, "config error: ortho_map.num_disparities must be a multiple of 16");
  if (sp.block_size % 2 == 0) return Error::make(ErrorCode::kConfig, "config error: ortho_map.block_size must be odd");
  OrthoMapParams mp = load_params(v, kOrthoMapFields);
  mp.max_tiles = static_cast<std::size_t>(own.max_tiles);
  const PinholeCamera cam = load_camera_calibration(ctx.config);
  stereo_ = std::make_unique<DenseStereo>(cam, sp);
  map_ = std::make_unique<OrthoMap>(mp);
  clock_ = &ctx.clock;
  body_from_camera_ = nadir_body_from_camera();

  auto kf = ctx.channels.ring_reader(chan::kKeyframes.with_name(own.keyframes_channel));
  if (!kf) return kf.error();
  keyframes_ = kf.value();
  auto poses = ctx.channels.latest_reader(chan::kKeyframePoses);
  if (!poses) return poses.error();
  poses_ = poses.value();
  auto st = ctx.channels.latest_writer(chan::kMapStatus);
  if (!st) return st.error();
  status_out_ = st.value();
  baseline_depth_ratio_ = own.baseline_depth_ratio;
  const auto history = static_cast<std::size_t>(own.pair_history);
  history_.clear();
  for (std::size_t i = 0; i < history; ++i) history_.push_back(std::make_unique<KeyframeMsg>());
  depth_scratch_.reserve(kImagePixels / kDepthSampleStride + 1);
  points_.reserve(kImagePixels);
  corrections_.reserve(KeyframePosesMsg::kCapacity);
  // Changed tiles on "map_tiles" (the gossip's and the regions stage's input), in the 0.5 m / 64-cell
  // format of MapTileMsg; a map of another cell or tile size is not published (logged).
  tiles_per_step_ = static_cast<std::size_t>(own.tiles_per_step);
  min_elevation_points_ = static_cast<std::uint32_t>(std::max(1, mp.min_elevation_points));
  tiles_enabled_ = std::abs(map_->params().resolution_m - kMapResolutionM) < 1e-9 && map_->params().tile_cells == kTileCells;
  if (tiles_enabled_) {
    auto tw = ctx.channels.ring_writer(chan::kMapTiles);
    if (!tw) return tw.error();
    tiles_out_ = tw.value();
    const std::size_t max_tiles = mp.max_tiles;
    std::size_t cap = 16;
    while (cap < 2 * max_tiles) cap <<= 1;
    slots_.assign(cap, TileSlot{});
    queue_.assign(max_tiles, 0);
    tile_msg_ = std::make_unique<MapTileMsg>();
  } else {
    AG_LOG_WARN("ortho_map", "%s: cells of %.2f m in %d-cell tiles: 'map_tiles' carries 0.5 m cells in 64-cell tiles only, so no tiles are published",
                std::string(ctx.stage_name).c_str(), map_->params().resolution_m, map_->params().tile_cells);
  }
  return ok_status();
}

void OrthoMapStage::publish_tiles(TimeNs now) noexcept {
  if (!tiles_enabled_) return;
  if (map_->version() != seen_version_) {
    seen_version_ = map_->version();
    const std::size_t mask = slots_.size() - 1;
    map_->for_each_tile([&](const Tile& t) {
      const std::uint64_t key = t.key.packed();
      std::size_t i = static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> 20) & mask;
      while (slots_[i].used && slots_[i].key != key) i = (i + 1) & mask;
      TileSlot& s = slots_[i];
      if (!s.used) {
        s.used = true;
        s.key = key;
        s.tile = &t;
      }
      if (s.version == t.version || s.queued || queue_n_ >= queue_.size()) return;
      s.queued = true;
      queue_[(queue_head_ + queue_n_) % queue_.size()] = static_cast<std::uint32_t>(i);
      ++queue_n_;
    });
  }
  for (std::size_t k = 0; k < tiles_per_step_ && queue_n_ > 0 && tiles_out_.free_slots() > 0; ++k) {
    TileSlot& s = slots_[queue_[queue_head_]];
    MapTileMsg& m = *tile_msg_;
    m.tx = s.tile->key.tx;
    m.ty = s.tile->key.ty;
    m.version = s.tile->version;
    for (std::size_t c = 0; c < kTileCellCount; ++c) {
      m.cls[c] = s.tile->live[c].cls;
      m.elevation[c] = s.tile->live[c].reported_elevation(min_elevation_points_);
    }
    m.stamp = now;
    m.published = now;
    (void)tiles_out_.push(m);
    s.version = m.version;
    s.queued = false;
    queue_head_ = (queue_head_ + 1) % queue_.size();
    --queue_n_;
    ++tiles_published_;
  }
}

Eigen::Isometry3d OrthoMapStage::camera_pose(const Pose3& body) const noexcept {
  Eigen::Isometry3d t = to_isometry(body);
  t.linear() = t.linear() * body_from_camera_;
  return t;
}

void OrthoMapStage::step(TimeNs now) noexcept {
  const bool fresh = poses_.fresh();
  const KeyframePosesMsg& latest = poses_.read();
  if (fresh) {
    corrections_.clear();
    for (std::uint32_t i = 0; i < latest.count; ++i) {
      const std::uint32_t id = latest.first_id + i;
      corrections_.emplace_back(id, camera_pose(latest.poses[i]));  // all: stereo partners too (rescale_depth)
    }
    map_->correct(corrections_);
    initialised_ = latest.initialised;
    scale_ = latest.scale;
  }
  auto newest_pose = [&](const KeyframeMsg& k) {
    if (latest.count != 0 && k.id >= latest.first_id && k.id < latest.first_id + latest.count)
      return camera_pose(latest.poses[k.id - latest.first_id]);
    return camera_pose(k.body_pose);
  };
  if (const KeyframeMsg* kf = keyframes_.front()) {
    ++c_.keyframes_in;
    const Eigen::Isometry3d cur = newest_pose(*kf);
    // The stereo partner: among the earlier keyframes of this segment, the one whose baseline is nearest
    // baseline_depth_ratio x the ground depth (a longer baseline than ASOOM's previous keyframe divides
    // the depth error from pose noise and matching noise by the same factor), as long as the pair is
    // not degenerate (baseline within 60 deg of the optical axis: climbing, descending).
    const double want = baseline_depth_ratio_ * (c_.ground_depth_m > 0 ? c_.ground_depth_m : 0.0);
    const KeyframeMsg* partner = nullptr;
    Eigen::Isometry3d partner_pose = Eigen::Isometry3d::Identity();
    double best = std::numeric_limits<double>::infinity();
    bool any_same_segment = false, any_degenerate = false;
    for (std::size_t k = 0; k < history_count_; ++k) {  // newest first
      const KeyframeMsg& h = *history_[(history_head_ + history_.size() - 1 - k) % history_.size()];
      if (h.segment != kf->segment) break;
      any_same_segment = true;
      const Eigen::Isometry3d hp = newest_pose(h);
      const Eigen::Vector3d base = cur.translation() - hp.translation();
      const double along_axis = std::fabs(base.dot(cur.linear().col(2))) / std::max(base.norm(), 1e-9);
      if (along_axis > max_baseline_axis_cos_) {
        any_degenerate = true;
        continue;
      }
      const double score = std::fabs(base.norm() - want);
      if (score < best) {
        best = score;
        partner = &h;
        partner_pose = hp;
      }
      if (want <= 0) break;  // ASOOM: the previous keyframe
    }
    if (partner != nullptr) {
      const TimeNs t0 = thread_cpu_now();
      auto r = stereo_->compute(StereoImage{partner->rgb.data(), partner->cls.data(), partner_pose},
                                StereoImage{kf->rgb.data(), kf->cls.data(), cur}, points_);
      c_.last_stereo_ms = cpu_ms_since(t0);
      if (r) {
        const TimeNs t1 = thread_cpu_now();
        map_->add_keyframe(kf->id, cur, points_, partner->id, (cur.translation() - partner_pose.translation()).norm());
        add_work(1.0);  // one keyframe fused (compute-time model)
        c_.last_bin_ms = cpu_ms_since(t1);
        ++c_.pairs_matched;
        c_.last_baseline_m = (cur.translation() - partner_pose.translation()).norm();
        // Ground depth for the next choice: median camera-to-point height of a sample of the points.
        depth_scratch_.clear();
        const double cz = cur.translation().z();
        for (std::size_t i = 0; i < points_.size(); i += kDepthSampleStride)
          depth_scratch_.push_back(static_cast<float>(cz - static_cast<double>(points_[i].z)));
        if (!depth_scratch_.empty()) {
          auto mid = depth_scratch_.begin() + static_cast<std::ptrdiff_t>(depth_scratch_.size() / 2);
          std::nth_element(depth_scratch_.begin(), mid, depth_scratch_.end());
          if (*mid > 0) c_.ground_depth_m = static_cast<double>(*mid);
        }
      } else {
        ++c_.pairs_refused;
      }
    } else if (any_same_segment && any_degenerate) {
      ++c_.pairs_refused;
    } else {
      ++c_.segment_starts;
    }
    std::memcpy(history_[history_head_].get(), kf, sizeof(KeyframeMsg));
    history_head_ = (history_head_ + 1) % history_.size();
    history_count_ = std::min(history_count_ + 1, history_.size());
    keyframes_.pop();
  }
  publish_tiles(now);
  status_.stamp = now;
  status_.version = map_->version();
  status_.keyframes = static_cast<std::uint32_t>(map_->stats().keyframes);
  status_.tiles = static_cast<std::uint32_t>(map_->tile_count());
  status_.tiles_rebuilt = static_cast<std::uint32_t>(map_->stats().tiles_rebuilt);
  status_.initialised = initialised_;
  status_.scale = scale_;
  status_.published = clock_->now();
  status_out_.publish(status_);
}

}  // namespace ag::mapping
