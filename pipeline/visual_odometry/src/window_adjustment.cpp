// Sliding-window bundle adjustment: Schur complement on the keyframes, LM with Huber weights.
#include "airground/visual_odometry/window_adjustment.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace ag::vo {

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) noexcept {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

double huber_rho(double r2, double k) noexcept {  // rho(r^2), the robustified squared norm
  const double r = std::sqrt(r2);
  return r <= k ? r2 : 2 * k * r - k * k;
}

}  // namespace

WindowAdjustment::WindowAdjustment(int max_keyframes, int max_points, int max_observations)
    : max_kf_(std::min(max_keyframes, kMaxWindowKeyframes)), max_pts_(max_points), max_obs_(max_observations) {
  free_index_.resize(static_cast<std::size_t>(max_kf_));
  hcp_.resize(static_cast<std::size_t>(max_obs_));
  hpp_inv_.resize(static_cast<std::size_t>(max_pts_));
  bp_.resize(static_cast<std::size_t>(max_pts_));
  saved_poses_.resize(static_cast<std::size_t>(max_kf_));
  saved_points_.resize(static_cast<std::size_t>(max_pts_));
}

double WindowAdjustment::cost(std::span<const CameraPose> poses, std::span<const GravityPrior> gravity,
                              std::span<const std::uint8_t> fixed, std::span<const Eigen::Vector3d> points,
                              std::span<const BaObservation> obs, const WindowAdjustmentParams& p) const noexcept {
  const double inv = 1.0 / p.pixel_sigma;
  double c = 0;
  for (const BaObservation& o : obs) {
    const Eigen::Vector3d& X = points[static_cast<std::size_t>(o.point)];
    if (!X.allFinite()) continue;
    const Eigen::Vector3d xc = poses[static_cast<std::size_t>(o.keyframe)].to_camera(X);
    if (xc.z() <= 1e-9) {
      c += 1e6;
      continue;
    }
    const Eigen::Vector2d r = (xc.head<2>() / xc.z() - o.x) * inv;
    c += huber_rho(r.squaredNorm(), p.huber_sigmas);
  }
  if (p.gravity_sigma_rad > 0)
    for (std::size_t k = 0; k < poses.size(); ++k)
      if (!fixed[k] && gravity[k].valid)
        c += ((poses[k].R * Eigen::Vector3d::UnitZ() - gravity[k].up_in_camera) / p.gravity_sigma_rad).squaredNorm();
  return 0.5 * c;
}

WindowAdjustmentReport WindowAdjustment::solve(std::span<CameraPose> poses, std::span<const std::uint8_t> fixed,
                                               std::span<const GravityPrior> gravity, std::span<Eigen::Vector3d> points,
                                               std::span<const BaObservation> obs, const WindowAdjustmentParams& p) noexcept {
  WindowAdjustmentReport rep;
  if (static_cast<int>(poses.size()) > max_kf_ || static_cast<int>(points.size()) > max_pts_ ||
      static_cast<int>(obs.size()) > max_obs_)
    return rep;
  int F = 0;
  for (std::size_t k = 0; k < poses.size(); ++k) free_index_[k] = fixed[k] ? -1 : F++;
  rep.free_keyframes = F;
  rep.points = static_cast<int>(points.size());
  rep.observations = static_cast<int>(obs.size());
  const double inv = 1.0 / p.pixel_sigma;
  double lambda = p.initial_lambda;
  double current = cost(poses, gravity, fixed, points, obs, p);
  rep.initial_cost = rep.final_cost = current;
  const int n = 6 * F;

  for (int it = 0; it < p.iterations; ++it) {
    S_.resize(n, n);
    s_.resize(n);
    SchurMatrix& S = S_;
    SchurVector& s = s_;
    S.setZero();
    s.setZero();
    // Per point: its block and its observations' keyframe-point blocks; then fold into S.
    std::size_t o0 = 0;
    while (o0 < obs.size()) {
      const std::int32_t pi = obs[o0].point;
      std::size_t o1 = o0;
      while (o1 < obs.size() && obs[o1].point == pi) ++o1;
      const auto pu = static_cast<std::size_t>(pi);
      const Eigen::Vector3d& X = points[pu];
      Eigen::Matrix3d hpp = Eigen::Matrix3d::Zero();
      Eigen::Vector3d bp = Eigen::Vector3d::Zero();
      for (std::size_t o = o0; o < o1; ++o) {
        hcp_[o].setZero();
        if (!X.allFinite()) continue;
        const CameraPose& P = poses[static_cast<std::size_t>(obs[o].keyframe)];
        const Eigen::Vector3d xc = P.to_camera(X);
        if (xc.z() <= 1e-9) continue;
        const double iz = 1.0 / xc.z();
        const Eigen::Vector2d r = (xc.head<2>() * iz - obs[o].x) * inv;
        Eigen::Matrix<double, 2, 3> dp;
        dp << iz, 0, -xc.x() * iz * iz, 0, iz, -xc.y() * iz * iz;
        dp *= inv;
        const double rn = r.norm();
        const double w = rn <= p.huber_sigmas ? 1.0 : p.huber_sigmas / rn;
        const Eigen::Matrix<double, 2, 3> Jp = dp * P.R;
        hpp += w * Jp.transpose() * Jp;
        bp += w * Jp.transpose() * r;
        const int f = free_index_[static_cast<std::size_t>(obs[o].keyframe)];
        if (f < 0) continue;
        Eigen::Matrix<double, 2, 6> Jc;
        Jc.leftCols<3>() = -dp * skew(xc);
        Jc.rightCols<3>() = dp;
        S.block<6, 6>(6 * f, 6 * f) += w * Jc.transpose() * Jc;
        s.segment<6>(6 * f) += w * Jc.transpose() * r;
        hcp_[o] = w * Jc.transpose() * Jp;
      }
      hpp.diagonal() *= 1.0 + lambda;
      hpp.diagonal().array() += 1e-9;
      hpp_inv_[pu] = hpp.inverse();
      bp_[pu] = bp;
      for (std::size_t a = o0; a < o1; ++a) {
        const int fa = free_index_[static_cast<std::size_t>(obs[a].keyframe)];
        if (fa < 0) continue;
        const Eigen::Matrix<double, 6, 3> t = hcp_[a] * hpp_inv_[pu];
        s.segment<6>(6 * fa) -= t * bp;
        for (std::size_t b = o0; b < o1; ++b) {
          const int fb = free_index_[static_cast<std::size_t>(obs[b].keyframe)];
          if (fb < 0) continue;
          S.block<6, 6>(6 * fa, 6 * fb) -= t * hcp_[b].transpose();
        }
      }
      o0 = o1;
    }
    if (p.gravity_sigma_rad > 0)
      for (std::size_t k = 0; k < poses.size(); ++k) {
        const int f = free_index_[k];
        if (f < 0 || !gravity[k].valid) continue;
        const Eigen::Vector3d up = poses[k].R * Eigen::Vector3d::UnitZ();
        const Eigen::Vector3d r = (up - gravity[k].up_in_camera) / p.gravity_sigma_rad;
        const Eigen::Matrix3d J = -skew(up) / p.gravity_sigma_rad;
        // Its Hessian enters damped like the rest (the damping below is on S's diagonal).
        S.block<3, 3>(6 * f, 6 * f) += J.transpose() * J;
        s.segment<3>(6 * f) += J.transpose() * r;
      }
    if (n > 0) {
      S.diagonal() *= 1.0 + lambda;
      S.diagonal().array() += 1e-9;
    }
    // Save, step, evaluate; on a worse cost restore and raise the damping.
    for (std::size_t k = 0; k < poses.size(); ++k) saved_poses_[k] = poses[k];
    for (std::size_t k = 0; k < points.size(); ++k) saved_points_[k] = points[k];
    dc_.resize(n);
    SchurVector& dc = dc_;
    if (n > 0) {
      const Eigen::LDLT<SchurMatrix> ldlt(S);
      dc = -ldlt.solve(s);
      if (!dc.allFinite()) break;
      for (std::size_t k = 0; k < poses.size(); ++k) {
        const int f = free_index_[k];
        if (f < 0) continue;
        const Eigen::Matrix3d dR = so3_exp(dc.segment<3>(6 * f));
        poses[k].R = dR * poses[k].R;
        poses[k].t = dR * poses[k].t + dc.segment<3>(6 * f + 3);
      }
    }
    // Points: dp = -Hpp^-1 (bp + sum Hcp^T dc).
    o0 = 0;
    while (o0 < obs.size()) {
      const std::int32_t pi = obs[o0].point;
      std::size_t o1 = o0;
      Eigen::Vector3d acc = bp_[static_cast<std::size_t>(pi)];
      while (o1 < obs.size() && obs[o1].point == pi) {
        const int f = free_index_[static_cast<std::size_t>(obs[o1].keyframe)];
        if (f >= 0) acc += hcp_[o1].transpose() * dc.segment<6>(6 * f);
        ++o1;
      }
      Eigen::Vector3d& X = points[static_cast<std::size_t>(pi)];
      if (X.allFinite()) X -= hpp_inv_[static_cast<std::size_t>(pi)] * acc;
      o0 = o1;
    }
    const double next = cost(poses, gravity, fixed, points, obs, p);
    rep.iterations = it + 1;
    if (next < current) {
      const bool converged = current - next < 1e-6 * current;
      current = next;
      lambda = std::max(lambda * 0.3, 1e-9);
      if (converged) break;
    } else {
      for (std::size_t k = 0; k < poses.size(); ++k) poses[k] = saved_poses_[k];
      for (std::size_t k = 0; k < points.size(); ++k) points[k] = saved_points_[k];
      lambda *= 10;
    }
  }
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const Eigen::Quaterniond q(poses[k].R);
    poses[k].R = q.normalized().toRotationMatrix();
  }
  rep.final_cost = current;
  return rep;
}

}  // namespace ag::vo
