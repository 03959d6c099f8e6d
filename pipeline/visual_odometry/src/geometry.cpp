// Known-rotation two-view translation, triangulation and the robust camera pose of the VO.
#include "airground/visual_odometry/geometry.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "airground/platform/rng.hpp"

namespace ag::vo {

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) noexcept {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Vector3d homog(const Eigen::Vector2d& x) noexcept { return {x.x(), x.y(), 1.0}; }

// Distance of x2 to the epipolar line of x1 (normalised units).
double epipolar_distance(const Eigen::Vector3d& t, const Eigen::Matrix3d& R, const Eigen::Vector2d& x1,
                         const Eigen::Vector2d& x2) noexcept {
  const Eigen::Vector3d l = t.cross(R * homog(x1));
  const double n = std::hypot(l.x(), l.y());
  return n > 1e-15 ? std::fabs(homog(x2).dot(l)) / n : std::numeric_limits<double>::infinity();
}

}  // namespace

CameraPose inverse(const CameraPose& p) noexcept {
  CameraPose q;
  q.R = p.R.transpose();
  q.t = -q.R * p.t;
  return q;
}

CameraPose compose(const CameraPose& a, const CameraPose& b) noexcept {
  CameraPose c;
  c.R = b.R * a.R;
  c.t = b.R * a.t + b.t;
  return c;
}

Eigen::Matrix3d so3_exp(const Eigen::Vector3d& w) noexcept {
  const double th = w.norm();
  if (th < 1e-12) return Eigen::Matrix3d::Identity() + skew(w);
  return Eigen::AngleAxisd(th, w / th).toRotationMatrix();
}

std::uint64_t SampleStream::next() noexcept { return splitmix64(s_); }

bool translation_known_rotation(std::span<const Eigen::Vector2d> x1, std::span<const Eigen::Vector2d> x2,
                                const Eigen::Matrix3d& R21, const RansacParams& p, SampleStream& rng,
                                Eigen::Vector3d& t21, std::span<std::uint8_t> inlier) noexcept {
  const std::size_t n = x1.size();
  if (n < 8) return false;
  int best = -1;
  Eigen::Vector3d best_t = Eigen::Vector3d::Zero();
  for (int it = 0; it < p.iterations; ++it) {
    const std::size_t i = rng.below(n), j = rng.below(n);
    if (i == j) continue;
    const Eigen::Vector3d a = (R21 * homog(x1[i])).cross(homog(x2[i]));
    const Eigen::Vector3d b = (R21 * homog(x1[j])).cross(homog(x2[j]));
    Eigen::Vector3d t = a.cross(b);
    if (t.norm() < 1e-12) continue;
    t.normalize();
    int count = 0;
    for (std::size_t k = 0; k < n; ++k) count += epipolar_distance(t, R21, x1[k], x2[k]) < p.threshold ? 1 : 0;
    if (count > best) {
      best = count;
      best_t = t;
    }
  }
  if (best < static_cast<int>(p.min_inlier_ratio * static_cast<double>(n)) || best < 8) return false;
  // Refine: the weighted smallest eigenvector of sum a a^T over the inliers (weights: epipolar line norm).
  Eigen::Vector3d t = best_t;
  for (int round = 0; round < 3; ++round) {
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    for (std::size_t k = 0; k < n; ++k) {
      if (epipolar_distance(t, R21, x1[k], x2[k]) >= p.threshold) continue;
      const Eigen::Vector3d a = (R21 * homog(x1[k])).cross(homog(x2[k]));
      const Eigen::Vector3d l = t.cross(R21 * homog(x1[k]));
      const double w = 1.0 / std::max(l.x() * l.x() + l.y() * l.y(), 1e-12);
      M += w * a * a.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(M);
    Eigen::Vector3d tn = es.eigenvectors().col(0);
    if (tn.dot(t) < 0) tn = -tn;
    t = tn.normalized();
  }
  // Sign: most points in front of both cameras.
  int front = 0, count = 0;
  const CameraPose a;
  CameraPose b;
  b.R = R21;
  b.t = t;
  for (std::size_t k = 0; k < n; ++k) {
    const bool in = epipolar_distance(t, R21, x1[k], x2[k]) < p.threshold;
    inlier[k] = in ? 1 : 0;
    if (!in) continue;
    ++count;
    // Depths along both rays from the midpoint solution, no parallax check.
    const Eigen::Vector3d r1 = homog(x1[k]), r2 = R21.transpose() * homog(x2[k]), c2 = b.centre();
    Eigen::Matrix2d A;
    A << r1.dot(r1), -r1.dot(r2), r1.dot(r2), -r2.dot(r2);
    const Eigen::Vector2d rhs(r1.dot(c2), r2.dot(c2));
    const Eigen::Vector2d d = A.fullPivLu().solve(rhs);
    if (d.x() > 0 && d.y() > 0) ++front;
  }
  t21 = 2 * front >= count ? t : Eigen::Vector3d(-t);
  return count >= 8;
}

bool triangulate(const CameraPose& a, const Eigen::Vector2d& xa, const CameraPose& b, const Eigen::Vector2d& xb,
                 double min_parallax_rad, Eigen::Vector3d& X) noexcept {
  const Eigen::Vector3d ra = (a.R.transpose() * homog(xa)).normalized(), rb = (b.R.transpose() * homog(xb)).normalized();
  if (std::acos(std::clamp(ra.dot(rb), -1.0, 1.0)) < min_parallax_rad) return false;
  const Eigen::Vector3d ca = a.centre(), cb = b.centre();
  Eigen::Matrix2d A;
  A << 1.0, -ra.dot(rb), ra.dot(rb), -1.0;
  const Eigen::Vector2d rhs(ra.dot(cb - ca), rb.dot(cb - ca));
  const Eigen::Vector2d d = A.fullPivLu().solve(rhs);
  if (!(d.x() > 0) || !(d.y() > 0)) return false;
  X = 0.5 * ((ca + d.x() * ra) + (cb + d.y() * rb));
  return a.to_camera(X).z() > 0 && b.to_camera(X).z() > 0;
}

double reprojection_error2(const CameraPose& p, const Eigen::Vector3d& X, const Eigen::Vector2d& x) noexcept {
  const Eigen::Vector3d c = p.to_camera(X);
  if (c.z() <= 1e-9) return std::numeric_limits<double>::infinity();
  return (c.head<2>() / c.z() - x).squaredNorm();
}

void refine_pose(std::span<const Eigen::Vector3d> X, std::span<const Eigen::Vector2d> x, std::span<const std::uint8_t> use,
                 const GravityPrior& g, const PoseRefineParams& pp, CameraPose& pose) noexcept {
  const double inv_sigma = 1.0 / pp.pixel_sigma;
  const double huber = pp.huber * inv_sigma;
  for (int it = 0; it < pp.iterations; ++it) {
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    int used = 0;
    for (std::size_t k = 0; k < X.size(); ++k) {
      if (!use[k]) continue;
      const Eigen::Vector3d c = pose.to_camera(X[k]);
      if (c.z() <= 1e-9) continue;
      const double iz = 1.0 / c.z();
      const Eigen::Vector2d r = (c.head<2>() * iz - x[k]) * inv_sigma;
      Eigen::Matrix<double, 2, 3> dp;
      dp << iz, 0, -c.x() * iz * iz, 0, iz, -c.y() * iz * iz;
      Eigen::Matrix<double, 2, 6> J;
      J.leftCols<3>() = -dp * skew(c);
      J.rightCols<3>() = dp;
      J *= inv_sigma;
      const double rn = r.norm();
      const double w = rn <= huber ? 1.0 : huber / rn;
      H += w * J.transpose() * J;
      b += w * J.transpose() * r;
      ++used;
    }
    if (used < 4) return;
    if (g.valid && pp.gravity_sigma_rad > 0) {
      const Eigen::Vector3d up = pose.R * Eigen::Vector3d::UnitZ();
      const double s = 1.0 / pp.gravity_sigma_rad;
      const Eigen::Vector3d r = (up - g.up_in_camera) * s;
      Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
      J.leftCols<3>() = -skew(up) * s;
      H += J.transpose() * J;
      b += J.transpose() * r;
    }
    H.diagonal() *= 1.0 + 1e-6;
    const Eigen::Matrix<double, 6, 1> d = -H.ldlt().solve(b);
    if (!d.allFinite()) return;
    const Eigen::Matrix3d dR = so3_exp(d.head<3>());
    pose.R = dR * pose.R;
    pose.t = dR * pose.t + d.tail<3>();
    if (d.squaredNorm() < 1e-16) break;
  }
  // Keep R orthonormal after the updates.
  const Eigen::Quaterniond q(pose.R);
  pose.R = q.normalized().toRotationMatrix();
}

int solve_pose(std::span<const Eigen::Vector3d> X, std::span<const Eigen::Vector2d> x, const GravityPrior& g,
               const RansacParams& rp, const PoseRefineParams& pp, SampleStream& rng, CameraPose& pose,
               std::span<std::uint8_t> inlier) noexcept {
  const std::size_t n = X.size();
  if (n < 6) return 0;
  const double thr2 = rp.threshold * rp.threshold;
  auto count_inliers = [&](const CameraPose& p) {
    int c = 0;
    for (std::size_t k = 0; k < n; ++k) c += reprojection_error2(p, X[k], x[k]) < thr2 ? 1 : 0;
    return c;
  };
  CameraPose best = pose;
  int best_count = count_inliers(pose);  // the prediction itself competes
  for (int it = 0; it < rp.iterations; ++it) {
    const std::size_t i = rng.below(n), j = rng.below(n);
    if (i == j) continue;
    // [1 0 -u; 0 1 -v] t = [u pz - px; v pz - py] for each of the two points, with p = R X.
    Eigen::Matrix<double, 4, 3> A;
    Eigen::Matrix<double, 4, 1> rhs;
    for (int s = 0; s < 2; ++s) {
      const std::size_t k = s == 0 ? i : j;
      const Eigen::Vector3d p = pose.R * X[k];
      const double u = x[k].x(), v = x[k].y();
      A.row(2 * s) << 1, 0, -u;
      A.row(2 * s + 1) << 0, 1, -v;
      rhs(2 * s) = u * p.z() - p.x();
      rhs(2 * s + 1) = v * p.z() - p.y();
    }
    CameraPose cand = pose;
    cand.t = (A.transpose() * A).ldlt().solve(A.transpose() * rhs);
    if (!cand.t.allFinite()) continue;
    const int c = count_inliers(cand);
    if (c > best_count) {
      best_count = c;
      best = cand;
    }
  }
  if (best_count < 6) return 0;
  pose = best;
  for (std::size_t k = 0; k < n; ++k) inlier[k] = reprojection_error2(pose, X[k], x[k]) < thr2 ? 1 : 0;
  auto refine_and_recount = [&] {
    refine_pose(X, x, inlier, g, pp, pose);
    int c = 0;
    for (std::size_t k = 0; k < n; ++k) {
      inlier[k] = reprojection_error2(pose, X[k], x[k]) < thr2 ? 1 : 0;
      c += inlier[k];
    }
    return c;
  };
  // Under a held rotation that is off, the RANSAC's inliers are the points where the error is nearly a
  // shift (the image centre); once the rotation is corrected the rest agree: refine again over all of them.
  int count = refine_and_recount();
  if (count > best_count) count = refine_and_recount();
  return count;
}

}  // namespace ag::vo
