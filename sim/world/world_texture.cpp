// Noise fields, per-class aerial colour and synthetic object heights for generated and imported worlds.
#include "airground/sim/world_texture.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "airground/messages/classes.hpp"
#include "airground/messages/geometry.hpp"
#include "airground/platform/rng.hpp"

namespace ag::sim {

namespace {

struct Colour {
  float r, g, b;
};

constexpr float smoothstep(float e0, float e1, float x) noexcept {
  const float t = std::clamp((x - e0) / (e1 - e0), 0.0F, 1.0F);
  return t * t * (3.0F - 2.0F * t);
}

constexpr Colour mix(Colour a, Colour b, float t) noexcept {
  return {a.r + (b.r - a.r) * t, a.g + (b.g - a.g) * t, a.b + (b.b - a.b) * t};
}

constexpr Colour add(Colour a, float v) noexcept { return {a.r + v, a.g + v, a.b + v}; }
constexpr Colour scale(Colour a, float k) noexcept { return {a.r * k, a.g * k, a.b * k}; }

std::uint8_t to_byte(float v) noexcept { return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0F, 255.0F))); }

// Roof colours: pitched roofs are tiles or slate, flat roofs gravel, bitumen or membranes.
constexpr std::array<Colour, 7> kPitchedRoofs{{{168, 84, 62}, {142, 70, 54}, {118, 64, 52}, {96, 96, 104}, {72, 74, 82}, {150, 112, 82}, {126, 92, 78}}};
constexpr std::array<Colour, 7> kFlatRoofs{{{162, 162, 158}, {128, 126, 120}, {198, 198, 192}, {92, 92, 95}, {150, 145, 132}, {112, 120, 116}, {140, 134, 126}}};
// Car paints, common ones repeated so they come up more often.
constexpr std::array<Colour, 14> kCarPaints{{{228, 228, 226}, {232, 232, 230}, {172, 174, 178}, {168, 170, 172}, {112, 112, 118},
                                              {34, 34, 38}, {28, 30, 34}, {172, 28, 30}, {40, 62, 140}, {28, 34, 72},
                                              {44, 92, 54}, {192, 176, 140}, {222, 192, 52}, {128, 30, 44}}};

// Per-component statistics of one class: labels, the colour each component gets, whether its roof is pitched.
struct Components {
  cv::Mat labels;  // CV_32S, 0 = not this class
  std::vector<Colour> colour;
  std::vector<std::uint8_t> pitched;
};

Components label_class(const cv::Mat& class_id, ClassId cls) {
  Components c;
  cv::Mat mask = class_id == raw(cls);
  const int n = cv::connectedComponents(mask, c.labels, 8, CV_32S);
  c.colour.assign(static_cast<std::size_t>(std::max(n, 1)), Colour{0, 0, 0});
  c.pitched.assign(static_cast<std::size_t>(std::max(n, 1)), 0);
  return c;
}

// Slope of the object surface from same-class neighbours only, so a roof's or a crown's own shape shades
// it and its walls do not.
struct Slope {
  float east, north;
};

Slope class_slope(const cv::Mat& class_id, const cv::Mat& height, int r, int c, float inv_res) noexcept {
  const std::uint8_t k = class_id.at<std::uint8_t>(r, c);
  const float h = height.at<float>(r, c);
  const auto sample = [&](int rr, int cc, bool& same) {
    if (rr < 0 || cc < 0 || rr >= class_id.rows || cc >= class_id.cols || class_id.at<std::uint8_t>(rr, cc) != k) {
      same = false;
      return h;
    }
    same = true;
    return height.at<float>(rr, cc);
  };
  bool sw = false, se = false, sn = false, ss = false;
  const float w = sample(r, c - 1, sw), e = sample(r, c + 1, se), n = sample(r - 1, c, sn), s = sample(r + 1, c, ss);
  const auto span = [](bool a, bool b) { return a && b ? 2.0F : 1.0F; };  // one-sided where the object ends
  const float dx = (e - w) * inv_res / span(sw, se);
  const float dn = (n - s) * inv_res / span(sn, ss);
  return {std::clamp(dx, -2.5F, 2.5F), std::clamp(dn, -2.5F, 2.5F)};
}

// Lambert shading for a sun in the north-west, 45 degrees up; 1.0 on level ground.
float sun_shade(Slope s) noexcept {
  const float nx = -s.east, ny = -s.north, nz = 1.0F;
  const float len = std::sqrt(nx * nx + ny * ny + nz * nz);
  const float lit = (nx * -0.5F + ny * 0.5F + nz * 0.70710678F) / len;
  return std::max(lit, 0.0F) / 0.70710678F;
}

}  // namespace

std::uint64_t mix_hash(std::uint64_t a, std::uint64_t b) noexcept {
  std::uint64_t s = a ^ (b * 0x9E3779B97F4A7C15ULL + 0x632BE59BD9B4E019ULL);
  (void)splitmix64(s);
  return splitmix64(s);
}

double hash_unit(std::uint64_t a, std::uint64_t b) noexcept { return static_cast<double>(mix_hash(a, b) >> 11) * 0x1.0p-53; }

cv::Mat white_noise(cv::Size size, std::uint64_t seed) {
  cv::Mat out(size, CV_32FC1);
  Rng rng(seed);
  for (int r = 0; r < out.rows; ++r) {
    auto* row = out.ptr<float>(r);
    for (int c = 0; c < out.cols; ++c) {
      row[c] = static_cast<float>(static_cast<double>(rng.next_u64() >> 40) * 0x1.0p-23 - 1.0);
    }
  }
  return out;
}

cv::Mat value_noise(cv::Size size, double cell_px, std::uint64_t seed) {
  if (cell_px <= 1.0) return white_noise(size, seed);
  const int lw = static_cast<int>(std::ceil(size.width / cell_px)) + 2;
  const int lh = static_cast<int>(std::ceil(size.height / cell_px)) + 2;
  cv::Mat lattice = white_noise(cv::Size(lw, lh), seed);
  cv::Mat out;
  cv::resize(lattice, out, size, 0, 0, cv::INTER_CUBIC);
  return out;
}

cv::Mat fractal_noise(cv::Size size, double cell_px, int octaves, std::uint64_t seed) {
  cv::Mat sum(size, CV_32FC1, cv::Scalar(0));
  float amplitude = 1.0F, total = 0.0F;
  for (int o = 0; o < octaves; ++o) {
    cv::Mat layer = value_noise(size, cell_px, mix_hash(seed, static_cast<std::uint64_t>(o)));
    cv::scaleAdd(layer, static_cast<double>(amplitude), sum, sum);
    total += amplitude;
    amplitude *= 0.5F;
    cell_px *= 0.5;
  }
  // A sum of independent octaves has a smaller spread than one; this keeps it near [-1, 1].
  sum *= static_cast<double>(1.6F / total);
  return sum;
}

cv::Mat hillshade(const cv::Mat& surface, double resolution) {
  CV_Assert(surface.type() == CV_32FC1);
  cv::Mat gx, gy;
  cv::Sobel(surface, gx, CV_32F, 1, 0, 3, 1.0 / (8.0 * resolution), 0, cv::BORDER_REPLICATE);
  cv::Sobel(surface, gy, CV_32F, 0, 1, 3, 1.0 / (8.0 * resolution), 0, cv::BORDER_REPLICATE);
  cv::Mat out(surface.size(), CV_32FC1);
  for (int r = 0; r < surface.rows; ++r) {
    const auto* ex = gx.ptr<float>(r);
    const auto* sy = gy.ptr<float>(r);
    auto* o = out.ptr<float>(r);
    for (int c = 0; c < surface.cols; ++c) {
      o[c] = sun_shade(Slope{ex[c], -sy[c]}) * 0.70710678F;  // rows grow southwards
    }
  }
  return out;
}

cv::Mat distance_to_class_edge(const cv::Mat& class_id, double resolution) {
  cv::Mat inside(class_id.size(), CV_8UC1, cv::Scalar(255));
  for (int r = 0; r < class_id.rows; ++r) {
    const auto* row = class_id.ptr<std::uint8_t>(r);
    const auto* up = class_id.ptr<std::uint8_t>(std::max(r - 1, 0));
    const auto* down = class_id.ptr<std::uint8_t>(std::min(r + 1, class_id.rows - 1));
    auto* o = inside.ptr<std::uint8_t>(r);
    for (int c = 0; c < class_id.cols; ++c) {
      const std::uint8_t k = row[c];
      if (up[c] != k || down[c] != k || row[std::max(c - 1, 0)] != k || row[std::min(c + 1, class_id.cols - 1)] != k) o[c] = 0;
    }
  }
  cv::Mat dist;
  cv::distanceTransform(inside, dist, cv::DIST_L2, cv::DIST_MASK_3);
  dist *= resolution;
  return dist;
}

cv::Mat paint_albedo(const cv::Mat& class_id, const cv::Mat& height, double resolution, std::uint64_t seed) {
  CV_Assert(class_id.type() == CV_8UC1 && height.type() == CV_32FC1 && class_id.size() == height.size());
  const cv::Size size = class_id.size();
  const auto px = [resolution](double metres) { return metres / resolution; };
  // Noise at the scales an aerial image shows: fields and wear (tens of m), patches (m), leaves and grain.
  const cv::Mat broad = fractal_noise(size, px(40.0), 3, mix_hash(seed, 1));
  const cv::Mat patch = fractal_noise(size, px(12.0), 3, mix_hash(seed, 2));
  const cv::Mat mid = fractal_noise(size, px(2.0), 2, mix_hash(seed, 3));
  const cv::Mat fine = value_noise(size, std::max(px(0.6), 1.5), mix_hash(seed, 4));
  const cv::Mat grain = white_noise(size, mix_hash(seed, 5));
  const cv::Mat edge = distance_to_class_edge(class_id, resolution);

  Components roofs = label_class(class_id, ClassId::kBuilding);
  Components cars = label_class(class_id, ClassId::kVehicle);
  const float inv_res = static_cast<float>(1.0 / resolution);
  {  // a roof is pitched when its own surface slopes on average
    std::vector<double> slope_sum(roofs.colour.size(), 0.0);
    std::vector<double> count(roofs.colour.size(), 0.0);
    for (int r = 0; r < size.height; ++r) {
      const auto* lab = roofs.labels.ptr<std::int32_t>(r);
      for (int c = 0; c < size.width; ++c) {
        if (lab[c] == 0) continue;
        const Slope s = class_slope(class_id, height, r, c, inv_res);
        slope_sum[static_cast<std::size_t>(lab[c])] += static_cast<double>(std::hypot(s.east, s.north));
        count[static_cast<std::size_t>(lab[c])] += 1.0;
      }
    }
    for (std::size_t i = 1; i < roofs.colour.size(); ++i) {
      roofs.pitched[i] = count[i] > 0 && slope_sum[i] / count[i] > 0.2 ? 1 : 0;
      const std::uint64_t h = mix_hash(seed ^ 0x524F4F46ULL, i);
      const Colour base = roofs.pitched[i] != 0 ? kPitchedRoofs[h % kPitchedRoofs.size()] : kFlatRoofs[h % kFlatRoofs.size()];
      const float jitter = static_cast<float>(hash_unit(h, 1) * 24.0 - 12.0);
      roofs.colour[i] = add(base, jitter);
    }
    for (std::size_t i = 1; i < cars.colour.size(); ++i) {
      const std::uint64_t h = mix_hash(seed ^ 0x434152ULL, i);
      cars.colour[i] = add(kCarPaints[h % kCarPaints.size()], static_cast<float>(hash_unit(h, 2) * 10.0 - 5.0));
    }
  }

  constexpr Colour kAsphalt{86, 87, 92}, kConcrete{162, 160, 152};
  constexpr Colour kDirtLight{156, 132, 98}, kDirtDark{118, 98, 74};
  constexpr Colour kGrassLush{74, 120, 46}, kGrassDark{50, 90, 38}, kGrassDry{140, 138, 80};
  constexpr Colour kTreeA{38, 74, 34}, kTreeB{62, 98, 42};
  constexpr Colour kWaterShallow{74, 98, 96}, kWaterDeep{34, 58, 78};
  const double ripple_angle = hash_unit(seed, 77) * kPi;
  const float ripple_cx = static_cast<float>(std::cos(ripple_angle) * resolution * 2.0 * kPi / 1.3);
  const float ripple_cy = static_cast<float>(std::sin(ripple_angle) * resolution * 2.0 * kPi / 1.3);

  cv::Mat out(size, CV_8UC3);
  for (int r = 0; r < size.height; ++r) {
    const auto* cls = class_id.ptr<std::uint8_t>(r);
    const auto* hgt = height.ptr<float>(r);
    const auto* nb = broad.ptr<float>(r);
    const auto* np = patch.ptr<float>(r);
    const auto* nm = mid.ptr<float>(r);
    const auto* nf = fine.ptr<float>(r);
    const auto* ng = grain.ptr<float>(r);
    const auto* ed = edge.ptr<float>(r);
    const auto* roof_lab = roofs.labels.ptr<std::int32_t>(r);
    const auto* car_lab = cars.labels.ptr<std::int32_t>(r);
    auto* o = out.ptr<cv::Vec3b>(r);
    for (int c = 0; c < size.width; ++c) {
      Colour col{100, 100, 100};
      switch (static_cast<ClassId>(cls[c])) {
        case ClassId::kRoad: {
          if (hgt[c] > 0.05F) {
            col = add(kConcrete, 6.0F * nm[c] + 9.0F * ng[c] + 5.0F * nb[c]);
          } else {
            col = add(kAsphalt, 9.0F * nb[c] + 5.0F * nm[c] + 10.0F * ng[c] + 4.0F * nf[c]);
            col = add(col, -13.0F * smoothstep(0.42F, 0.5F, np[c]));  // patched repairs
            col.b += 3.0F * nb[c];
          }
          break;
        }
        case ClassId::kDirt: {
          col = mix(kDirtLight, kDirtDark, 0.5F + 0.5F * np[c]);
          col = add(col, 9.0F * nm[c] + 22.0F * ng[c] + 5.0F * nf[c]);
          if (ng[c] > 0.86F) col = add(col, 30.0F);  // pale stones in the gravel
          if (ng[c] < -0.93F) col = add(col, -25.0F);
          break;
        }
        case ClassId::kGrass: {
          col = mix(kGrassLush, kGrassDark, smoothstep(-0.35F, 0.55F, nb[c]));
          col = mix(col, kGrassDry, 0.45F * smoothstep(0.35F, 0.9F, np[c]));
          const float tuft = 8.0F * nm[c] + 6.0F * nf[c] + 7.0F * ng[c];
          col.r += 0.7F * tuft;
          col.g += tuft;
          col.b += 0.5F * tuft;
          break;
        }
        case ClassId::kTree: {
          col = mix(kTreeA, kTreeB, 0.5F + 0.5F * np[c]);
          col = add(col, 12.0F * nf[c] + 6.0F * ng[c] + 5.0F * nm[c]);
          const float shade = sun_shade(class_slope(class_id, height, r, c, inv_res));
          const float rim = 0.62F + 0.38F * std::min(ed[c] / 1.5F, 1.0F);
          col = scale(col, (0.5F + 0.55F * shade) * rim);
          break;
        }
        case ClassId::kBuilding: {
          const auto label = static_cast<std::size_t>(roof_lab[c]);
          col = roofs.colour[label];
          col = add(col, 5.0F * nm[c] + 5.0F * ng[c] + 3.0F * nf[c] + 4.0F * nb[c]);
          const Slope s = class_slope(class_id, height, r, c, inv_res);
          const float shade = sun_shade(s);
          if (roofs.pitched[label] != 0) {
            col = scale(col, 0.72F + 0.3F * shade);
            if (std::hypot(s.east, s.north) > 0.2F) {  // tile courses are contour lines of the roof
              col = scale(col, 1.0F + 0.07F * std::sin(hgt[c] * 2.0F * static_cast<float>(kPi) / 0.32F));
            }
          } else {
            col = scale(col, 0.85F + 0.15F * shade);
            if (ed[c] < 0.6F) col = add(col, 22.0F);  // parapet
          }
          break;
        }
        case ClassId::kVehicle: {
          col = cars.colour[static_cast<std::size_t>(car_lab[c])];
          col = add(col, 3.0F * ng[c]);
          col = scale(col, 0.8F + 0.2F * std::min(ed[c] / 0.4F, 1.0F));
          break;
        }
        case ClassId::kWater: {
          col = mix(kWaterShallow, kWaterDeep, std::min(ed[c] / 5.0F, 1.0F));
          const float ripple = std::sin(static_cast<float>(c) * ripple_cx + static_cast<float>(r) * ripple_cy + 3.0F * nm[c]);
          col = add(col, 6.0F * ripple + 4.0F * nf[c] + 3.0F * ng[c] + 6.0F * np[c]);
          if (ripple > 0.97F && nf[c] > 0.2F) col = add(col, 22.0F);  // glints
          break;
        }
        default:
          col = add(Colour{100, 100, 100}, 10.0F * ng[c]);
          break;
      }
      o[c] = cv::Vec3b(to_byte(col.r), to_byte(col.g), to_byte(col.b));
    }
  }
  return out;
}

cv::Mat synthesize_heights(const cv::Mat& class_id, double resolution, std::uint64_t seed) {
  CV_Assert(class_id.type() == CV_8UC1);
  cv::Mat height(class_id.size(), CV_32FC1, cv::Scalar(0));
  const Components roofs = label_class(class_id, ClassId::kBuilding);
  const Components crowns = label_class(class_id, ClassId::kTree);
  const cv::Mat edge = distance_to_class_edge(class_id, resolution);
  const cv::Mat leaves = value_noise(class_id.size(), std::max(1.0 / resolution, 1.5), mix_hash(seed, 11));
  const bool curbs = resolution <= 0.5;
  const auto is_curb_neighbour = [](std::uint8_t k) {
    return k == raw(ClassId::kGrass) || k == raw(ClassId::kTree) || k == raw(ClassId::kBuilding);
  };
  for (int r = 0; r < class_id.rows; ++r) {
    const auto* cls = class_id.ptr<std::uint8_t>(r);
    const auto* up = class_id.ptr<std::uint8_t>(std::max(r - 1, 0));
    const auto* down = class_id.ptr<std::uint8_t>(std::min(r + 1, class_id.rows - 1));
    const auto* roof_lab = roofs.labels.ptr<std::int32_t>(r);
    const auto* crown_lab = crowns.labels.ptr<std::int32_t>(r);
    const auto* ed = edge.ptr<float>(r);
    const auto* lv = leaves.ptr<float>(r);
    auto* h = height.ptr<float>(r);
    for (int c = 0; c < class_id.cols; ++c) {
      switch (static_cast<ClassId>(cls[c])) {
        case ClassId::kBuilding:
          h[c] = static_cast<float>(8.0 + 7.0 * hash_unit(seed ^ 0x424C44ULL, static_cast<std::uint64_t>(roof_lab[c])));
          break;
        case ClassId::kTree: {
          const float top = static_cast<float>(6.0 + 6.0 * hash_unit(seed ^ 0x545245ULL, static_cast<std::uint64_t>(crown_lab[c])));
          h[c] = std::max(top * (0.6F + 0.4F * std::min(ed[c] / 3.0F, 1.0F)) + 0.4F * lv[c], 0.5F);
          break;
        }
        case ClassId::kVehicle:
          h[c] = 1.5F;
          break;
        case ClassId::kRoad:
          if (curbs && (is_curb_neighbour(up[c]) || is_curb_neighbour(down[c]) ||
                        is_curb_neighbour(cls[std::max(c - 1, 0)]) || is_curb_neighbour(cls[std::min(c + 1, class_id.cols - 1)]))) {
            h[c] = 0.15F;
          }
          break;
        default:
          break;
      }
    }
  }
  return height;
}

}  // namespace ag::sim
