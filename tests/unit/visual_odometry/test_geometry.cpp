// The VO's geometry on synthetic scenes with known truth: known-rotation translation (direction, sign,
// outliers), triangulation and its refusals, the camera pose (what its rotation-holding RANSAC can and
// cannot recover) and the gravity prior's pull on the up direction.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include "airground/visual_odometry/geometry.hpp"

namespace ag::vo {
namespace {

constexpr double kFx = 483.5;
constexpr double kDeg = M_PI / 180.0;

double angle_deg(const Eigen::Matrix3d& R) { return Eigen::AngleAxisd(R).angle() / kDeg; }
double angle_between_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) / kDeg;
}

// A nadir camera 40 m above uneven ground (camera frame: z down toward the ground).
CameraPose nadir_pose(const Eigen::Vector3d& centre, const Eigen::Vector3d& tilt_rad) {
  CameraPose p;
  p.R = so3_exp(tilt_rad);
  p.t = -p.R * centre;
  return p;
}

// World points seen by camera `p` inside a 600x380 px window, depth 30-50 m.
std::vector<Eigen::Vector3d> scene(const CameraPose& p, std::size_t n, std::mt19937& rng) {
  std::uniform_real_distribution<double> ux(-300.0 / kFx, 300.0 / kFx), uy(-190.0 / kFx, 190.0 / kFx), depth(30.0, 50.0);
  const CameraPose w = inverse(p);
  std::vector<Eigen::Vector3d> X;
  for (std::size_t i = 0; i < n; ++i) {
    const double z = depth(rng);
    X.push_back(w.to_camera(Eigen::Vector3d(ux(rng) * z, uy(rng) * z, z)));
  }
  return X;
}

Eigen::Vector2d project(const CameraPose& p, const Eigen::Vector3d& X) {
  const Eigen::Vector3d c = p.to_camera(X);
  return c.head<2>() / c.z();
}

struct TwoViewCase {
  std::vector<Eigen::Vector2d> x1, x2;
  std::vector<std::uint8_t> outlier;
};

TwoViewCase two_view(const CameraPose& c1, const CameraPose& c2, double noise_px, double outlier_share, std::uint32_t seed,
                     std::size_t n = 400) {
  std::mt19937 rng(seed);
  const std::vector<Eigen::Vector3d> X = scene(c1, n, rng);
  std::normal_distribution<double> noise(0.0, noise_px / kFx);
  std::uniform_real_distribution<double> u01(0.0, 1.0), ux(-300.0 / kFx, 300.0 / kFx), uy(-190.0 / kFx, 190.0 / kFx);
  TwoViewCase c;
  for (const Eigen::Vector3d& p : X) {
    c.x1.push_back(project(c1, p) + Eigen::Vector2d(noise(rng), noise(rng)));
    const bool out = u01(rng) < outlier_share;
    c.x2.push_back(out ? Eigen::Vector2d(ux(rng), uy(rng)) : Eigen::Vector2d(project(c2, p) + Eigen::Vector2d(noise(rng), noise(rng))));
    c.outlier.push_back(out ? 1 : 0);
  }
  return c;
}

// Known rotation, 5 m baseline at 30-50 m, 600 points, 30 % outliers, 0.3 px noise: the direction
// within 0.2 deg, the sign with the points in front, the outliers marked. (At the VO's 2 m start baseline
// the component along the optical axis is only known to ~0.25 deg at this noise -- each point's depth is
// free, and forward motion only turns the epipolar lines by y * tz / |t| -- so 0.2 deg needs more baseline.)
constexpr double kBaseline = 5.0;

TEST(TranslationKnownRotation, RecoversTheDirectionAndSignWithThirtyPercentOutliers) {
  const Eigen::Vector3d directions[] = {{1, 0, 0}, {-1, 0, 0}, {0.3, -1, 0}, {0.5, 0.5, 0.4}, {0.2, 0.1, -1}};
  std::uint32_t seed = 1;
  for (const Eigen::Vector3d& d : directions) {
    const CameraPose c1 = nadir_pose({0, 0, 0}, {0.02, -0.03, 0.1});
    // Camera 2: moved 2 m along d (in camera 1's frame), rotated by a few degrees.
    const Eigen::Vector3d centre2 = inverse(c1).R * (kBaseline * d.normalized());
    const CameraPose c2 = nadir_pose(centre2, {0.05, 0.04, 0.2});
    const TwoViewCase tv = two_view(c1, c2, 0.3, 0.3, seed++, 600);
    const CameraPose rel = compose(inverse(c1), c2);  // camera 1 -> camera 2
    SampleStream rng(42);
    RansacParams rp;
    rp.iterations = 100;
    Eigen::Vector3d t;
    std::vector<std::uint8_t> inl(tv.x1.size());
    ASSERT_TRUE(translation_known_rotation(tv.x1, tv.x2, rel.R, rp, rng, t, inl)) << d.transpose();
    EXPECT_NEAR(t.norm(), 1.0, 1e-9);
    std::printf("direction (%.1f %.1f %.1f): error %.3f deg\n", d.x(), d.y(), d.z(), angle_between_deg(t, rel.t));
    // Mostly along the optical axis the direction is the least determined (see above): 0.285 deg measured
    // on aarch64 (0.2 on x86-64, same data; FMA changes the RANSAC's path), so 0.35 there, 0.2 elsewhere.
    const double bound = std::fabs(d.normalized().z()) > 0.9 ? 0.35 : 0.2;
    EXPECT_LT(angle_between_deg(t, rel.t), bound) << "direction " << d.transpose() << " got " << t.transpose() << " want "
                                                  << rel.t.normalized().transpose();
    int wrong = 0, inliers = 0;
    for (std::size_t i = 0; i < inl.size(); ++i) {
      inliers += inl[i];
      wrong += (inl[i] && tv.outlier[i]) ? 1 : 0;
    }
    EXPECT_GT(inliers, 380);
    EXPECT_LT(wrong, 15) << "outliers taken as inliers (a random point may lie near its epipolar line)";
  }
}

TEST(TranslationKnownRotation, RefusesWithoutConsensus) {
  const CameraPose c1 = nadir_pose({0, 0, 0}, {0, 0, 0});
  const CameraPose c2 = nadir_pose({2, 0, 0}, {0, 0, 0});
  const TwoViewCase tv = two_view(c1, c2, 0.3, 0.9, 7);
  SampleStream rng(1);
  Eigen::Vector3d t;
  std::vector<std::uint8_t> inl(tv.x1.size());
  EXPECT_FALSE(translation_known_rotation(tv.x1, tv.x2, compose(inverse(c1), c2).R, RansacParams{}, rng, t, inl));
  std::vector<Eigen::Vector2d> few(tv.x1.begin(), tv.x1.begin() + 5);
  EXPECT_FALSE(translation_known_rotation(few, few, Eigen::Matrix3d::Identity(), RansacParams{}, rng, t, inl));
}

TEST(TranslationKnownRotation, IsDeterministicForAGivenSeed) {
  const CameraPose c1 = nadir_pose({0, 0, 0}, {0, 0, 0});
  const CameraPose c2 = nadir_pose({1.5, 0.5, 0}, {0.01, 0, 0});
  const TwoViewCase tv = two_view(c1, c2, 0.3, 0.3, 3);
  const Eigen::Matrix3d R = compose(inverse(c1), c2).R;
  Eigen::Vector3d a, b;
  std::vector<std::uint8_t> ia(tv.x1.size()), ib(tv.x1.size());
  SampleStream r1(9), r2(9);
  ASSERT_TRUE(translation_known_rotation(tv.x1, tv.x2, R, RansacParams{}, r1, a, ia));
  ASSERT_TRUE(translation_known_rotation(tv.x1, tv.x2, R, RansacParams{}, r2, b, ib));
  EXPECT_EQ(a, b);
  EXPECT_EQ(ia, ib);
}

TEST(Triangulate, RecoversThePointAndRefusesSmallParallaxAndPointsBehind) {
  const CameraPose a = nadir_pose({0, 0, 0}, {0.01, 0.02, 0.0});
  const CameraPose b = nadir_pose({3, 1, 0.2}, {-0.02, 0.01, 0.1});
  const Eigen::Vector3d X = inverse(a).to_camera(Eigen::Vector3d(2.0, -3.0, 40.0));
  Eigen::Vector3d Y;
  ASSERT_TRUE(triangulate(a, project(a, X), b, project(b, X), 1.0 * kDeg, Y));
  EXPECT_LT((Y - X).norm(), 1e-6);
  EXPECT_LT(reprojection_error2(a, Y, project(a, X)), 1e-18);

  // 3 m at 40 m is 4.3 deg of parallax: refused above that threshold, accepted below.
  EXPECT_FALSE(triangulate(a, project(a, X), b, project(b, X), 5.0 * kDeg, Y));
  EXPECT_TRUE(triangulate(a, project(a, X), b, project(b, X), 4.0 * kDeg, Y));
  // A tiny baseline: nearly parallel rays.
  const CameraPose near_b = nadir_pose({0.1, 0, 0}, {0.01, 0.02, 0.0});
  EXPECT_FALSE(triangulate(a, project(a, X), near_b, project(near_b, X), 1.0 * kDeg, Y));

  // A point behind both cameras projects to valid-looking coordinates; the rays meet behind: refused.
  const Eigen::Vector3d B = inverse(a).to_camera(Eigen::Vector3d(2.0, -3.0, -40.0));
  ASSERT_LT(a.to_camera(B).z(), 0);
  ASSERT_LT(b.to_camera(B).z(), 0);
  EXPECT_FALSE(triangulate(a, project(a, B), b, project(b, B), 1.0 * kDeg, Y));
  // Observations that diverge (the rays would meet behind the cameras).
  const Eigen::Vector2d xa = project(a, X);
  const Eigen::Vector2d xb = xa + Eigen::Vector2d(0.2, 0.0);  // b, 3 m to the right, sees it further right: behind
  EXPECT_FALSE(triangulate(a, xa, nadir_pose({3, 0, 0}, {0.01, 0.02, 0.0}), xb, 1.0 * kDeg, Y));
  EXPECT_TRUE(std::isinf(reprojection_error2(a, B, xa)));
}

struct PnpCase {
  std::vector<Eigen::Vector3d> X;
  std::vector<Eigen::Vector2d> x;
  CameraPose truth;
};

PnpCase pnp_case(std::size_t n, double noise_px, double outlier_share, std::uint32_t seed) {
  std::mt19937 rng(seed);
  PnpCase c;
  c.truth = nadir_pose({5, -2, 1}, {0.03, -0.05, 0.4});
  c.X = scene(c.truth, n, rng);
  std::normal_distribution<double> noise(0.0, noise_px / kFx);
  std::uniform_real_distribution<double> u01(0.0, 1.0), ux(-300.0 / kFx, 300.0 / kFx), uy(-190.0 / kFx, 190.0 / kFx);
  for (const Eigen::Vector3d& X : c.X)
    c.x.push_back(u01(rng) < outlier_share ? Eigen::Vector2d(ux(rng), uy(rng))
                                           : Eigen::Vector2d(project(c.truth, X) + Eigen::Vector2d(noise(rng), noise(rng))));
  return c;
}

GravityPrior up_of(const CameraPose& p) { return GravityPrior{p.R * Eigen::Vector3d::UnitZ(), true}; }

// The prediction: the true pose with a rotation error about a tilted axis and the centre 1.5 m off.
CameraPose predicted(const CameraPose& truth, double rot_err_deg) {
  CameraPose p;
  p.R = so3_exp(Eigen::Vector3d(0.6, -0.8, 0.3).normalized() * rot_err_deg * kDeg) * truth.R;
  p.t = -p.R * (truth.centre() + Eigen::Vector3d(1.0, -1.0, 0.5));
  return p;
}

// solve_pose holds the predicted rotation through its RANSAC (two points fix the translation), then
// refines all six degrees of freedom over the inliers. With the autopilot's prediction (well within
// 0.5 deg) it recovers the pose: rotation within 0.05 deg, centre within 0.5 % of the depth.
TEST(SolvePose, RecoversThePoseFromAPredictionWithinHalfADegree) {
  for (const double err_deg : {0.0, 0.2, 0.5}) {
    for (const bool gravity : {false, true}) {
      const PnpCase c = pnp_case(300, 0.5, 0.2, 11);
      CameraPose pose = predicted(c.truth, err_deg);
      SampleStream rng(5);
      RansacParams rp;
      rp.iterations = 30;
      PoseRefineParams pp;
      std::vector<std::uint8_t> inl(c.X.size());
      const GravityPrior g = gravity ? up_of(c.truth) : GravityPrior{};
      const int n = solve_pose(c.X, c.x, g, rp, pp, rng, pose, inl);
      std::printf("prediction %.1f deg off, gravity %d: %d inliers, rotation %.4f deg, centre %.3f m\n", err_deg, gravity ? 1 : 0, n,
                  angle_deg(pose.R * c.truth.R.transpose()), (pose.centre() - c.truth.centre()).norm());
      EXPECT_GT(n, 200) << err_deg << " deg";
      EXPECT_LT(angle_deg(pose.R * c.truth.R.transpose()), 0.05) << err_deg << " deg, gravity " << gravity;
      EXPECT_LT((pose.centre() - c.truth.centre()).norm(), 0.005 * 40.0) << err_deg << " deg, gravity " << gravity;
    }
  }
}

// What it cannot do: the RANSAC never moves the rotation, so from a prediction 10 deg off only the
// points where the rotation error is nearly a shift agree; the two refinements then turn the rotation
// most of the way (GN from a minority of central points, then over the grown set), but not to the
// 0.05 deg of a good prediction, and the 2 px inlier test cannot tell: it reports nearly every point.
// The VO therefore always predicts the rotation (the autopilot's, else constant rate) and bundle-adjusts.
TEST(SolvePose, AFarOffRotationPredictionIsOnlyPartlyRecovered) {
  const PnpCase c = pnp_case(300, 0.5, 0.0, 12);
  CameraPose pose = predicted(c.truth, 10.0);
  SampleStream rng(5);
  std::vector<std::uint8_t> inl(c.X.size());
  const int n = solve_pose(c.X, c.x, GravityPrior{}, RansacParams{}, PoseRefineParams{}, rng, pose, inl);
  const double err = angle_deg(pose.R * c.truth.R.transpose());
  std::printf("10 deg off: %d inliers, rotation %.3f deg, centre %.3f m\n", n, err, (pose.centre() - c.truth.centre()).norm());
  EXPECT_LT(err, 1.0) << "it moves toward the truth";
  // More refinement from there reaches the optimum: the limit is the iteration budget, not the model.
  PoseRefineParams more;
  more.iterations = 50;
  refine_pose(c.X, c.x, inl, GravityPrior{}, more, pose);
  EXPECT_LT(angle_deg(pose.R * c.truth.R.transpose()), 0.05);
}

TEST(SolvePose, RefusesTooFewPoints) {
  const PnpCase c = pnp_case(5, 0.5, 0.0, 13);
  CameraPose pose = c.truth;
  SampleStream rng(5);
  std::vector<std::uint8_t> inl(c.X.size());
  EXPECT_EQ(solve_pose(c.X, c.x, GravityPrior{}, RansacParams{}, PoseRefineParams{}, rng, pose, inl), 0);
}

// The gravity prior pulls the camera's up direction toward the autopilot's: with it off the refinement
// gives the vision's up (the truth), with a very tight sigma the prior's, and with the default in between.
TEST(RefinePose, TheGravityPriorPullsTheUpDirection) {
  const PnpCase c = pnp_case(300, 0.5, 0.0, 14);
  const Eigen::Vector3d true_up = c.truth.R * Eigen::Vector3d::UnitZ();
  GravityPrior g;
  g.valid = true;
  g.up_in_camera = so3_exp(Eigen::Vector3d(0.0, 1.0, 0.0) * 1.0 * kDeg) * true_up;  // 1 deg off the truth
  std::vector<std::uint8_t> use(c.X.size(), 1);
  auto up_after = [&](double sigma, bool valid) {
    CameraPose pose = c.truth;
    PoseRefineParams pp;
    pp.iterations = 20;
    pp.gravity_sigma_rad = sigma;
    GravityPrior gg = g;
    gg.valid = valid;
    refine_pose(c.X, c.x, use, gg, pp, pose);
    return Eigen::Vector3d(pose.R * Eigen::Vector3d::UnitZ());
  };
  // (0.0005 rad: with 300 points at 0.5 px the vision holds the up direction to ~0.03 deg, so the VO's
  // 0.005 rad barely moves it here; a comparable sigma must land in between.)
  const Eigen::Vector3d off = up_after(0.005, false), tight = up_after(1e-5, true), dflt = up_after(0.0005, true);
  EXPECT_LT(angle_between_deg(off, true_up), 0.05);
  EXPECT_LT(angle_between_deg(tight, g.up_in_camera), 0.01);
  std::printf("up vs truth: prior off %.3f deg, 0.0005 rad %.3f deg; that vs the prior %.3f deg\n", angle_between_deg(off, true_up),
              angle_between_deg(dflt, true_up), angle_between_deg(dflt, g.up_in_camera));
  EXPECT_GT(angle_between_deg(dflt, true_up), angle_between_deg(off, true_up) + 0.1) << "the prior pulls";
  EXPECT_LT(angle_between_deg(dflt, g.up_in_camera), 1.0 - 0.1) << "toward the prior";
  // A zero sigma switches the prior off.
  EXPECT_LT(angle_between_deg(up_after(0.0, true), off), 1e-6);
}

TEST(PoseAlgebra, InverseComposeAndExp) {
  const CameraPose a = nadir_pose({1, 2, 3}, {0.1, -0.2, 0.3});
  const CameraPose b = nadir_pose({-4, 0, 1}, {0.0, 0.4, -0.1});
  const Eigen::Vector3d X(3, -1, 20);
  EXPECT_LT((compose(a, b).to_camera(X) - b.to_camera(a.to_camera(X))).norm(), 1e-12);
  EXPECT_LT((compose(a, inverse(a)).to_camera(X) - X).norm(), 1e-12);
  EXPECT_LT((so3_exp(Eigen::Vector3d(0, 0, M_PI / 2)) * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 1e-12);
  EXPECT_LT((so3_exp(Eigen::Vector3d(1e-14, 0, 0)) - Eigen::Matrix3d::Identity()).norm(), 1e-13);
}

}  // namespace
}  // namespace ag::vo
