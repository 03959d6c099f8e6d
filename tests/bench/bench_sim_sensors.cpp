// bench_sim_sensors: one-core speed of the simulated nadir camera (640x400 and 1280x800 frames/s) and
// of the Ouster LiDAR (64x512/1024/2048 scans, ms and rays/s) over a synthetic 500 m town.
// `bench_sim_sensors --dump DIR` also writes the rendered frames (rgb, class, depth PNGs) for a look;
// `--lidar-only` skips the camera, `--camera-only` the LiDAR. References measured in the same run: the
// camera with every cast from the eye (no tile start), the LiDAR with one full cast per ray.
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <random>
#include <string>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/planning/local_tracker.hpp"
#include "airground/sim/camera.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/raycast.hpp"
#include "bench_common.hpp"

namespace {

using ag::ClassId;
using ag::Pose3;
using ag::sim::World;

double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

cv::Vec3b shade_of(ClassId k, std::mt19937& rng, int spread) {
  const ag::Rgb c = ag::ClassTable::builtin().info(k).color;
  std::uniform_int_distribution<int> d(-spread, spread);
  const int s = d(rng);
  return {cv::saturate_cast<std::uint8_t>(c.r + s), cv::saturate_cast<std::uint8_t>(c.g + s),
          cv::saturate_cast<std::uint8_t>(c.b + s)};
}

// A 500 m x 500 m town at 0.25 m: a street grid, blocks of grass with buildings, tree crowns, parked cars,
// gravel yards and a pond, on gently rolling terrain.
World make_town() {
  constexpr std::int32_t kSize = 2000;
  World w;
  w.header.name = "bench-town";
  w.header.grid = ag::GridGeometry{0.25, kSize, kSize, -250.0, 250.0};
  w.class_id = cv::Mat(kSize, kSize, CV_8UC1, cv::Scalar(ag::raw(ClassId::kGrass)));
  w.height = cv::Mat(kSize, kSize, CV_32FC1, cv::Scalar(0.0));
  w.terrain = cv::Mat(kSize, kSize, CV_32FC1);
  w.albedo = cv::Mat(kSize, kSize, CV_8UC3);
  std::mt19937 rng(2024);
  const auto& g = w.grid();
  for (std::int32_t r = 0; r < kSize; ++r) {
    for (std::int32_t c = 0; c < kSize; ++c) {
      const double x = g.x_of(c), y = g.y_of(r);
      w.terrain.at<float>(r, c) = static_cast<float>(2.0 * std::sin(x / 60.0) * std::cos(y / 45.0));
      const double bx = std::fmod(x + 250.0, 60.0), by = std::fmod(y + 250.0, 60.0);
      const bool road = bx < 10.0 || by < 10.0;
      const ClassId k = road ? ClassId::kRoad : ClassId::kGrass;
      w.class_id.at<std::uint8_t>(r, c) = ag::raw(k);
      w.albedo.at<cv::Vec3b>(r, c) = shade_of(k, rng, 12);
    }
  }
  const auto put = [&](std::int32_t c, std::int32_t r, ClassId k, float h, cv::Vec3b rgb) {
    if (!g.contains(c, r)) return;
    w.class_id.at<std::uint8_t>(r, c) = ag::raw(k);
    w.height.at<float>(r, c) = h;
    w.albedo.at<cv::Vec3b>(r, c) = rgb;
  };
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  // Per block (50 m of land between 10 m streets): a yard, one or two buildings, trees and cars.
  for (int bi = 0; bi < 9; ++bi) {
    for (int bj = 0; bj < 9; ++bj) {
      const double x0 = -250.0 + bi * 60.0 + 10.0, y0 = -250.0 + bj * 60.0 + 10.0;  // SW corner of the land
      if (u01(rng) < 0.3) {  // gravel yard
        const double yx = x0 + 2 + u01(rng) * 20, yy = y0 + 2 + u01(rng) * 20;
        for (double x = yx; x < yx + 20; x += 0.25)
          for (double y = yy; y < yy + 15; y += 0.25) put(g.col(x), g.row(y), ClassId::kDirt, 0.0f, shade_of(ClassId::kDirt, rng, 15));
      }
      const int nb = 1 + static_cast<int>(u01(rng) * 2.0);
      for (int b = 0; b < nb; ++b) {
        const double wx = 10 + u01(rng) * 18, wy = 10 + u01(rng) * 18, h = 5 + u01(rng) * 25;
        const double bx = x0 + 3 + u01(rng) * (44 - wx), by = y0 + 3 + u01(rng) * (44 - wy);
        const cv::Vec3b roof = shade_of(ClassId::kBuilding, rng, 40);
        for (double x = bx; x < bx + wx; x += 0.25)
          for (double y = by; y < by + wy; y += 0.25) put(g.col(x), g.row(y), ClassId::kBuilding, static_cast<float>(h), roof);
      }
      for (int t = 0; t < 6; ++t) {  // round crowns, domed
        const double cx = x0 + 3 + u01(rng) * 44, cy = y0 + 3 + u01(rng) * 44, rad = 2 + u01(rng) * 2.5, h = 6 + u01(rng) * 9;
        for (double x = cx - rad; x <= cx + rad; x += 0.25) {
          for (double y = cy - rad; y <= cy + rad; y += 0.25) {
            const double d2 = ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / (rad * rad);
            if (d2 > 1.0) continue;
            const std::int32_t c = g.col(x), r = g.row(y);
            if (g.contains(c, r) && w.class_id.at<std::uint8_t>(r, c) == ag::raw(ClassId::kBuilding)) continue;
            put(c, r, ClassId::kTree, static_cast<float>(h * (0.6 + 0.4 * std::sqrt(1.0 - d2))), shade_of(ClassId::kTree, rng, 20));
          }
        }
      }
      for (int v = 0; v < 4; ++v) {  // cars parked along the street south of the block
        const double cx = x0 + u01(rng) * 45, cy = y0 - 2.5;
        const cv::Vec3b paint = shade_of(ClassId::kVehicle, rng, 60);
        for (double x = cx; x < cx + 4.5; x += 0.25)
          for (double y = cy; y < cy + 1.75; y += 0.25) put(g.col(x), g.row(y), ClassId::kVehicle, 1.5f, paint);
      }
    }
  }
  for (double x = 72; x < 98; x += 0.25)  // a pond inside one block
    for (double y = 135; y < 160; y += 0.25)
      if ((x - 85) * (x - 85) / 169 + (y - 147.5) * (y - 147.5) / 156 < 1.0)
        put(g.col(x), g.row(y), ClassId::kWater, 0.0f, shade_of(ClassId::kWater, rng, 8));
  return w;
}

struct Timing {
  double per_op_s;
  int ops;
};

// Runs op() for at least min_s of thread CPU time (and at least min_ops times); the median op time.
template <typename F>
Timing time_it(F&& op, double min_s, int min_ops) {
  std::vector<double> t;
  const double start = thread_cpu_s();
  while (static_cast<int>(t.size()) < min_ops || thread_cpu_s() - start < min_s) {
    const double a = thread_cpu_s();
    op();
    t.push_back(thread_cpu_s() - a);
  }
  std::sort(t.begin(), t.end());
  return {t[t.size() / 2], static_cast<int>(t.size())};
}

void dump_frame(const std::string& dir, const std::string& name, const ag::sim::CameraFrame& f) {
  cv::Mat bgr;
  cv::cvtColor(f.rgb, bgr, cv::COLOR_RGB2BGR);
  cv::imwrite(dir + "/" + name + "_rgb.png", bgr);
  cv::Mat cls(f.cls.size(), CV_8UC3);
  for (int r = 0; r < cls.rows; ++r) {
    for (int c = 0; c < cls.cols; ++c) {
      const ag::Rgb k = ag::ClassTable::builtin().info(static_cast<ClassId>(f.cls.at<std::uint8_t>(r, c))).color;
      cls.at<cv::Vec3b>(r, c) = cv::Vec3b(k.b, k.g, k.r);
    }
  }
  cv::imwrite(dir + "/" + name + "_class.png", cls);
  cv::Mat depth16;
  f.depth.convertTo(depth16, CV_16UC1, 1000.0);  // millimetres
  cv::imwrite(dir + "/" + name + "_depth_mm.png", depth16);
  double lo = 0, hi = 0;
  cv::minMaxLoc(f.depth, &lo, &hi, nullptr, nullptr, f.depth > 0);
  cv::Mat vis;
  f.depth.convertTo(vis, CV_8UC1, 255.0 / std::max(hi - lo, 1e-3), -lo * 255.0 / std::max(hi - lo, 1e-3));
  cv::applyColorMap(vis, vis, cv::COLORMAP_TURBO);
  vis.setTo(cv::Scalar(0, 0, 0), f.depth <= 0);
  cv::imwrite(dir + "/" + name + "_depth_vis.png", vis);
}

// Bird's-eye view of a scan, 0.1 m per pixel, coloured by class.
void dump_scan(const std::string& dir, const std::string& name, const std::vector<ag::sim::LidarPoint>& pts) {
  cv::Mat img(800, 800, CV_8UC3, cv::Scalar(0, 0, 0));
  for (const auto& p : pts) {
    const int u = 400 - static_cast<int>(std::lround(p.y * 10.0f)), v = 400 - static_cast<int>(std::lround(p.x * 10.0f));
    if (u < 0 || v < 0 || u >= 800 || v >= 800) continue;
    const ag::Rgb k = ag::ClassTable::builtin().info(static_cast<ClassId>(p.cls)).color;
    img.at<cv::Vec3b>(v, u) = cv::Vec3b(k.b, k.g, k.r);
  }
  cv::imwrite(dir + "/" + name + "_bev.png", img);
}

}  // namespace

int main(int argc, char** argv) {
  std::string dump_dir;
  bool lidar_only = false, camera_only = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--dump" && i + 1 < argc) dump_dir = argv[++i];
    if (a == "--lidar-only") lidar_only = true;
    if (a == "--camera-only") camera_only = true;
  }
  const auto cpus = ag::bench::allowed_cpus();
  const bool pinned = !cpus.empty() && ag::bench::pin_this_thread(cpus.back());
  std::printf("bench_sim_sensors: one core%s\n", pinned ? (" (pinned to CPU " + std::to_string(cpus.back()) + ")").c_str() : "");

  const double t_world = thread_cpu_s();
  const World town = make_town();
  const auto rc = std::make_shared<const ag::sim::HeightfieldRaycaster>(town);
  std::printf("world: 2000x2000 cells at 0.25 m (500 m square), built with its max pyramid in %.2f s\n",
              thread_cpu_s() - t_world);

  // The camera 50 m above a crossing (streets x, y in [-10, 0]), yawed, slightly tilted.
  const double ground = static_cast<double>(town.terrain.at<float>(town.grid().row(-5.0), town.grid().col(-5.0)));
  const Pose3 cam_pose{-3.0, -4.0, ground + 50.0, 0.02, -0.01, 0.3};
  std::string json = "{\"bench\":\"sim_sensors\"";
  char buf[256];
  for (const bool shadows : {true, false}) {
    if (lidar_only) break;
    for (const double scale : {0.5, 1.0}) {
      const ag::sim::CameraModel model = ag::sim::CameraModel{}.scaled(scale);
      ag::sim::CameraShading shading;
      shading.shadows = shadows;
      const ag::sim::CameraRenderer cam(town, model, shading, rc);
      ag::sim::CameraShading from_eye = shading;
      from_eye.tile_start = false;
      const ag::sim::CameraRenderer ref(town, model, from_eye, rc);
      ag::sim::CameraFrame frame;
      cam.render(cam_pose, frame);  // sizes the frame
      const Timing t = time_it([&] { cam.render(cam_pose, frame); }, 2.0, 5);
      const Timing r = time_it([&] { ref.render(cam_pose, frame); }, 1.0, 3);
      const double fps = 1.0 / t.per_op_s;
      std::printf("camera %4dx%-4d shadows %-3s: %6.1f frames/s  (%.1f ms/frame, %.0f ns/pixel, median of %d); casts from the eye %.1f ms: x%.2f\n",
                  model.width, model.height, shadows ? "on" : "off", fps, 1e3 * t.per_op_s,
                  1e9 * t.per_op_s / (model.width * model.height), t.ops, 1e3 * r.per_op_s, r.per_op_s / t.per_op_s);
      std::snprintf(buf, sizeof buf, ",\"camera_%dx%d_%s_fps\":%.2f,\"camera_%dx%d_%s_from_eye_fps\":%.2f", model.width,
                    model.height, shadows ? "shadows" : "noshadows", fps, model.width, model.height,
                    shadows ? "shadows" : "noshadows", 1.0 / r.per_op_s);
      json += buf;
      if (!dump_dir.empty() && shadows) dump_frame(dump_dir, "camera_" + std::to_string(model.width), frame);
    }
  }

  if (!lidar_only) {  // the sensor model (camera_sensor) against the ideal camera, 640x400 without shadows
    const ag::sim::CameraModel model = ag::sim::CameraModel{}.scaled(0.5);
    ag::sim::CameraSensor sensor;
    sensor.noise = sensor.auto_exposure = sensor.motion_blur = sensor.vignetting = true;
    const ag::sim::CameraRenderer ideal(town, model, ag::sim::CameraShading{}, rc);
    const ag::sim::CameraRenderer real(town, model, ag::sim::CameraShading{}, sensor, rc);
    ag::sim::CameraShot survey;  // a daylight survey frame: 0.4 ms at 5 m/s blurs 0.02 px (one sample)
    survey.frame = 1;
    survey.exposure = {4e-4, 1.0};
    survey.velocity = {5.0, 0.0, 0.0};
    ag::sim::CameraFrame frame;
    const Timing ti = time_it([&] { ideal.render(cam_pose, frame); }, 2.0, 5);
    const Timing ts = time_it([&] { real.render(cam_pose, frame, 0, survey); }, 2.0, 5);
    const int samples = frame.blur_samples;
    ag::sim::CameraShot fast = survey;  // a 3 px blur (62 m/s for 5 ms at 50 m), to show what samples cost
    fast.exposure = {5e-3, 1.0};
    fast.velocity = {62.0, 0.0, 0.0};
    real.render(cam_pose, frame, 0, fast);
    const int fast_samples = frame.blur_samples;
    const Timing tf = time_it([&] { real.render(cam_pose, frame, 0, fast); }, 1.0, 3);
    std::printf("camera  640x400 sensor model (noise, vignetting, exposure; %d blur sample): %.1f ms/frame, ideal camera %.1f ms "
                "in this run: x%.2f; with a %d-sample blur %.1f ms\n",
                samples, 1e3 * ts.per_op_s, 1e3 * ti.per_op_s, ts.per_op_s / ti.per_op_s, fast_samples, 1e3 * tf.per_op_s);
    std::snprintf(buf, sizeof buf, ",\"camera_640x400_sensor_ms\":%.2f,\"camera_640x400_ideal_ms\":%.2f", 1e3 * ts.per_op_s,
                  1e3 * ti.per_op_s);
    json += buf;
  }

  if (camera_only) {
    json += "}";
    const std::string written = ag::bench::append_result_line(json);
    if (!written.empty()) std::printf("results appended to %s\n", written.c_str());
    return 0;
  }
  // The LiDAR 1 m above the middle of a street, looking along it (blocks with buildings and trees on
  // both sides, a crossing behind).
  const double street = static_cast<double>(town.terrain.at<float>(town.grid().row(20.0), town.grid().col(-5.0)));
  const Pose3 lidar_pose{-5.0, 20.0, street + 1.0, 0.0, 0.0, 1.62};
  auto beams_or = ag::sim::OusterBeamModel::load_default(1024);
  if (!beams_or) {
    std::fprintf(stderr, "%s\n", beams_or.error().message.c_str());
    return 1;
  }
  for (const int cols : {512, 1024, 2048}) {
    ag::sim::OusterBeamModel beams = beams_or.value();
    beams.columns = cols;
    const ag::sim::LidarSimulator lidar(town, beams, ag::sim::LidarNoise{}, rc);
    std::vector<ag::sim::LidarPoint> pts;
    std::uint64_t seed = 0;
    lidar.scan(lidar_pose, seed, pts);
    const Timing t = time_it([&] { lidar.scan(lidar_pose, ++seed, pts); }, 1.0, 10);
    const Timing r = time_it([&] { lidar.scan_per_ray(lidar_pose, ++seed, pts); }, 0.5, 5);
    const double rays = static_cast<double>(lidar.rays_per_scan());
    std::printf("lidar  %2dx%-4d: %6.2f ms/scan  %5.1f Mrays/s  (%zu returns, median of %d); one cast per ray %6.2f ms: x%.1f\n",
                beams.rings(), cols, 1e3 * t.per_op_s, rays / t.per_op_s * 1e-6, pts.size(), t.ops, 1e3 * r.per_op_s,
                r.per_op_s / t.per_op_s);
    std::snprintf(buf, sizeof buf, ",\"lidar_64x%d_ms\":%.3f,\"lidar_64x%d_mrays_s\":%.2f,\"lidar_64x%d_per_ray_ms\":%.3f", cols,
                  1e3 * t.per_op_s, cols, rays / t.per_op_s * 1e-6, cols, 1e3 * r.per_op_s);
    json += buf;
    if (!dump_dir.empty() && cols == 1024) dump_scan(dump_dir, "lidar_1024", pts);
  }

  // A robot on a slope: the beams of one azimuth are no longer coplanar, the fan is split finer.
  {
    const ag::sim::LidarSimulator lidar(town, beams_or.value(), ag::sim::LidarNoise{}, rc);
    const Pose3 tilted{lidar_pose.x, lidar_pose.y, lidar_pose.z, 0.05, -0.035, lidar_pose.yaw};
    std::vector<ag::sim::LidarPoint> pts;
    std::uint64_t seed = 0;
    lidar.scan(tilted, seed, pts);
    const Timing t = time_it([&] { lidar.scan(tilted, ++seed, pts); }, 1.0, 10);
    const Timing r = time_it([&] { lidar.scan_per_ray(tilted, ++seed, pts); }, 0.5, 5);
    std::printf("lidar  64x1024 rolled 2.9 deg, pitched 2 deg: %6.2f ms/scan; one cast per ray %6.2f ms: x%.1f\n",
                1e3 * t.per_op_s, 1e3 * r.per_op_s, r.per_op_s / t.per_op_s);
    std::snprintf(buf, sizeof buf, ",\"lidar_64x1024_tilted_ms\":%.3f,\"lidar_64x1024_tilted_per_ray_ms\":%.3f",
                  1e3 * t.per_op_s, 1e3 * r.per_op_s);
    json += buf;
  }

  // What the max pyramid buys: the same 64x1024 scan, one cast per ray, with cell-by-cell traversal.
  {
    const auto plain = std::make_shared<const ag::sim::HeightfieldRaycaster>(town, ag::sim::RaycastOptions{false});
    const ag::sim::LidarSimulator lidar(town, beams_or.value(), ag::sim::LidarNoise{}, plain);
    std::vector<ag::sim::LidarPoint> pts;
    lidar.scan_per_ray(lidar_pose, 0, pts);
    const Timing t = time_it([&] { lidar.scan_per_ray(lidar_pose, 1, pts); }, 1.0, 3);
    std::printf("lidar  64x1024 without the max pyramid: %6.2f ms/scan (reference)\n", 1e3 * t.per_op_s);
    std::snprintf(buf, sizeof buf, ",\"lidar_64x1024_plain_dda_ms\":%.3f", 1e3 * t.per_op_s);
    json += buf;
  }
  // The ground robot's obstacle grid from that 64x1024 scan (the tracker stage's work per scan): free
  // space traced once per end cell, against a line to every ground return (the same grid).
  if (!camera_only) {
    const ag::sim::LidarSimulator lidar(town, beams_or.value(), ag::sim::LidarNoise{}, rc);
    std::vector<ag::sim::LidarPoint> pts;
    lidar.scan(lidar_pose, 3, pts);
    std::vector<ag::ScanReturn> sr;
    for (const auto& q : pts) sr.push_back(ag::ScanReturn{q.x, q.y, q.z, q.range, q.cls, q.ring, q.col});
    const ag::Pose3 mount{0, 0, 1.0, 0, 0, 0};
    const ag::Pose2 robot{lidar_pose.x, lidar_pose.y, lidar_pose.yaw};
    ag::plan::LocalTrackerParams once, every;
    every.trace_each_end_cell_once = false;
    ag::plan::LocalTracker a(once), b(every);
    const Timing t = time_it([&] { (void)a.update(sr, mount, robot, 1.0); }, 1.0, 10);
    const Timing r = time_it([&] { (void)b.update(sr, mount, robot, 1.0); }, 1.0, 5);
    int same = 0;
    for (int j = 0; j < a.width(); ++j)
      for (int i = 0; i < a.width(); ++i) same += a.cell(i, j) == b.cell(i, j);
    std::printf("tracker obstacle grid from it: %6.2f ms/scan; a line to every ground return %6.2f ms: x%.1f (grids %s)\n",
                1e3 * t.per_op_s, 1e3 * r.per_op_s, r.per_op_s / t.per_op_s, same == a.width() * a.width() ? "identical" : "DIFFER");
    std::snprintf(buf, sizeof buf, ",\"tracker_update_ms\":%.3f,\"tracker_update_every_ray_ms\":%.3f", 1e3 * t.per_op_s, 1e3 * r.per_op_s);
    json += buf;
  }
  json += "}";
  const std::string written = ag::bench::append_result_line(json);
  if (!written.empty()) std::printf("results appended to %s\n", written.c_str());
  return 0;
}
