// Our sliding-window bundle adjustment against Ceres on the same synthetic windows: the same whitened
// reprojection residuals with the same Huber loss, the same gravity prior (R e_z - up) / sigma on the free
// keyframes, the same two fixed keyframes. Final costs and poses must agree; ours must descend.
#include <gtest/gtest.h>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "airground/visual_odometry/window_adjustment.hpp"

namespace ag::vo {
namespace {

constexpr double kFx = 483.5;
constexpr double kDeg = M_PI / 180.0;

struct Window {
  std::vector<CameraPose> truth, poses;
  std::vector<std::uint8_t> fixed;
  std::vector<GravityPrior> gravity;
  std::vector<Eigen::Vector3d> true_points, points;
  std::vector<BaObservation> obs;
};

// `kfs` keyframes 2 m apart at 40 m over ground within +-3 m, slightly tilted; `n` points, each seen by
// every keyframe whose 640x400 image holds it; 0.5 px noise, `outliers` of the observations 5-30 px off;
// gravity priors with 0.1 deg of error; the start perturbed by `rot_deg` / `pos_m` / `pt_m`.
Window make_window(int kfs, int n, double outliers, double rot_deg, double pos_m, double pt_m, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  Window w;
  for (int k = 0; k < kfs; ++k) {
    // World z up; the camera looks down (camera z = world -z), flying along world x.
    Eigen::Matrix3d down;
    down << 0, -1, 0, -1, 0, 0, 0, 0, -1;  // rows: camera axes in world (x right = -y world, y down = -x world)
    const Eigen::Vector3d tilt(0.02 * g(rng), 0.02 * g(rng), 0.01 * g(rng));
    CameraPose p;
    p.R = so3_exp(tilt) * down;
    const Eigen::Vector3d c(2.0 * k, 0.3 * g(rng), 40.0 + 0.3 * g(rng));
    p.t = -p.R * c;
    w.truth.push_back(p);
    w.fixed.push_back(k < 2 ? 1 : 0);
    GravityPrior gp;
    gp.valid = true;
    gp.up_in_camera = so3_exp(Eigen::Vector3d(g(rng), g(rng), 0.0) * 0.1 * kDeg / std::sqrt(2.0)) * (p.R * Eigen::Vector3d::UnitZ());
    w.gravity.push_back(gp);
  }
  std::uniform_real_distribution<double> px(-15.0, 25.0), py(-24.0, 24.0), pz(-3.0, 3.0);
  std::normal_distribution<double> noise(0.0, 0.5 / kFx);
  while (static_cast<int>(w.true_points.size()) < n) {
    const Eigen::Vector3d X(px(rng), py(rng), pz(rng));
    std::vector<BaObservation> seen;
    for (int k = 0; k < kfs; ++k) {
      const Eigen::Vector3d c = w.truth[static_cast<std::size_t>(k)].to_camera(X);
      const Eigen::Vector2d x = c.head<2>() / c.z();
      const double u = kFx * x.x() + 319.5, v = kFx * x.y() + 199.5;
      if (c.z() <= 0 || u < 0 || u > 639 || v < 0 || v > 399) continue;
      Eigen::Vector2d obs = x + Eigen::Vector2d(noise(rng), noise(rng));
      if (u01(rng) < outliers) {
        const double a = 2 * M_PI * u01(rng), r = (5.0 + 25.0 * u01(rng)) / kFx;
        obs += r * Eigen::Vector2d(std::cos(a), std::sin(a));
      }
      seen.push_back(BaObservation{k, static_cast<std::int32_t>(w.true_points.size()), obs});
    }
    if (seen.size() < 2) continue;
    w.true_points.push_back(X);
    w.obs.insert(w.obs.end(), seen.begin(), seen.end());
  }
  w.poses = w.truth;
  for (std::size_t k = 0; k < w.poses.size(); ++k) {
    if (w.fixed[k]) continue;
    const Eigen::Vector3d c = w.poses[k].centre() + pos_m * Eigen::Vector3d(g(rng), g(rng), g(rng));
    w.poses[k].R = so3_exp(Eigen::Vector3d(g(rng), g(rng), g(rng)) * rot_deg * kDeg) * w.poses[k].R;
    w.poses[k].t = -w.poses[k].R * c;
  }
  w.points = w.true_points;
  for (Eigen::Vector3d& X : w.points) X += pt_m * Eigen::Vector3d(g(rng), g(rng), g(rng));
  return w;
}

struct Reprojection {
  Eigen::Vector2d x;
  double inv_sigma;
  template <typename T>
  bool operator()(const T* aa, const T* t, const T* X, T* r) const {
    T p[3];
    ceres::AngleAxisRotatePoint(aa, X, p);
    p[0] += t[0];
    p[1] += t[1];
    p[2] += t[2];
    r[0] = (p[0] / p[2] - T(x.x())) * T(inv_sigma);
    r[1] = (p[1] / p[2] - T(x.y())) * T(inv_sigma);
    return true;
  }
};

struct Gravity {
  Eigen::Vector3d up;
  double inv_sigma;
  template <typename T>
  bool operator()(const T* aa, T* r) const {
    const T ez[3] = {T(0), T(0), T(1)};
    T p[3];
    ceres::AngleAxisRotatePoint(aa, ez, p);
    for (int i = 0; i < 3; ++i) r[i] = (p[i] - T(up[i])) * T(inv_sigma);
    return true;
  }
};

struct CeresResult {
  std::vector<CameraPose> poses;
  std::vector<Eigen::Vector3d> points;
  double initial_cost{0}, final_cost{0};
};

CeresResult solve_with_ceres(const Window& w, const WindowAdjustmentParams& p) {
  std::vector<std::array<double, 6>> cam(w.poses.size());
  for (std::size_t k = 0; k < w.poses.size(); ++k) {
    const Eigen::AngleAxisd aa(w.poses[k].R);
    const Eigen::Vector3d v = aa.angle() * aa.axis();
    cam[k] = {v.x(), v.y(), v.z(), w.poses[k].t.x(), w.poses[k].t.y(), w.poses[k].t.z()};
  }
  std::vector<Eigen::Vector3d> pts = w.points;
  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  ceres::HuberLoss huber(p.huber_sigmas);
  for (const BaObservation& o : w.obs) {
    auto* cost = new ceres::AutoDiffCostFunction<Reprojection, 2, 3, 3, 3>(new Reprojection{o.x, 1.0 / p.pixel_sigma});
    std::array<double, 6>& c = cam[static_cast<std::size_t>(o.keyframe)];
    problem.AddResidualBlock(cost, &huber, c.data(), c.data() + 3, pts[static_cast<std::size_t>(o.point)].data());
  }
  for (std::size_t k = 0; k < w.poses.size(); ++k) {
    if (w.fixed[k]) {
      problem.SetParameterBlockConstant(cam[k].data());
      problem.SetParameterBlockConstant(cam[k].data() + 3);
      continue;
    }
    if (p.gravity_sigma_rad > 0 && w.gravity[k].valid)
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Gravity, 3, 3>(new Gravity{w.gravity[k].up_in_camera, 1.0 / p.gravity_sigma_rad}),
                               nullptr, cam[k].data());
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_SCHUR;
  so.max_num_iterations = 200;
  so.function_tolerance = 1e-14;
  so.gradient_tolerance = 1e-14;
  so.parameter_tolerance = 1e-14;
  so.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  CeresResult r;
  r.initial_cost = summary.initial_cost;
  r.final_cost = summary.final_cost;
  for (const auto& c : cam) {
    CameraPose q;
    const Eigen::Vector3d v(c[0], c[1], c[2]);
    q.R = so3_exp(v);
    q.t = Eigen::Vector3d(c[3], c[4], c[5]);
    r.poses.push_back(q);
  }
  r.points = pts;
  return r;
}

double rot_deg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) { return Eigen::AngleAxisd(a * b.transpose()).angle() / kDeg; }

WindowAdjustmentParams params(int iterations) {
  WindowAdjustmentParams p;
  p.iterations = iterations;
  p.pixel_sigma = 1.0 / kFx;
  p.gravity_sigma_rad = 0.005;
  return p;
}

// 6 keyframes, 300 points, 0.5 px noise, 5 % outliers, the two oldest fixed, gravity priors: ours run to
// convergence and Ceres end at the same cost (within 1 %) and the same poses and points.
TEST(WindowAdjustment, AgreesWithCeresOnTheSameProblem) {
  for (const std::uint32_t seed : {1U, 2U, 3U}) {
    Window w = make_window(6, 300, 0.05, 0.3, 0.3, 0.3, seed);
    const WindowAdjustmentParams p = params(50);
    const CeresResult ref = solve_with_ceres(w, p);
    WindowAdjustment wa(12, 2000, 4000);
    const WindowAdjustmentReport rep = wa.solve(w.poses, w.fixed, w.gravity, w.points, w.obs, p);
    std::printf("seed %u: ours %d it, cost %.3f -> %.3f; ceres %.3f -> %.3f\n", seed, rep.iterations, rep.initial_cost, rep.final_cost,
                ref.initial_cost, ref.final_cost);
    EXPECT_NEAR(rep.initial_cost, ref.initial_cost, 1e-6 * ref.initial_cost) << "the same cost function";
    EXPECT_NEAR(rep.final_cost, ref.final_cost, 0.01 * ref.final_cost);
    EXPECT_EQ(rep.free_keyframes, 4);
    EXPECT_EQ(rep.points, 300);
    EXPECT_EQ(rep.observations, static_cast<int>(w.obs.size()));
    for (std::size_t k = 0; k < w.poses.size(); ++k) {
      // The cost agrees within 1 % on both platforms; the poses within 0.002 deg / 5 mm on x86-64 but up
      // to 0.012 deg / 9 mm on aarch64 (a flat valley the 50 iterations do not finish), hence these bounds.
      EXPECT_LT(rot_deg(w.poses[k].R, ref.poses[k].R), 0.02) << "keyframe " << k;
      EXPECT_LT((w.poses[k].centre() - ref.poses[k].centre()).norm(), 0.015) << "keyframe " << k;
      // And both near the truth (the two fixed keyframes hold the gauge).
      EXPECT_LT(rot_deg(w.poses[k].R, w.truth[k].R), 0.25) << "keyframe " << k;
      EXPECT_LT((w.poses[k].centre() - w.truth[k].centre()).norm(), 0.2) << "keyframe " << k;
    }
    // Points: a point whose few observations include an outlier that makes its rays diverge has its
    // optimum at infinity, where both solvers head at their own pace; the others must agree.
    std::vector<double> diff;
    for (std::size_t i = 0; i < w.points.size(); ++i)
      if ((ref.points[i] - w.true_points[i]).norm() < 5.0) diff.push_back((w.points[i] - ref.points[i]).norm());
    std::sort(diff.begin(), diff.end());
    ASSERT_GT(diff.size(), 285U);
    const double p50 = diff[diff.size() / 2], p95 = diff[diff.size() * 95 / 100];
    std::printf("  points vs ceres: p50 %.4f m, p95 %.4f m\n", p50, p95);
    EXPECT_LT(p50, 0.005);
    EXPECT_LT(p95, 0.03);
    // The fixed keyframes did not move.
    for (std::size_t k = 0; k < 2; ++k) {
      EXPECT_EQ(w.poses[k].t, w.truth[k].t);
      EXPECT_LT(rot_deg(w.poses[k].R, w.truth[k].R), 1e-9);
    }
  }
}

// Without gravity priors (sigma 0) the two agree too: the prior is not what makes them meet.
TEST(WindowAdjustment, AgreesWithCeresWithoutGravity) {
  Window w = make_window(6, 300, 0.05, 0.3, 0.3, 0.3, 4);
  WindowAdjustmentParams p = params(50);
  p.gravity_sigma_rad = 0.0;
  const CeresResult ref = solve_with_ceres(w, p);
  WindowAdjustment wa(12, 2000, 4000);
  const WindowAdjustmentReport rep = wa.solve(w.poses, w.fixed, w.gravity, w.points, w.obs, p);
  EXPECT_NEAR(rep.final_cost, ref.final_cost, 0.01 * ref.final_cost);
  for (std::size_t k = 0; k < w.poses.size(); ++k) EXPECT_LT((w.poses[k].centre() - ref.poses[k].centre()).norm(), 0.005) << k;
}

// With the VO's budget (a few iterations) from a perturbed start, the cost drops most of the way to
// Ceres' optimum and the poses move toward the truth.
TEST(WindowAdjustment, ReducesTheCostFromAPerturbedStartInFewIterations) {
  Window w = make_window(7, 300, 0.05, 0.5, 0.5, 0.5, 5);
  const WindowAdjustmentParams p = params(5);
  const CeresResult ref = solve_with_ceres(w, params(50));
  double before = 0;
  for (std::size_t k = 2; k < w.poses.size(); ++k) before += (w.poses[k].centre() - w.truth[k].centre()).norm();
  WindowAdjustment wa(12, 2000, 4000);
  const WindowAdjustmentReport rep = wa.solve(w.poses, w.fixed, w.gravity, w.points, w.obs, p);
  double after = 0;
  for (std::size_t k = 2; k < w.poses.size(); ++k) after += (w.poses[k].centre() - w.truth[k].centre()).norm();
  EXPECT_LE(rep.iterations, 5);
  EXPECT_LT(rep.final_cost, 0.1 * rep.initial_cost);
  EXPECT_LT(rep.final_cost, 1.05 * ref.final_cost) << "within 5 % of the optimum after 5 iterations";
  EXPECT_LT(after, 0.2 * before);
}

TEST(WindowAdjustment, RefusesAProblemLargerThanItsBuffersAndLeavesItUntouched) {
  Window w = make_window(6, 300, 0.0, 0.3, 0.3, 0.3, 6);
  const std::vector<CameraPose> start = w.poses;
  WindowAdjustment small(6, 100, 4000);
  const WindowAdjustmentReport rep = small.solve(w.poses, w.fixed, w.gravity, w.points, w.obs, params(5));
  EXPECT_EQ(rep.iterations, 0);
  for (std::size_t k = 0; k < w.poses.size(); ++k) EXPECT_EQ(w.poses[k].t, start[k].t);
}

}  // namespace
}  // namespace ag::vo
