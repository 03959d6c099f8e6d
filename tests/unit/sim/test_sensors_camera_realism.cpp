// CameraSensor: noise, auto-exposure, motion blur and vignetting measured on rendered frames against the
// model's own formulas, and the determinism the team runner relies on (bands, frames rendered ahead).
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "airground/sim/camera.hpp"
#include "test_sensors_world.hpp"

namespace ag::sim {
namespace {

using testing::fill_cells;
using testing::fill_rect;
using testing::flat_world;

CameraModel half_model() { return CameraModel{}.scaled(0.5); }

CameraShading untextured() {
  CameraShading sh;
  sh.detail_texture = false;  // a flat patch renders at its albedo exactly
  return sh;
}

World grey_world(int level) {
  World w = flat_world(400, 400, 0.25, -50.0, 50.0, ClassId::kRoad);
  w.albedo.setTo(cv::Scalar(level, level, level));
  return w;
}

// Buildings, trees and cars on sloping ground, so that blur and band edges cross height steps.
World town() {
  World w = flat_world(320, 320, 0.25, -40.0, 40.0, ClassId::kRoad);
  const GridGeometry& g = w.grid();
  for (std::int32_t r = 0; r < g.height; ++r)
    for (std::int32_t c = 0; c < g.width; ++c) w.terrain.at<float>(r, c) = static_cast<float>(0.05 * g.x_of(c) - 0.02 * g.y_of(r));
  std::mt19937 rng(11);
  const auto uni = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  for (int i = 0; i < 30; ++i) {
    const int c = uni(0, 300), r = uni(0, 300);
    fill_cells(w, c, r, c + uni(8, 40), r + uni(8, 40), ClassId::kBuilding, static_cast<float>(uni(4, 25)), {150, 140, 130});
  }
  for (int i = 0; i < 60; ++i) {
    const int c = uni(0, 310), r = uni(0, 310);
    fill_cells(w, c, r, c + uni(3, 8), r + uni(3, 8), ClassId::kTree, static_cast<float>(uni(3, 12)), {30, 110, 40});
  }
  return w;
}

CameraShot shot_at(const CameraSensor& s, std::uint64_t frame) {
  CameraShot shot;
  shot.seed = 42;
  shot.frame = frame;
  shot.exposure = {s.exposure_s, s.gain};
  return shot;
}

// Mean and variance of every channel over a centred patch.
void patch_stats(const cv::Mat& rgb, int half, double& mean, double& var) {
  const cv::Rect roi(rgb.cols / 2 - half, rgb.rows / 2 - half, 2 * half, 2 * half);
  cv::Scalar m, sd;
  cv::meanStdDev(rgb(roi).reshape(1), m, sd);
  mean = m[0];
  var = sd[0] * sd[0];
}

TEST(CameraSensor, NoiseVarianceOnAFlatPatchIsShotPlusReadNoiseThroughTheGain) {
  CameraSensor s;
  s.noise = true;
  s.full_well_e = 2000;
  s.read_noise_e = 10;
  s.sensor_width_px = 640;  // one sensor pixel per rendered pixel
  s.exposure_s = s.full_scale_exposure_s;
  s.gain = 1.2;
  for (const int level : {40, 180}) {
    const World w = grey_world(level);
    const CameraRenderer cam(w, half_model(), untextured(), s);
    CameraFrame f;
    cam.render({0, 0, 40, 0, 0, 0}, f, 0, shot_at(s, 1));
    double mean = 0, var = 0;
    patch_stats(f.rgb, 100, mean, var);
    // Electrons e = level / 255 * full well; var(e) = e + read^2; DN = e * gain * 255 / full well, rounded.
    const double e = level / 255.0 * s.full_well_e;
    const double k = s.gain * 255.0 / s.full_well_e;
    const double expect = k * k * (e + s.read_noise_e * s.read_noise_e) + 1.0 / 12.0;
    SCOPED_TRACE("level " + std::to_string(level));
    EXPECT_NEAR(mean, s.gain * level, 0.15);
    EXPECT_NEAR(var / expect, 1.0, 0.04) << "measured " << var << ", model " << expect;
  }

  // Rendered at half the sensor's width, a pixel averages four: a quarter of the variance in DN.
  s.sensor_width_px = 1280;
  const World w = grey_world(180);
  const CameraRenderer cam(w, half_model(), untextured(), s);
  CameraFrame f;
  cam.render({0, 0, 40, 0, 0, 0}, f, 0, shot_at(s, 1));
  double mean = 0, var = 0;
  patch_stats(f.rgb, 100, mean, var);
  const double e = 180 / 255.0 * 4 * s.full_well_e;
  const double k = s.gain * 255.0 / (4 * s.full_well_e);
  EXPECT_NEAR(var / (k * k * (e + 4 * s.read_noise_e * s.read_noise_e) + 1.0 / 12.0), 1.0, 0.05);
}

TEST(CameraSensor, NoiseIsAFunctionOfSeedFrameAndPixelOnly) {
  CameraSensor s;
  s.noise = true;
  const World w = town();
  const CameraRenderer cam(w, half_model(), {}, s);
  const Pose3 pose{1, 2, 45, 0.02, 0.01, -0.3};
  CameraFrame a, b, c;
  cam.render(pose, a, 0, shot_at(s, 7));
  cam.render(pose, b, 0, shot_at(s, 8));
  cam.render(pose, c, 0, shot_at(s, 7));
  EXPECT_EQ(cv::norm(a.rgb, c.rgb, cv::NORM_INF), 0.0) << "the same seed and frame gave other pixels";
  EXPECT_GT(cv::norm(a.rgb, b.rgb, cv::NORM_L1) / static_cast<double>(a.rgb.total()), 0.5) << "noise frozen across frames";
  CameraShot other = shot_at(s, 7);
  other.seed = 43;
  cam.render(pose, c, 0, other);
  EXPECT_GT(cv::norm(a.rgb, c.rgb, cv::NORM_L1) / static_cast<double>(a.rgb.total()), 0.5) << "seed ignored";
}

TEST(CameraSensor, VignettingCornerOverCentreIsTheParameter) {
  const World w = grey_world(250);
  for (const double corner : {0.5, 0.8}) {
    CameraSensor s;
    s.vignetting = true;
    s.corner_illumination = corner;
    const CameraModel m = half_model();
    const CameraRenderer cam(w, m, untextured(), s);
    CameraFrame f;
    cam.render({0, 0, 40, 0, 0, 0}, f);
    const double centre = f.rgb.at<cv::Vec3b>(m.height / 2, m.width / 2)[1];
    const cv::Point corners[] = {{0, 0}, {m.width - 1, 0}, {0, m.height - 1}, {m.width - 1, m.height - 1}};
    double lowest = 1.0;
    for (const cv::Point& p : corners) lowest = std::min(lowest, f.rgb.at<cv::Vec3b>(p)[1] / centre);
    SCOPED_TRACE("corner " + std::to_string(corner));
    EXPECT_NEAR(centre, 250.0, 0.6);
    EXPECT_NEAR(lowest, corner, 0.006);
    // In between it follows cos(theta)^k of the pixel's own ray.
    const double k = std::log(corner) / std::log(static_cast<double>(cam.pixel_ray(0, 0).z()));
    for (const cv::Point p : {cv::Point(100, 80), cv::Point(500, 300), cv::Point(320, 20)})
      EXPECT_NEAR(f.rgb.at<cv::Vec3b>(p)[1], 250.0 * std::pow(static_cast<double>(cam.pixel_ray(p.x, p.y).z()), k), 0.6);
  }
}

// Second central moment [px^2] of the line spread of a horizontal edge: the derivative of the mean row
// profile over a band of columns.
double edge_spread_variance(const cv::Mat& rgb, int row0, int row1) {
  std::vector<double> esf;
  for (int r = row0; r < row1; ++r) {
    double sum = 0;
    for (int c = 200; c < 440; ++c) sum += rgb.at<cv::Vec3b>(r, c)[1];
    esf.push_back(sum / 240.0);
  }
  double w = 0, m1 = 0, m2 = 0;
  for (std::size_t i = 1; i < esf.size(); ++i) {
    const double d = esf[i] - esf[i - 1], x = static_cast<double>(i) - 0.5;
    w += d;
    m1 += d * x;
    m2 += d * x * x;
  }
  m1 /= w;
  return m2 / w - m1 * m1;
}

TEST(CameraSensor, BlurLengthIsSpeedTimesExposureTimesFocalOverHeight) {
  // West dark, east bright: facing east, the edge is a horizontal line across the image.
  World w = grey_world(40);
  fill_rect(w, 0.1, -50, 50, 50, ClassId::kRoad, 0.0f, {200, 200, 200});
  CameraSensor s;
  s.motion_blur = true;
  s.blur_max_samples = 63;
  s.exposure_s = s.exposure_max_s = s.full_scale_exposure_s = 0.1;  // brightness as the ideal camera
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m, untextured(), s);
  const Pose3 pose{0, 0, 40, 0, 0, 0};
  CameraShot still = shot_at(s, 1), moving = still;
  moving.velocity = {10.0, 0.0, 0.0};  // [m/s] east, along the image's up
  const double expect = 10.0 * 0.1 * m.fy / 40.0;
  EXPECT_NEAR(cam.blur_length_px(pose, moving), expect, 1e-9);

  CameraFrame sharp, blurred;
  cam.render(pose, sharp, 0, still);
  cam.render(pose, blurred, 0, moving);
  EXPECT_EQ(sharp.blur_samples, 1);
  const int k = blurred.blur_samples;
  EXPECT_EQ(k, 2 * static_cast<int>(std::ceil(expect)) + 1);
  const double added = edge_spread_variance(blurred.rgb, 150, 250) - edge_spread_variance(sharp.rgb, 150, 250);
  // k evenly spaced samples over a length L spread as L^2 (1 - 1/k^2) / 12.
  const double measured = std::sqrt(12.0 * added / (1.0 - 1.0 / (k * k)));
  EXPECT_NEAR(measured / expect, 1.0, 0.03) << "blur " << measured << " px, expected " << expect;
  EXPECT_EQ(cv::norm(sharp.cls, blurred.cls, cv::NORM_INF), 0.0) << "class and depth are the frame's pose's";

  // Twice the height, half the blur.
  const Pose3 high{0, 0, 80, 0, 0, 0};
  EXPECT_NEAR(cam.blur_length_px(high, moving), expect / 2, 1e-9);
  cam.render(high, sharp, 0, still);
  cam.render(high, blurred, 0, moving);
  const int k2 = blurred.blur_samples;
  const double added2 = edge_spread_variance(blurred.rgb, 150, 250) - edge_spread_variance(sharp.rgb, 150, 250);
  EXPECT_NEAR(std::sqrt(12.0 * added2 / (1.0 - 1.0 / (k2 * k2))) / (expect / 2), 1.0, 0.05);

  // A yaw rate sweeps the corners: r * omega * t there, nothing at the centre.
  CameraShot turning = still;
  turning.yaw_rate = 0.5;
  const double r_corner = std::hypot(m.cx, m.cy);
  EXPECT_NEAR(cam.blur_length_px(pose, turning), r_corner * 0.5 * 0.1, 1e-9);
}

TEST(CameraSensor, AutoExposureSettlesOnTheTargetAfterABrightnessStepWithinItsLimits) {
  CameraSensor s;
  s.noise = true;
  s.auto_exposure = true;
  const World bright = grey_world(200), dark = grey_world(50), night = grey_world(0);
  const CameraModel m = half_model();
  const CameraRenderer on_bright(bright, m, {}, s), on_dark(dark, m, {}, s), at_night(night, m, {}, s);
  CameraAutoExposure ae(s);
  CameraFrame f;
  std::uint64_t frame = 0;
  const auto step = [&](const CameraRenderer& cam) {
    CameraShot shot = shot_at(s, frame++);
    shot.exposure = ae.next();
    cam.render({0, 0, 40, 0, 0, 0}, f, 0, shot);
    ae.observe(f);
    EXPECT_GE(f.shot.exposure.exposure_s, s.exposure_min_s);
    EXPECT_LE(f.shot.exposure.exposure_s, s.exposure_max_s);
    EXPECT_GE(f.shot.exposure.gain, 1.0);
    EXPECT_LE(f.shot.exposure.gain, s.gain_max);
    return ae.last_mean();
  };
  const auto settled = [&](double mean) { return std::abs(mean / s.ae_target - 1.0) < 0.05; };
  for (int i = 0; i < 12; ++i) step(on_bright);
  EXPECT_TRUE(settled(step(on_bright)));
  const double brighter_exposure = f.shot.exposure.exposure_s * f.shot.exposure.gain;

  // A 4x darker scene: the first frame is exposed for the old one (the loop lags), then it settles.
  const double first = step(on_dark);
  EXPECT_NEAR(first, s.ae_target / 4, 0.03);
  int frames = 1;
  while (!settled(step(on_dark)) && frames < 30) ++frames;
  EXPECT_GE(frames, 3) << "settled faster than a real loop";
  EXPECT_LE(frames, 8);
  EXPECT_NEAR(f.shot.exposure.exposure_s * f.shot.exposure.gain / brighter_exposure, 4.0, 0.4);
  for (int i = 0; i < 5; ++i) EXPECT_TRUE(settled(step(on_dark))) << "did not hold";

  // Far too dark: the longest exposure, then the highest gain, never beyond.
  for (int i = 0; i < 40; ++i) step(at_night);
  EXPECT_DOUBLE_EQ(f.shot.exposure.exposure_s, s.exposure_max_s);
  EXPECT_DOUBLE_EQ(f.shot.exposure.gain, s.gain_max);
  // And back in the light: gain first back to 1, the exposure inside its limits.
  for (int i = 0; i < 40; ++i) step(on_bright);
  EXPECT_DOUBLE_EQ(f.shot.exposure.gain, 1.0);
  EXPECT_TRUE(settled(ae.last_mean()));
}

TEST(CameraSensor, AutoExposureOffKeepsTheFixedExposure) {
  CameraSensor s;
  s.exposure_s = 2e-4;
  CameraAutoExposure ae(s);
  const World w = grey_world(10);
  const CameraRenderer cam(w, half_model(), untextured(), s);
  CameraFrame f;
  cam.render({0, 0, 40, 0, 0, 0}, f, 0, shot_at(s, 0));
  ae.observe(f);
  EXPECT_DOUBLE_EQ(ae.next().exposure_s, 2e-4);
  EXPECT_DOUBLE_EQ(ae.next().gain, 1.0);
  EXPECT_EQ(f.rgb.at<cv::Vec3b>(200, 320)[0], 7) << "10 x 2/3 of the full-scale exposure";
}

// Everything on: the band split and the order frames are rendered in change nothing.
TEST(CameraSensor, PixelsDependOnSeedFrameAndPoseNotOnBandsOrOrder) {
  CameraSensor s;
  s.noise = s.auto_exposure = s.motion_blur = s.vignetting = true;
  s.exposure_max_s = 0.02;
  s.full_scale_exposure_s = 0.03;  // the shot below at gain 2: the ideal camera's brightness
  const World w = town();
  const CameraModel m = half_model();
  const CameraRenderer cam(w, m, {}, s);
  const Pose3 pose{1, 2, 45, 0.02, 0.01, -0.3};
  CameraShot shot = shot_at(s, 5);
  shot.exposure = {0.015, 2.0};
  shot.velocity = {4.0, -3.0, 0.5};
  shot.yaw_rate = 0.3;
  CameraFrame whole, parts, other;
  cam.render(pose, whole, 0, shot);
  EXPECT_GT(whole.blur_samples, 1);
  cam.render(pose, other, 0, shot_at(s, 6));  // another frame in between
  cam.prepare(pose, parts, 0, shot);
  for (const int b : {7, 2, 0, 5, 3, 1, 6, 4})  // bands in any order
    cam.render_rows(pose, m.height * b / 8, m.height * (b + 1) / 8, parts);
  EXPECT_EQ(cv::norm(whole.rgb, parts.rgb, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(whole.cls, parts.cls, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(whole.depth, parts.depth, cv::NORM_INF), 0.0);
  cam.prepare(pose, parts, 0, shot);
  // 16 rows each, as the runner's prefetch splits them.
  for (int b = 0; b < 25; ++b) cam.render_rows(pose, m.height * b / 25, m.height * (b + 1) / 25, parts);
  EXPECT_EQ(cv::norm(whole.rgb, parts.rgb, cv::NORM_INF), 0.0);
}

// Blur samples from moved eyes start their casts where the tile's bound says: the same as casting
// every one of them from its eye.
TEST(CameraSensor, BlurSamplesWithTileStartEqualCastsFromTheEye) {
  CameraSensor s;
  s.motion_blur = true;
  s.exposure_s = s.exposure_max_s = s.full_scale_exposure_s = 0.05;
  const World w = town();
  CameraShading fast, slow;
  slow.tile_start = false;
  const CameraRenderer a(w, half_model(), fast, s), b(w, half_model(), slow, s);
  CameraShot shot = shot_at(s, 1);
  shot.velocity = {6.0, 2.0, -1.5};
  shot.yaw_rate = -0.4;
  CameraFrame fa, fb;
  const Pose3 pose{-3, 4, 30, 0.03, -0.02, 0.9};
  a.render(pose, fa, 0, shot);
  b.render(pose, fb, 0, shot);
  EXPECT_GT(fa.blur_samples, 3);
  EXPECT_EQ(cv::norm(fa.rgb, fb.rgb, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(fa.depth, fb.depth, cv::NORM_INF), 0.0);
}

TEST(CameraSensor, ZeroEffectsGiveTheIdealCamera) {
  const World w = town();
  const CameraModel m = half_model();
  const CameraRenderer ideal(w, m);
  CameraSensor s;
  s.motion_blur = true;  // at rest: nothing to blur
  s.vignetting = true;
  s.corner_illumination = 1.0;
  s.auto_exposure = true;  // the first frame at the full-scale exposure
  const CameraRenderer zero(w, m, {}, s);
  const Pose3 pose{1, 2, 45, 0.02, 0.01, -0.3};
  CameraFrame a, b;
  ideal.render(pose, a);
  zero.render(pose, b, 0, shot_at(s, 3));
  EXPECT_EQ(cv::norm(a.rgb, b.rgb, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0);
}

// 64-bit FNV-1a over the three images.
std::uint64_t frame_hash(const CameraFrame& f) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (const cv::Mat* m : {&f.rgb, &f.cls, &f.depth}) {
    for (int r = 0; r < m->rows; ++r) {
      const auto* p = m->ptr<std::uint8_t>(r);
      for (std::size_t i = 0; i < static_cast<std::size_t>(m->cols) * m->elemSize(); ++i) h = (h ^ p[i]) * 0x100000001b3ULL;
    }
  }
  return h;
}

// The default sensor is today's renderer bit for bit: hashes of frames rendered before the sensor model
// existed (x86-64; another architecture may round the shading differently).
TEST(CameraSensor, EverythingOffIsTheRendererBeforeTheSensorModel) {
#if defined(__x86_64__)
  const World w = town();
  CameraShading shadows;
  shadows.shadows = true;
  const CameraRenderer plain(w, half_model(), CameraShading{}, CameraSensor{});
  const CameraRenderer shaded(w, half_model(), shadows, CameraSensor{});
  CameraFrame f;
  plain.render({1, 2, 45, 0.02, 0.01, -0.3}, f);
  EXPECT_EQ(frame_hash(f), 4665483870192527982ULL);
  shaded.render({-3, 4, 30, 0.03, -0.02, 0.9}, f);
  EXPECT_EQ(frame_hash(f), 18336321886694310184ULL);
#else
  GTEST_SKIP() << "hashes recorded on x86-64";
#endif
}

TEST(CameraSensor, YamlSectionWithUnitsAndClearErrors) {
  const char* yaml = R"(camera_sensor:
  noise: true
  full_well_e: 6000
  read_noise_e: 3.5
  auto_exposure: true
  exposure_max_s: 0.002
  motion_blur: true
  blur_max_samples: 9
  vignetting: true
  corner_illumination: 0.7
)";
  auto s = CameraSensor::load_string(yaml, "test.yaml");
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_TRUE(s->noise && s->auto_exposure && s->motion_blur && s->vignetting);
  EXPECT_DOUBLE_EQ(s->full_well_e, 6000);
  EXPECT_DOUBLE_EQ(s->exposure_max_s, 0.002);
  EXPECT_EQ(s->blur_max_samples, 9);
  EXPECT_DOUBLE_EQ(s->gain_max, CameraSensor{}.gain_max);
  EXPECT_TRUE(CameraModel::load_string(yaml, "test.yaml").ok()) << "the other sections ignore this one";

  const auto error_of = [](const char* text) {
    auto r = CameraSensor::load_string(text, "bad.yaml");
    EXPECT_FALSE(r.ok()) << text;
    return r.ok() ? std::string() : r.error().message;
  };
  EXPECT_NE(error_of("camera_sensor:\n  full_well_e: -5\n").find("camera_sensor.full_well_e"), std::string::npos);
  EXPECT_NE(error_of("camera_sensor:\n  corner_illumination: 1.5\n").find("camera_sensor.corner_illumination"), std::string::npos);
  EXPECT_NE(error_of("camera_sensor:\n  noise: loud\n").find("camera_sensor.noise"), std::string::npos);
  EXPECT_NE(error_of("camera_sensor:\n  shot_noise: true\n").find("camera_sensor.shot_noise"), std::string::npos);
  const std::string range = error_of("camera_sensor:\n  exposure_s: 0.01\n");
  EXPECT_NE(range.find("camera_sensor.exposure_s"), std::string::npos) << range;
  EXPECT_NE(range.find("exposure_max_s"), std::string::npos) << range;
  EXPECT_NE(range.find("bad.yaml"), std::string::npos) << range;
  EXPECT_NE(error_of("camera_sensor:\n  blur_max_samples: 8\n").find("camera_sensor.blur_max_samples"), std::string::npos);
  EXPECT_NE(error_of("camera_sensor:\n  gain: 20\n").find("camera_sensor.gain"), std::string::npos);

  CameraSensor bad;
  bad.gain = 0.5;
  EXPECT_THROW(CameraRenderer(grey_world(1), half_model(), {}, bad), std::invalid_argument);

  // The shipped file: the real camera, every effect on.
  auto file = CameraSensor::load_file(std::string(AG_SOURCE_DIR) + "/config/sensors/camera.yaml");
  ASSERT_TRUE(file.ok()) << file.error().message;
  EXPECT_TRUE(file->noise && file->auto_exposure && file->motion_blur && file->vignetting);
  EXPECT_FALSE(CameraSensor{}.active()) << "a default-constructed sensor is the ideal camera";
  // A camera file without the section: the robots' real camera (field mode), every effect on.
  auto bare = CameraSensor::load_string("camera:\n  width: 640\n", "bare.yaml");
  ASSERT_TRUE(bare.ok()) << bare.error().message;
  EXPECT_TRUE(bare->noise && bare->auto_exposure && bare->motion_blur && bare->vignetting);
  EXPECT_TRUE(CameraSensor::field().active());
}

}  // namespace
}  // namespace ag::sim
