// airground-sim world generate, import and show, and one look into a world: a camera frame (render) or a
// LiDAR scan (scan).
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "airground/sim/camera.hpp"
#include "airground/sim/generator.hpp"
#include "airground/sim/importer.hpp"
#include "airground/sim/lidar.hpp"
#include "airground/sim/runner.hpp"
#include "airground/sim/world_png.hpp"
#include "cli.hpp"

namespace fs = std::filesystem;

namespace ag::sim::cli {

namespace {

Datum parse_datum(const Args& a) {
  Datum d;
  if (!a.has("datum")) return d;
  const std::string v = a.get("datum");
  if (std::sscanf(v.c_str(), "%lf,%lf,%lf", &d.lat_deg, &d.lon_deg, &d.height_m) != 3 || std::abs(d.lat_deg) > 90 || std::abs(d.lon_deg) > 180)
    usage_error("--datum needs LAT,LON,HEIGHT in degrees and metres, got '" + v + "'");
  return d;
}

}  // namespace

int world_generate(const Args& a) {
  GeneratorOptions o;
  o.seed = static_cast<std::uint64_t>(number(a, "seed", 1));
  o.size_m = number(a, "size", o.size_m);
  o.targets = static_cast<int>(number(a, "targets", o.targets));
  o.resolution = number(a, "resolution", o.resolution);
  o.datum = parse_datum(a);
  const std::string out = required(a, "out");
  std::fprintf(stderr, "generating a %.0f m world (seed %llu, %d targets, %.2f m cells)...\n", o.size_m,
               static_cast<unsigned long long>(o.seed), o.targets, o.resolution);
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<TargetCluster> targets;
  auto w = generate_world(o, &targets);
  if (!w) return fail(w.error());
  if (auto st = save_world(w.value(), out); !st) return fail(st.error());
  if (auto st = save_targets(targets, w.value().header.staging, out); !st) return fail(st.error());
  if (auto st = write_world_pngs(w.value(), (fs::path(out) / "png").string()); !st) return fail(st.error());
  std::printf("world %s: %dx%d cells, %zu target clusters, %.1f s; layer pictures in %s/png\n", out.c_str(),
              w.value().grid().width, w.value().grid().height, targets.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), out.c_str());
  return 0;
}

int world_import(const Args& a) {
  ImportOptions o;
  o.classes_path = required(a, "classes");
  o.legend_path = required(a, "legend");
  if (a.has("px-per-m")) {
    const double ppm = number(a, "px-per-m", 0);
    if (ppm <= 0) usage_error("--px-per-m must be positive");
    o.resolution_m_per_px = 1.0 / ppm;
  } else {
    o.resolution_m_per_px = number(a, "resolution", 0);
  }
  if (!(o.resolution_m_per_px > 0)) usage_error("--resolution METRES_PER_PIXEL (or --px-per-m) is required and positive");
  o.elevation_path = a.get("elevation");
  o.color_path = a.get("color");
  o.name = a.get("name", fs::path(o.classes_path).stem().string());
  o.datum = parse_datum(a);
  const std::string out = required(a, "out");
  DeriveTargetsOptions derive;
  if (a.has("target-link")) {
    derive.link_m = number(a, "target-link", derive.link_m);
    if (!(derive.link_m > 0)) usage_error("--target-link must be positive (metres between the cars of one cluster)");
  }
  auto w = import_world(o);
  if (!w) return fail(w.error());
  World& world = w.value();
  // The mission's targets: the user's file (checked against this world; its staging pose is where the
  // robots start), or the map's own parked-car clusters.
  std::vector<TargetCluster> targets;
  std::string targets_from;
  if (a.has("targets")) {
    const std::string path = a.get("targets");
    auto tf = load_targets_file(path);
    if (!tf) return fail(tf.error());
    if (auto st = check_targets_in_world(tf.value(), world, path); !st) return fail(st.error());
    world.header.staging = tf.value().staging;
    targets = tf.value().targets;
    targets_from = "from " + path;
  } else {
    const DerivedTargets d = derive_targets(world, derive);
    targets = d.targets;
    char buf[256];
    std::snprintf(buf, sizeof buf, "derived from the vehicle class: %d cars, clusters linked within %.1f m", d.cars, derive.link_m);
    targets_from = buf;
    if (d.small_blobs > 0) targets_from += "; " + std::to_string(d.small_blobs) + " vehicle specks under 1.5 m2 dropped";
    if (d.large_blobs > 0) targets_from += "; " + std::to_string(d.large_blobs) + " vehicle areas over 20 m2 each taken as one car";
    if (targets.empty())
      std::fprintf(stderr, "world import: the map has no vehicle cells, so a mission on it has no targets to score; give "
                           "--targets FILE.yaml\n");
  }
  if (auto st = save_world(world, out); !st) return fail(st.error());
  if (auto st = save_targets(targets, world.header.staging, out); !st) return fail(st.error());
  if (auto st = write_world_pngs(world, (fs::path(out) / "png").string()); !st) return fail(st.error());
  std::printf("world %s: %dx%d cells at %.3f m; staging (%.1f, %.1f); %zu targets %s -> %s/targets.yaml (edit it, or "
              "import with --targets FILE.yaml); layer pictures in %s/png\n",
              out.c_str(), world.grid().width, world.grid().height, world.grid().resolution, world.header.staging.x,
              world.header.staging.y, targets.size(), targets_from.c_str(), out.c_str(), out.c_str());
  return 0;
}

int world_show(const Args& a) {
  if (a.pos.empty()) usage_error("world show needs the world directory");
  const std::string out = required(a, "out");
  auto w = resolve_world(a.pos.front());
  if (!w) return fail(w.error());
  if (auto st = write_world_pngs(*w.value(), out); !st) return fail(st.error());
  std::printf("wrote the layers of %s to %s\n", a.pos.front().c_str(), out.c_str());
  return 0;
}

int render(const Args& a) {
  auto w = resolve_world(a.get("world", "default"));
  if (!w) return fail(w.error());
  const auto p = numbers(a, "pose", 6);
  const std::string out = required(a, "out");
  CameraModel model;
  CameraShading shading;
  if (a.has("config")) {
    auto m = CameraModel::load_file(a.get("config"));
    if (!m) return fail(m.error());
    model = m.value();
    auto s = CameraShading::load_file(a.get("config"));
    if (!s) return fail(s.error());
    shading = s.value();
  }
  if (a.has("scale")) model = model.scaled(number(a, "scale", 1.0));
  CameraRenderer renderer(*w.value(), model, shading);
  CameraFrame f;
  const auto t0 = std::chrono::steady_clock::now();
  renderer.render(Pose3{p[0], p[1], p[2], p[3], p[4], p[5]}, f);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  fs::create_directories(out);
  cv::Mat bgr, depth_mm;
  cv::cvtColor(f.rgb, bgr, cv::COLOR_RGB2BGR);
  f.depth.convertTo(depth_mm, CV_16U, 1000.0);
  cv::Mat depth_vis;
  double dmax = 0;
  cv::minMaxLoc(f.depth, nullptr, &dmax);
  f.depth.convertTo(depth_vis, CV_8U, dmax > 0 ? 255.0 / dmax : 1.0);
  cv::applyColorMap(depth_vis, depth_vis, cv::COLORMAP_VIRIDIS);
  const bool ok = cv::imwrite((fs::path(out) / "rgb.png").string(), bgr) &&
                  cv::imwrite((fs::path(out) / "class.png").string(), f.cls) &&
                  cv::imwrite((fs::path(out) / "class_colour.png").string(), [&] { cv::Mat c; cv::cvtColor(class_display_image(f.cls), c, cv::COLOR_RGB2BGR); return c; }()) &&
                  cv::imwrite((fs::path(out) / "depth_mm.png").string(), depth_mm) &&
                  cv::imwrite((fs::path(out) / "depth.png").string(), depth_vis);
  if (!ok) return fail(Error::make(ErrorCode::kIo, "cannot write images into " + out));
  std::printf("rendered %dx%d in %.1f ms: %s/{rgb,class,class_colour,depth_mm,depth}.png (class.png holds ids, depth_mm.png 16-bit mm)\n",
              f.rgb.cols, f.rgb.rows, ms, out.c_str());
  return 0;
}

int scan(const Args& a) {
  auto w = resolve_world(a.get("world", "default"));
  if (!w) return fail(w.error());
  const auto p = numbers(a, "pose", 3);
  const std::string out = required(a, "out");
  const int columns = static_cast<int>(number(a, "columns", 1024));
  const double height = number(a, "height", 0.6);
  auto beams = OusterBeamModel::load_default(columns);
  if (!beams) return fail(beams.error());
  const World& world = *w.value();
  const GridGeometry& g = world.grid();
  const int c = g.col(p[0]), r = g.row(p[1]);
  if (!g.contains(c, r)) usage_error("--pose is outside the world");
  LidarSimulator lidar(world, beams.value(), LidarNoise{});
  std::vector<LidarPoint> pts;
  const Pose3 pose{p[0], p[1], static_cast<double>(world.surface_at(c, r)) + height, 0, 0, p[2]};
  const auto t0 = std::chrono::steady_clock::now();
  lidar.scan(pose, 1, pts);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  fs::create_directories(out);
  std::ofstream ply(fs::path(out) / "scan.ply");
  ply << "ply\nformat ascii 1.0\ncomment airground-sim scan, sensor frame (x forward, y left, z up) [m]\nelement vertex "
      << pts.size() << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar class\nproperty ushort ring\n";
  ply << "end_header\n";
  for (const auto& q : pts) {
    const Rgb col = ClassTable::builtin().info(static_cast<ClassId>(q.cls)).color;
    ply << q.x << ' ' << q.y << ' ' << q.z << ' ' << int(col.r) << ' ' << int(col.g) << ' ' << int(col.b) << ' ' << int(q.cls) << ' ' << q.ring << '\n';
  }
  // Top-down picture, 60 m across, 10 px/m, forward up.
  constexpr int kPx = 600;
  cv::Mat top(kPx, kPx, CV_8UC3, cv::Scalar(20, 20, 20));
  for (const auto& q : pts) {
    const int u = static_cast<int>(kPx / 2 - q.y * 10), v = static_cast<int>(kPx / 2 - q.x * 10);
    if (u < 0 || v < 0 || u >= kPx || v >= kPx) continue;
    const Rgb col = ClassTable::builtin().info(static_cast<ClassId>(q.cls)).color;
    top.at<cv::Vec3b>(v, u) = cv::Vec3b(col.b, col.g, col.r);
  }
  cv::drawMarker(top, cv::Point(kPx / 2, kPx / 2), cv::Scalar(255, 255, 255), cv::MARKER_TRIANGLE_UP, 12, 2);
  cv::imwrite((fs::path(out) / "scan_top.png").string(), top);
  std::printf("scan of %zu points (%d x %d rays) in %.1f ms: %s/scan.ply, %s/scan_top.png\n", pts.size(),
              beams.value().rings(), columns, ms, out.c_str(), out.c_str());
  return 0;
}

}  // namespace ag::sim::cli
