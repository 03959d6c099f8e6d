// The VO's life cycle: start a segment, track frames against the local map, add keyframes, adjust.
#include "airground/visual_odometry/visual_odometry.hpp"

#include <algorithm>
#include <cmath>

namespace ag::vo {

namespace {

constexpr std::size_t kPointSlots = 8192;  // map points live in slot id % kPointSlots
constexpr int kMinStartTracks = 30;        // fewer corners left while starting: start again from here

Eigen::Matrix3d yaw_removed(const Eigen::Matrix3d& R_wb) noexcept {
  const double yaw = std::atan2(R_wb(1, 0), R_wb(0, 0));
  return Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * R_wb;
}

}  // namespace

VisualOdometry::VisualOdometry(const VoParams& p)
    : p_(p),
      corners_(p.corners),
      flow_(p.flow),
      adjustment_(std::min(p.window_keyframes, kMaxWindowKeyframes), p.window_keyframes * p.max_features,
                  p.window_keyframes * p.max_features) {
  p_.window_keyframes = std::clamp(p_.window_keyframes, 2, kMaxWindowKeyframes);
  const auto nf = static_cast<std::size_t>(p_.max_features);
  const auto nobs = static_cast<std::size_t>(p_.window_keyframes) * nf;
  tracks_.reserve(nf);
  prev_px_.resize(nf);
  next_px_.resize(nf);
  rot_px_.resize(nf);
  new_corners_.reserve(nf);
  ok_.resize(nf);
  keep_.resize(nf);
  motion_.reserve(nf);
  points_.resize(kPointSlots);
  window_.resize(static_cast<std::size_t>(p_.window_keyframes));
  for (Keyframe& k : window_) k.obs.resize(nf);
  pnp_X_.resize(nf);
  pnp_x_.resize(nf);
  two_view_x1_.resize(nf);
  two_view_x2_.resize(nf);
  pnp_track_.resize(nf);
  ba_tuples_.reserve(nobs);
  ba_obs_.reserve(nobs);
  ba_points_.reserve(nobs);
  ba_slots_.reserve(nobs);
  ba_poses_.resize(static_cast<std::size_t>(p_.window_keyframes));
  ba_gravity_.resize(static_cast<std::size_t>(p_.window_keyframes));
  ba_fixed_.resize(static_cast<std::size_t>(p_.window_keyframes));
  for (ImagePyramid& pyr : pyr_) {
    // Size every level once, so the first frame does not allocate either.
    std::vector<std::uint8_t> grey(static_cast<std::size_t>(p_.camera.width) * static_cast<std::size_t>(p_.camera.height), 0);
    pyr.build_from_grey(grey.data(), p_.camera.width, p_.camera.height);
  }
  std::vector<Pixel> none;
  corners_.detect(pyr_[0], none, new_corners_, 0);  // sizes the detector's buffers
}

Eigen::Vector2d VisualOdometry::normalised(const Pixel& px) const noexcept {
  return p_.camera.undistort_pixel(px.u, px.v);
}

VisualOdometry::MapPoint* VisualOdometry::point_of(std::uint32_t id) noexcept {
  MapPoint& m = points_[id % kPointSlots];
  return m.valid && m.id == id ? &m : nullptr;
}

VisualOdometry::Keyframe* VisualOdometry::keyframe_by_serial(std::uint64_t serial) noexcept {
  for (std::size_t i = 0; i < window_size_; ++i) {
    Keyframe& k = window_[(window_head_ + i) % window_.size()];
    if (k.serial == serial) return &k;
  }
  return nullptr;
}

double VisualOdometry::median_motion_since(std::uint64_t) const noexcept {
  auto& m = const_cast<std::vector<float>&>(motion_);
  m.clear();
  for (const Track& t : tracks_) m.push_back(std::hypot(t.px.u - t.kf_px.u, t.px.v - t.kf_px.v));
  if (m.empty()) return 0.0;
  auto mid = m.begin() + static_cast<std::ptrdiff_t>(m.size() / 2);
  std::nth_element(m.begin(), mid, m.end());
  return *mid;
}

VoFrame VisualOdometry::process(TimeNs stamp, const std::uint8_t* rgb, const std::optional<Eigen::Matrix3d>& world_from_body) noexcept {
  cur_ ^= 1;
  pyr_[cur_].build_from_rgb(rgb, p_.camera.width, p_.camera.height);
  return step(stamp, world_from_body);
}

VoFrame VisualOdometry::process_grey(TimeNs stamp, const std::uint8_t* grey, const std::optional<Eigen::Matrix3d>& world_from_body) noexcept {
  cur_ ^= 1;
  pyr_[cur_].build_from_grey(grey, p_.camera.width, p_.camera.height);
  return step(stamp, world_from_body);
}

void VisualOdometry::drop_tracks(const std::vector<std::uint8_t>& keep) noexcept {
  std::size_t w = 0;
  for (std::size_t i = 0; i < tracks_.size(); ++i)
    if (keep[i]) tracks_[w++] = tracks_[i];
  tracks_.resize(w);
}

void VisualOdometry::detect_corners(bool at_keyframe) noexcept {
  const std::size_t cap = static_cast<std::size_t>(p_.max_features);
  if (tracks_.size() >= cap) return;
  for (std::size_t i = 0; i < tracks_.size(); ++i) prev_px_[i] = tracks_[i].px;
  corners_.detect(pyr_[cur_], std::span<const Pixel>(prev_px_.data(), tracks_.size()), new_corners_, cap - tracks_.size());
  // Corners found between keyframes have no keyframe observation yet: the next keyframe anchors them.
  const std::uint64_t anchor = at_keyframe && window_size_ ? newest_keyframe().serial : 0;
  for (const Pixel& c : new_corners_) {
    Track t;
    t.px = t.kf_px = c;
    t.id = next_track_id_++;
    t.anchor_kf = anchor;
    t.anchor_x = normalised(c);
    tracks_.push_back(t);
  }
}

void VisualOdometry::restart(const GravityPrior& g, const Eigen::Matrix3d& R_wb, TimeNs stamp) noexcept {
  tracks_.clear();
  for (MapPoint& m : points_) m.valid = false;
  window_head_ = window_size_ = 0;
  state_ = VoState::kStarting;
  have_prev_pose_ = false;
  mean_flow_ = Pixel{};
  // The segment's frame: level, with the yaw of this first keyframe, origin at its camera.
  Keyframe& k = window_[0];
  k.serial = next_kf_serial_++;
  k.stamp = stamp;
  k.pose.R = (R_wb * nadir_body_from_camera()).transpose();
  k.pose.t.setZero();
  k.gravity = g;
  k.n_obs = 0;
  window_size_ = 1;
  detect_corners(true);
}

VoFrame VisualOdometry::output(const CameraPose& pose, bool keyframe) const noexcept {
  VoFrame f;
  f.tracking = true;
  f.keyframe = keyframe;
  f.segment = segment_;
  f.body_in_segment.linear() = pose.R.transpose() * nadir_body_from_camera().transpose();
  f.body_in_segment.translation() = pose.centre();
  f.tracked = static_cast<int>(tracks_.size());
  return f;
}

VoFrame VisualOdometry::step(TimeNs stamp, const std::optional<Eigen::Matrix3d>& R_wb) noexcept {
  ++stats_.frames;
  GravityPrior g;
  if (R_wb) {
    g.up_in_camera = ((*R_wb) * nadir_body_from_camera()).transpose() * Eigen::Vector3d::UnitZ();
    g.valid = true;
  } else {
    ++stats_.frames_without_attitude;
  }
  const std::optional<Eigen::Matrix3d> prev_att = prev_attitude_;
  prev_attitude_ = R_wb;
  // Frames need not come evenly (a camera drops frames when its reader is late): the motion guesses
  // below are per frame, so they scale with this frame's interval over the one before it.
  double dt_scale = 1.0;
  if (last_stamp_ != 0 && stamp > last_stamp_) {
    const TimeNs dt = stamp - last_stamp_;
    if (last_dt_ > 0 && dt != last_dt_) dt_scale = std::clamp(static_cast<double>(dt) / static_cast<double>(last_dt_), 0.25, 4.0);
    last_dt_ = dt;
  }
  last_stamp_ = stamp;
  VoFrame none;
  none.segment = segment_;
  if (!have_prev_) {
    have_prev_ = true;
    kf0_attitude_ = R_wb ? *R_wb : Eigen::Matrix3d::Identity();
    kf0_has_attitude_ = R_wb.has_value();
    restart(g, R_wb ? yaw_removed(*R_wb) : Eigen::Matrix3d::Identity(), stamp);
    return none;
  }
  // The camera's rotation since the previous frame (autopilot, else constant rate): corners are looked for
  // where that rotation and the last frame's translational image motion put them (a quadrotor tilts
  // several degrees in a frame, tens of pixels).
  const Eigen::Matrix3d R_bc = nadir_body_from_camera();
  Eigen::Matrix3d R_cc = Eigen::Matrix3d::Identity();
  if (R_wb && prev_att)
    R_cc = R_bc.transpose() * ((*prev_att).transpose() * (*R_wb)).transpose() * R_bc;
  else if (state_ == VoState::kTracking && have_prev_pose_)
    R_cc = pose_.R * prev_pose_.R.transpose();
  const ImagePyramid& prev = pyr_[cur_ ^ 1];
  const std::size_t n = tracks_.size();
  for (std::size_t i = 0; i < n; ++i) {
    prev_px_[i] = tracks_[i].px;
    const Eigen::Vector2d x = normalised(tracks_[i].px);
    const Eigen::Vector3d h = R_cc * Eigen::Vector3d(x.x(), x.y(), 1.0);
    const Eigen::Vector2d q = h.z() > 1e-6 ? p_.camera.distort_to_pixel(h.x() / h.z(), h.y() / h.z()) : Eigen::Vector2d(x.x(), x.y());
    rot_px_[i] = Pixel{static_cast<float>(q.x()), static_cast<float>(q.y())};
    next_px_[i] = Pixel{rot_px_[i].u + static_cast<float>(dt_scale) * mean_flow_.u, rot_px_[i].v + static_cast<float>(dt_scale) * mean_flow_.v};
  }
  flow_.track(prev, pyr_[cur_], std::span<const Pixel>(prev_px_.data(), n), std::span<Pixel>(next_px_.data(), n),
              std::span<std::uint8_t>(ok_.data(), n));
  motion_.clear();
  for (std::size_t i = 0; i < n; ++i) {
    keep_[i] = ok_[i];
    if (!ok_[i]) continue;
    tracks_[i].px = next_px_[i];
    motion_.push_back(next_px_[i].u - rot_px_[i].u);
  }
  // Median image motion beyond the rotation, per axis, as the next frame's guess.
  if (!motion_.empty()) {
    auto mid = motion_.begin() + static_cast<std::ptrdiff_t>(motion_.size() / 2);
    std::nth_element(motion_.begin(), mid, motion_.end());
    mean_flow_.u = *mid;
    motion_.clear();
    for (std::size_t i = 0; i < n; ++i)
      if (ok_[i]) motion_.push_back(next_px_[i].v - rot_px_[i].v);
    mid = motion_.begin() + static_cast<std::ptrdiff_t>(motion_.size() / 2);
    std::nth_element(motion_.begin(), mid, motion_.end());
    mean_flow_.v = *mid;
  }
  drop_tracks(keep_);

  if (state_ == VoState::kStarting) {
    if (try_start(g, R_wb, stamp)) {
      state_ = VoState::kTracking;
      if (segment_started_) ++segment_;
      segment_started_ = true;
      ++stats_.segments;
      ++stats_.tracked_frames;
      VoFrame f = output(pose_, true);
      f.new_segment = true;
      f.segment = segment_;
      f.inliers = newest_keyframe().n_obs;
      return f;
    }
    if (static_cast<int>(tracks_.size()) < kMinStartTracks) {
      kf0_attitude_ = R_wb ? *R_wb : Eigen::Matrix3d::Identity();
      kf0_has_attitude_ = R_wb.has_value();
      restart(g, R_wb ? yaw_removed(*R_wb) : Eigen::Matrix3d::Identity(), stamp);
    }
    none.segment = segment_;
    return none;
  }

  // Predict: rotation from the autopilot's body rotation since the last frame (or constant), position
  // at constant velocity.
  CameraPose pred = pose_;
  if (R_wb && prev_att) {
    const Eigen::Matrix3d R_wb_prev = pose_.R.transpose() * R_bc.transpose();
    const Eigen::Matrix3d R_wb_pred = R_wb_prev * (prev_att->transpose() * (*R_wb));
    pred.R = (R_wb_pred * R_bc).transpose();
  } else if (have_prev_pose_) {
    pred.R = (pose_.R * prev_pose_.R.transpose()) * pose_.R;
  }
  const Eigen::Vector3d c = pose_.centre();
  const Eigen::Vector3d c_pred = !have_prev_pose_ ? c
                                 : dt_scale == 1.0 ? Eigen::Vector3d(2 * c - prev_pose_.centre())
                                                   : Eigen::Vector3d(c + dt_scale * (c - prev_pose_.centre()));
  pred.t = -pred.R * c_pred;
  int inliers = 0;
  if (!track_pose(g, pred, inliers)) {
    ++stats_.losses;
    kf0_attitude_ = R_wb ? *R_wb : Eigen::Matrix3d::Identity();
    kf0_has_attitude_ = R_wb.has_value();
    restart(g, R_wb ? yaw_removed(*R_wb) : Eigen::Matrix3d::Identity(), stamp);
    none.segment = segment_;
    return none;
  }
  prev_pose_ = pose_;
  have_prev_pose_ = true;
  pose_ = pred;
  ++stats_.tracked_frames;

  int with_points = 0;
  for (const Track& t : tracks_) with_points += t.has_point ? 1 : 0;
  const bool kf = median_motion_since(0) > p_.keyframe_parallax_px ||
                  with_points < static_cast<int>(p_.keyframe_min_tracked * newest_keyframe().n_obs);
  if (kf)
    make_keyframe(pose_, g, stamp);
  else if (static_cast<double>(tracks_.size()) < p_.redetect_below * p_.max_features)
    detect_corners(false);
  VoFrame f = output(pose_, kf);
  f.inliers = inliers;
  return f;
}

bool VisualOdometry::try_start(const GravityPrior& g, const std::optional<Eigen::Matrix3d>& R_wb, TimeNs stamp) noexcept {
  if (median_motion_since(0) < p_.init_parallax_px) return false;
  const Keyframe& k0 = window_[window_head_];
  std::size_t n = 0;
  for (const Track& t : tracks_) {
    two_view_x1_[n] = t.anchor_x;
    two_view_x2_[n] = normalised(t.px);
    ++n;
  }
  // The rotation between the two frames: the autopilot's, or none (a level survey camera).
  Eigen::Matrix3d R21 = Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d R_bc = nadir_body_from_camera();
  Eigen::Matrix3d R_c2w = k0.pose.R;
  if (R_wb && kf0_has_attitude_) {
    const Eigen::Matrix3d R_wb0 = k0.pose.R.transpose() * R_bc.transpose();
    const Eigen::Matrix3d R_wb2 = R_wb0 * (kf0_attitude_.transpose() * (*R_wb));
    R_c2w = (R_wb2 * R_bc).transpose();
    R21 = R_c2w * k0.pose.R.transpose();
  }
  RansacParams rp;
  rp.iterations = 100;
  rp.threshold = p_.max_reprojection_px / p_.camera.fx;
  Eigen::Vector3d t21;
  if (!translation_known_rotation(std::span<const Eigen::Vector2d>(two_view_x1_.data(), n),
                                  std::span<const Eigen::Vector2d>(two_view_x2_.data(), n), R21, rp, rng_, t21,
                                  std::span<std::uint8_t>(keep_.data(), n))) {
    ++stats_.starts_failed;
    return false;
  }
  drop_tracks(keep_);  // the outliers of the two-view fit
  CameraPose p2;
  p2.R = R_c2w;
  p2.t = R21 * k0.pose.t + t21;  // unit baseline: the segment's scale
  make_keyframe(p2, g, stamp);
  if (newest_keyframe().n_obs < p_.min_pose_inliers) {
    ++stats_.starts_failed;
    kf0_attitude_ = R_wb ? *R_wb : Eigen::Matrix3d::Identity();
    kf0_has_attitude_ = R_wb.has_value();
    restart(g, R_wb ? yaw_removed(*R_wb) : Eigen::Matrix3d::Identity(), stamp);
    return false;
  }
  pose_ = newest_keyframe().pose;
  have_prev_pose_ = false;
  return true;
}

bool VisualOdometry::track_pose(const GravityPrior& g, CameraPose& pose, int& inliers) noexcept {
  std::size_t n = 0;
  for (std::size_t i = 0; i < tracks_.size(); ++i) {
    const Track& t = tracks_[i];
    if (!t.has_point) continue;
    const MapPoint* m = point_of(t.id);
    if (m == nullptr) {
      tracks_[i].has_point = false;
      continue;
    }
    pnp_X_[n] = m->X;
    pnp_x_[n] = normalised(t.px);
    pnp_track_[n] = static_cast<std::uint32_t>(i);
    ++n;
  }
  RansacParams rp;
  rp.iterations = 30;
  rp.threshold = p_.max_reprojection_px / p_.camera.fx;
  PoseRefineParams pp;
  pp.pixel_sigma = 1.0 / p_.camera.fx;
  pp.huber = 1.5 / p_.camera.fx;
  pp.gravity_sigma_rad = p_.gravity_sigma_rad;
  inliers = solve_pose(std::span<const Eigen::Vector3d>(pnp_X_.data(), n), std::span<const Eigen::Vector2d>(pnp_x_.data(), n),
                       g, rp, pp, rng_, pose, std::span<std::uint8_t>(ok_.data(), n));
  if (inliers < p_.min_pose_inliers) {
    return false;
  }
  // Tracks whose map point disagrees have drifted (or the point is wrong): drop both.
  for (std::size_t i = 0; i < tracks_.size(); ++i) keep_[i] = 1;
  for (std::size_t k = 0; k < n; ++k)
    if (!ok_[k]) {
      keep_[pnp_track_[k]] = 0;
      if (MapPoint* m = point_of(tracks_[pnp_track_[k]].id)) m->valid = false;
    }
  drop_tracks(keep_);
  return true;
}

void VisualOdometry::make_keyframe(const CameraPose& pose, const GravityPrior& g, TimeNs stamp) noexcept {
  if (window_size_ == window_.size()) {
    window_head_ = (window_head_ + 1) % window_.size();
    --window_size_;
  }
  Keyframe& kf = window_[(window_head_ + window_size_) % window_.size()];
  ++window_size_;
  kf.serial = next_kf_serial_++;
  kf.stamp = stamp;
  kf.pose = pose;
  kf.gravity = g;
  kf.n_obs = 0;
  for (Track& t : tracks_) {
    t.kf_px = t.px;
    if (t.has_point && kf.n_obs < static_cast<int>(kf.obs.size())) kf.obs[static_cast<std::size_t>(kf.n_obs++)] = KfObs{t.id, normalised(t.px)};
  }
  triangulate_new(kf);
  ++stats_.keyframes;
  if (window_size_ >= 3) adjust_window();
  pose_ = newest_keyframe().pose;
  detect_corners(true);
}

void VisualOdometry::triangulate_new(Keyframe& kf) noexcept {
  const double min_par = p_.min_triangulation_deg * M_PI / 180.0;
  const double thr2 = std::pow(p_.max_reprojection_px / p_.camera.fx, 2);
  for (Track& t : tracks_) {
    if (t.has_point) continue;
    Keyframe* a = keyframe_by_serial(t.anchor_kf);
    const Eigen::Vector2d x = normalised(t.px);
    if (a == nullptr || a == &kf) {  // its first keyframe left the window: start again from this one
      t.anchor_kf = kf.serial;
      t.anchor_x = x;
      continue;
    }
    Eigen::Vector3d X;
    if (!triangulate(a->pose, t.anchor_x, kf.pose, x, min_par, X)) continue;  // more baseline later
    if (reprojection_error2(a->pose, X, t.anchor_x) > thr2 || reprojection_error2(kf.pose, X, x) > thr2) {
      ++stats_.points_rejected;
      t.anchor_kf = kf.serial;
      t.anchor_x = x;
      continue;
    }
    MapPoint& m = points_[t.id % kPointSlots];
    m.id = t.id;
    m.valid = true;
    m.X = X;
    t.has_point = true;
    ++stats_.points_triangulated;
    if (a->n_obs < static_cast<int>(a->obs.size())) a->obs[static_cast<std::size_t>(a->n_obs++)] = KfObs{t.id, t.anchor_x};
    if (kf.n_obs < static_cast<int>(kf.obs.size())) kf.obs[static_cast<std::size_t>(kf.n_obs++)] = KfObs{t.id, x};
  }
}

void VisualOdometry::adjust_window() noexcept {
  ba_tuples_.clear();
  for (std::size_t i = 0; i < window_size_; ++i) {
    const Keyframe& k = window_[(window_head_ + i) % window_.size()];
    for (int o = 0; o < k.n_obs; ++o) {
      const KfObs& ob = k.obs[static_cast<std::size_t>(o)];
      if (point_of(ob.id) == nullptr) continue;
      ba_tuples_.push_back(BaTuple{ob.id % static_cast<std::uint32_t>(kPointSlots), static_cast<std::int32_t>(i), ob.x});
    }
  }
  std::sort(ba_tuples_.begin(), ba_tuples_.end(), [](const BaTuple& a, const BaTuple& b) { return a.slot != b.slot ? a.slot < b.slot : a.kf < b.kf; });
  ba_obs_.clear();
  ba_points_.clear();
  ba_slots_.clear();
  std::size_t i = 0;
  while (i < ba_tuples_.size()) {
    std::size_t j = i;
    while (j < ba_tuples_.size() && ba_tuples_[j].slot == ba_tuples_[i].slot) ++j;
    if (j - i >= 2) {  // a point seen once in the window constrains nothing here
      const auto pi = static_cast<std::int32_t>(ba_points_.size());
      ba_points_.push_back(points_[ba_tuples_[i].slot].X);
      ba_slots_.push_back(ba_tuples_[i].slot);
      for (std::size_t k = i; k < j; ++k) ba_obs_.push_back(BaObservation{ba_tuples_[k].kf, pi, ba_tuples_[k].x});
    }
    i = j;
  }
  for (std::size_t k = 0; k < window_size_; ++k) {
    const Keyframe& kf = window_[(window_head_ + k) % window_.size()];
    ba_poses_[k] = kf.pose;
    ba_gravity_[k] = kf.gravity;
    ba_fixed_[k] = k < 2 ? 1 : 0;  // the two oldest hold position, yaw and scale
  }
  WindowAdjustmentParams wp;
  wp.iterations = p_.ba_iterations;
  wp.pixel_sigma = 1.0 / p_.camera.fx;
  wp.gravity_sigma_rad = p_.gravity_sigma_rad;
  stats_.last_adjustment = adjustment_.solve(std::span<CameraPose>(ba_poses_.data(), window_size_),
                                             std::span<const std::uint8_t>(ba_fixed_.data(), window_size_),
                                             std::span<const GravityPrior>(ba_gravity_.data(), window_size_), ba_points_, ba_obs_, wp);
  for (std::size_t k = 0; k < window_size_; ++k) window_[(window_head_ + k) % window_.size()].pose = ba_poses_[k];
  // Points back; those that still disagree with a keyframe leave the map.
  const double thr2 = std::pow(2.0 * p_.max_reprojection_px / p_.camera.fx, 2);
  for (std::size_t k = 0; k < ba_points_.size(); ++k) points_[ba_slots_[k]].X = ba_points_[k];
  for (const BaObservation& o : ba_obs_)
    if (reprojection_error2(ba_poses_[static_cast<std::size_t>(o.keyframe)], ba_points_[static_cast<std::size_t>(o.point)], o.x) > thr2)
      points_[ba_slots_[static_cast<std::size_t>(o.point)]].valid = false;
  for (Track& t : tracks_)
    if (t.has_point && point_of(t.id) == nullptr) t.has_point = false;
}

}  // namespace ag::vo
