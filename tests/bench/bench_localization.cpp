// bench_localization: the ground robot's semantic localizer on one core, on a synthetic 1 km^2 world.
//   - one filter update with 2,000 particles and a 64 x 1024 scan (goal <= 20 ms), against a direct
//     transcription of the cost formula (trigonometry and a field lookup per bin and shift) timed in
//     the same run;
//   - a distance-field update for one changed 64 x 64 tile (goal <= 5 ms), against a full recompute;
//   - labelling and rendering a 64 x 1024 scan;
//   - the memory of the distance fields, filter and render for 1 km^2 at 0.5 m (goal <= 300 MB), and
//     the process's resident set.
// Times are thread CPU time (medians and minima of repeated runs), so a busy machine counts less.
// AG_BENCH_OUT=<file> appends the figures as one JSON line.
#include <algorithm>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "../unit/localization/synthetic_world.hpp"
#include "airground/localization/class_distance_fields.hpp"
#include "airground/localization/particle_filter.hpp"
#include "airground/localization/polar_render.hpp"
#include "airground/localization/scan_labeller.hpp"
#include "airground/localization/semantic_localizer.hpp"
#include "bench_common.hpp"

namespace {

using namespace ag;
using namespace ag::loc;
// Thread CPU time: the figures hold on a busy machine (other processes do not count).
struct Clock {
  using time_point = double;  // [ms]
  static double now() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
  }
};

double ms_since(Clock::time_point t0) { return Clock::now() - t0; }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}
double minimum(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end()); }

double rss_mib() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return 0.0;
}

// The cost formula transcribed directly: for every particle and yaw shift, every bin's map position by
// trigonometry and its distances by ClassDistanceFields::distance_m(). Returns a checksum.
double reference_costs(const std::vector<Pose2>& particles, const ScanRenderPolar& r, const ClassDistanceFields& f, int window) {
  double check = 0.0;
  const double da = r.angle_bin_rad(), dr = r.range_bin_m();
  for (const Pose2& p : particles) {
    double best = 1e30;
    for (int s = -window; s <= window; ++s) {
      double sum = 0.0, known = 0.0;
      for (const ScanRenderPolar::Bin& b : r.bins()) {
        const double a = p.yaw + (b.angle + s + 0.5) * da, rr = (b.range + 0.5) * dr;
        const double x = p.x + rr * std::cos(a), y = p.y + rr * std::sin(a);
        if (f.class_at(x, y) == 255) continue;
        known += static_cast<double>(b.weight);
        for (std::uint32_t k = 0; k < b.entries; ++k) {
          const ScanRenderPolar::Entry& e = r.entries()[b.first + k];
          sum += static_cast<double>(e.value) * f.distance_m(x, y, static_cast<int>(e.channel));
        }
      }
      best = std::min(best, known > 0 ? sum / known : 1e9);
    }
    check += best;
  }
  return check;
}

}  // namespace

int main() {
  ag::bench::AffinityGuard guard;
  const std::vector<int> cpus = ag::bench::allowed_cpus();
  const bool pinned = !cpus.empty() && ag::bench::pin_this_thread(cpus.back());

  // 1 km^2 world (32 x 32 tiles of 32 m) and its fields.
  auto t0 = Clock::now();
  const test::SyntheticWorld w = test::make_world(32, 32, 2024);
  const double world_ms = ms_since(t0);
  const LocalizationChannels ch = LocalizationChannels::per_class();
  DistanceFieldParams dp;
  ClassDistanceFields fields(dp, ch, w.extent());
  for (int ty = 0; ty < w.tiles_y(); ++ty)
    for (int tx = 0; tx < w.tiles_x(); ++tx) fields.set_tile(tx, ty, 1, w.tile(tx, ty));
  t0 = Clock::now();
  fields.recompute_all();
  const double full_ms = ms_since(t0);

  // One changed tile at a time: a new building appears in it (the same 40 changes to a copy of w, for
  // every fields object; the scan below is taken in the changed world).
  const auto time_tile_changes = [](ClassDistanceFields& f, test::SyntheticWorld& changing) {
    std::vector<double> ms;
    test::TestRng rng(5);
    for (int i = 0; i < 40; ++i) {
      const int tx = 2 + static_cast<int>(rng.uniform() * 28), ty = 2 + static_cast<int>(rng.uniform() * 28);
      const double x0 = tx * 32.0 + rng.uniform(2, 20), y0 = ty * 32.0 + rng.uniform(2, 20);
      changing.fill_rect(x0, y0, x0 + 8, y0 + 8, ClassId::kBuilding, 6.0F);
      const std::vector<std::uint8_t> tile = changing.tile(tx, ty);
      const auto start = Clock::now();
      f.set_tile(tx, ty, static_cast<std::uint64_t>(2 + i), tile);
      f.update();
      ms.push_back(ms_since(start));
    }
    return ms;
  };
  test::SyntheticWorld changing = w;
  const std::vector<double> tile_ms = time_tile_changes(fields, changing);
  const double tile_median = median(tile_ms), tile_max = *std::max_element(tile_ms.begin(), tile_ms.end());

  // The same changes in the shipped configuration's fields: the geometric labelling's two channels,
  // without and with the obstacle faces (a face test per input cell; the rectangle one cell wider).
  double geo_tile_median[2] = {0.0, 0.0};
  for (const bool faces : {false, true}) {
    ClassDistanceFields geo(dp, LocalizationChannels::two_class(1.0, 1.5, faces), w.extent());
    for (int ty = 0; ty < w.tiles_y(); ++ty)
      for (int tx = 0; tx < w.tiles_x(); ++tx) geo.set_tile(tx, ty, 1, w.tile(tx, ty));
    geo.recompute_all();
    test::SyntheticWorld geo_changing = w;
    geo_tile_median[faces ? 1 : 0] = median(time_tile_changes(geo, geo_changing));
  }

  // A 64 x 1024 scan at a crossing, labelled both ways and rendered.
  test::LidarModel lidar;
  lidar.rings = 64;
  lidar.columns = 1024;
  const Pose2 truth{w.road_x[5] + 20.0, w.road_y[5], 0.3};
  std::vector<ScanPoint> scan;
  test::ray_cast(changing, truth, lidar, 1, scan);
  std::vector<ScanPoint> geo = scan;
  GeometricLabeller geometric(GeometricLabelParams{}, 64, 1024);
  std::vector<double> label_ms;
  for (int i = 0; i < 20; ++i) {
    geo = scan;
    t0 = Clock::now();
    geometric.label(geo, lidar.rings, lidar.columns);
    label_ms.push_back(ms_since(t0));
  }
  PolarRenderParams rp;
  ScanRenderPolar render(rp, ch);
  std::vector<double> render_ms;
  for (int i = 0; i < 20; ++i) {
    t0 = Clock::now();
    render.render(scan, 4.0);
    render_ms.push_back(ms_since(t0));
  }

  // The filter: 2,000 particles around the truth, forced updates on the same scan.
  std::printf("bench_localization (%s)\n", pinned ? "pinned to one CPU" : "not pinned");
  std::printf("  world 1 km^2: generated in %.0f ms; %zu scan points\n", world_ms, scan.size());
  double update_ms_by_bin[2] = {0, 0}, update_min_by_bin[2] = {0, 0}, ref_ratio[2] = {0, 0};
  std::size_t bins_by_bin[2] = {0, 0};
  const double bin_sizes[2] = {4.0, 1.0};
  // `runs` forced updates of `filter`, each from a fresh Gaussian of `sigma_m` around (2, -1) m off the truth.
  auto time_updates = [&](ParticleFilter& filter, double sigma_m, int runs) {
    std::vector<double> times;
    for (int i = 0; i < runs; ++i) {
      filter.initialise_gaussian(Pose2{truth.x + 2.0, truth.y - 1.0, truth.yaw + 0.05}, sigma_m, 0.1);
      const auto start = Clock::now();
      filter.update(render, fields, true);
      times.push_back(ms_since(start));
    }
    return times;
  };
  for (int k = 0; k < 2; ++k) {
    ParticleFilterParams fp;
    fp.min_particles = fp.max_particles = 2000;
    ParticleFilter filter(fp, rp, 7);
    render.render(scan, bin_sizes[k]);
    bins_by_bin[k] = render.bins().size();
    const std::vector<double> times = time_updates(filter, 4.0, 30);
    update_ms_by_bin[k] = median(times);
    update_min_by_bin[k] = minimum(times);
    // reference on 100 particles, scaled to 2,000
    std::vector<Pose2> parts;
    for (std::size_t i = 0; i < 100; ++i) parts.push_back(filter.particle(i));
    t0 = Clock::now();
    const double check = reference_costs(parts, render, fields, fp.yaw_window_bins);
    const double ref_ms = ms_since(t0) * 20.0;
    ref_ratio[k] = ref_ms / update_ms_by_bin[k];
    std::printf("  filter update, 2000 particles, yaw window +-%d bins, range bins %.0f m (%zu non-empty bins): median %.2f ms, "
                "min %.2f ms (goal <= 20 ms); direct formula %.1f ms -> %.1fx faster (checksum %.1f)\n",
                fp.yaw_window_bins, bin_sizes[k], bins_by_bin[k], update_ms_by_bin[k], update_min_by_bin[k], ref_ms, ref_ratio[k],
                check);
  }
  // The obstacle prior's cost where it works hardest: 2,000 particles spread 25 m over roads and blocks
  // (a re-spread), 4 m range bins, with the prior and without it.
  double prior_ms[2] = {0, 0};
  std::uint64_t penalised = 0;
  render.render(scan, 4.0);
  for (int on = 0; on < 2; ++on) {
    ParticleFilterParams fp;
    fp.min_particles = fp.max_particles = 2000;
    if (on == 0) fp.obstacle_penalty_per_m = 0.0;
    ParticleFilter filter(fp, rp, 7);
    prior_ms[on] = median(time_updates(filter, 25.0, 20));
    if (on == 1) penalised = filter.estimate().inside_obstacle / 20;
  }
  std::printf("  filter update, 2000 particles spread 25 m: median %.2f ms with the obstacle prior (%llu particles penalised), "
              "%.2f ms without -> %.2fx\n",
              prior_ms[1], static_cast<unsigned long long>(penalised), prior_ms[0], prior_ms[1] / prior_ms[0]);
  std::printf("  distance fields, one changed 64x64 tile: median %.2f ms, max %.2f ms (goal <= 5 ms); full recompute "
              "of 1 km^2: %.0f ms -> %.0fx\n",
              tile_median, tile_max, full_ms, full_ms / tile_median);
  std::printf("  the same tile, geometric labelling's two channels (shipped): median %.2f ms with obstacle faces, %.2f ms "
              "without -> %.2fx\n",
              geo_tile_median[1], geo_tile_median[0], geo_tile_median[1] / geo_tile_median[0]);
  std::printf("  scan 64x1024: geometric labelling %.2f ms, polar render %.2f ms\n", median(label_ms), median(render_ms));

  LocalizerParams lp;
  SemanticLocalizer localizer(lp, ch, 1);
  const double fields_mib = static_cast<double>(fields.memory_bytes()) / (1024.0 * 1024.0);
  const double loc_mib = static_cast<double>(localizer.memory_bytes() + geometric.memory_bytes()) / (1024.0 * 1024.0);
  std::printf("  memory, 1 km^2 at 0.5 m: distance fields %.1f MiB + localizer (%d particles max) and labeller %.1f MiB "
              "= %.1f MiB (goal <= 300 MB); process resident set %.0f MiB (includes this benchmark's world copies)\n",
              fields_mib, lp.filter.max_particles, loc_mib, fields_mib + loc_mib, rss_mib());

  char json[1024];
  std::snprintf(json, sizeof json,
                "{\"bench\":\"localization\",\"update_ms_2000_4m\":%.3f,\"update_ms_2000_1m\":%.3f,\"ratio_vs_direct_4m\":%.2f,"
                "\"tile_update_ms_median\":%.3f,\"tile_update_ms_max\":%.3f,\"full_recompute_ms\":%.1f,"
                "\"tile_update_ms_geometric_faces\":%.3f,\"tile_update_ms_geometric_regions\":%.3f,"
                "\"label_ms\":%.3f,\"render_ms\":%.3f,\"memory_mib\":%.1f}",
                update_ms_by_bin[0], update_ms_by_bin[1], ref_ratio[0], tile_median, tile_max, full_ms, geo_tile_median[1],
                geo_tile_median[0], median(label_ms),
                median(render_ms), fields_mib + loc_mib);
  ag::bench::append_result_line(json);
  return 0;
}
