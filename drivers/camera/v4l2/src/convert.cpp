// Pixel conversion with OpenCV's arithmetic (fixed-point BT.601 YUV, bilinear Bayer), so frames match
// what cv::cvtColor would give on the desktop tools.
#include <algorithm>
#include <cstdint>

#include "airground/drivers/camera/v4l2/camera.hpp"

namespace ag::v4l2 {

namespace {
// OpenCV's ITU-R BT.601 constants (color_yuv), 20-bit fixed point.
constexpr int kCY = 1220542, kCUB = 2116026, kCUG = -409993, kCVG = -852492, kCVR = 1673527, kShift = 20;
std::uint8_t sat(int v) noexcept { return static_cast<std::uint8_t>(std::clamp(v, 0, 255)); }

void yuv_to_bgr(int y, int u, int v, std::uint8_t* bgr) noexcept {
  const int yy = std::max(0, y - 16) * kCY;
  const int uu = u - 128, vv = v - 128;
  constexpr int half = 1 << (kShift - 1);
  bgr[0] = sat((yy + kCUB * uu + half) >> kShift);
  bgr[1] = sat((yy + kCVG * vv + kCUG * uu + half) >> kShift);
  bgr[2] = sat((yy + kCVR * vv + half) >> kShift);
}

// The colour of Bayer site (x, y): 0 = red, 1 = green, 2 = blue.
int site(PixelFormat f, std::uint32_t x, std::uint32_t y) noexcept {
  const bool ox = (x & 1) != 0, oy = (y & 1) != 0;
  if (f == PixelFormat::kBayerRggb8) return !ox && !oy ? 0 : ox && oy ? 2 : 1;
  return ox && !oy ? 0 : !ox && oy ? 2 : 1;  // GRBG
}

// Bilinear demosaic at an interior pixel (1 <= x < w-1, 1 <= y < h-1).
void demosaic(const Frame& f, std::uint32_t x, std::uint32_t y, std::uint8_t* bgr) noexcept {
  const std::uint8_t* d = f.data.data();
  const std::size_t s = f.stride;
  auto at = [&](std::uint32_t xx, std::uint32_t yy) -> int { return d[static_cast<std::size_t>(yy) * s + xx]; };
  const int c = site(f.format, x, y);
  const int self = at(x, y);
  const int cross = (at(x - 1, y) + at(x + 1, y) + at(x, y - 1) + at(x, y + 1) + 2) >> 2;
  const int diag = (at(x - 1, y - 1) + at(x + 1, y - 1) + at(x - 1, y + 1) + at(x + 1, y + 1) + 2) >> 2;
  const int horiz = (at(x - 1, y) + at(x + 1, y) + 1) >> 1;
  const int vert = (at(x, y - 1) + at(x, y + 1) + 1) >> 1;
  int r, g, b;
  if (c == 0) {
    r = self, g = cross, b = diag;
  } else if (c == 2) {
    b = self, g = cross, r = diag;
  } else {
    g = self;
    // On a green site the row holds red or blue neighbours left and right.
    const bool red_row = site(f.format, x + 1, y) == 0;
    r = red_row ? horiz : vert;
    b = red_row ? vert : horiz;
  }
  bgr[0] = static_cast<std::uint8_t>(b);
  bgr[1] = static_cast<std::uint8_t>(g);
  bgr[2] = static_cast<std::uint8_t>(r);
}

void bayer_to_bgr(const Frame& f, std::uint8_t* out) noexcept {
  const std::uint32_t w = f.width, h = f.height;
  if (w < 3 || h < 3) {
    std::fill(out, out + static_cast<std::size_t>(w) * h * 3, std::uint8_t{0});
    return;
  }
  for (std::uint32_t y = 1; y + 1 < h; ++y)
    for (std::uint32_t x = 1; x + 1 < w; ++x) demosaic(f, x, y, out + (static_cast<std::size_t>(y) * w + x) * 3);
  // Borders: the nearest interior pixel (OpenCV extrapolates the same way up to a pixel's rounding).
  auto copy = [&](std::uint32_t x, std::uint32_t y, std::uint32_t sx, std::uint32_t sy) {
    std::copy_n(out + (static_cast<std::size_t>(sy) * w + sx) * 3, 3, out + (static_cast<std::size_t>(y) * w + x) * 3);
  };
  for (std::uint32_t x = 0; x < w; ++x) {
    const std::uint32_t sx = std::clamp<std::uint32_t>(x, 1, w - 2);
    copy(x, 0, sx, 1);
    copy(x, h - 1, sx, h - 2);
  }
  for (std::uint32_t y = 1; y + 1 < h; ++y) {
    copy(0, y, 1, y);
    copy(w - 1, y, w - 2, y);
  }
}

std::uint8_t grey_of(const std::uint8_t* bgr) noexcept {
  // OpenCV's RGB2GRAY: 0.299 R + 0.587 G + 0.114 B in 14-bit fixed point.
  return static_cast<std::uint8_t>((bgr[2] * 4899 + bgr[1] * 9617 + bgr[0] * 1868 + (1 << 13)) >> 14);
}
}  // namespace

void to_bgr(const Frame& f, std::uint8_t* out) noexcept {
  const std::uint32_t w = f.width, h = f.height;
  const std::uint8_t* d = f.data.data();
  switch (f.format) {
    case PixelFormat::kGrey:
      for (std::uint32_t y = 0; y < h; ++y)
        for (std::uint32_t x = 0; x < w; ++x) {
          const std::uint8_t v = d[static_cast<std::size_t>(y) * f.stride + x];
          std::uint8_t* o = out + (static_cast<std::size_t>(y) * w + x) * 3;
          o[0] = o[1] = o[2] = v;
        }
      return;
    case PixelFormat::kYuyv:
      for (std::uint32_t y = 0; y < h; ++y) {
        const std::uint8_t* row = d + static_cast<std::size_t>(y) * f.stride;
        for (std::uint32_t x = 0; x + 1 < w; x += 2) {
          const std::uint8_t* p = row + 2 * x;  // Y0 U Y1 V
          std::uint8_t* o = out + (static_cast<std::size_t>(y) * w + x) * 3;
          yuv_to_bgr(p[0], p[1], p[3], o);
          yuv_to_bgr(p[2], p[1], p[3], o + 3);
        }
      }
      return;
    case PixelFormat::kBayerRggb8:
    case PixelFormat::kBayerGrbg8: bayer_to_bgr(f, out); return;
  }
}

void to_grey(const Frame& f, std::uint8_t* out) noexcept {
  const std::uint32_t w = f.width, h = f.height;
  const std::uint8_t* d = f.data.data();
  switch (f.format) {
    case PixelFormat::kGrey:
      for (std::uint32_t y = 0; y < h; ++y) std::copy_n(d + static_cast<std::size_t>(y) * f.stride, w, out + static_cast<std::size_t>(y) * w);
      return;
    case PixelFormat::kYuyv:
      for (std::uint32_t y = 0; y < h; ++y)
        for (std::uint32_t x = 0; x < w; ++x) out[static_cast<std::size_t>(y) * w + x] = d[static_cast<std::size_t>(y) * f.stride + 2 * x];
      return;
    case PixelFormat::kBayerRggb8:
    case PixelFormat::kBayerGrbg8: {
      if (w < 3 || h < 3) {
        std::fill(out, out + static_cast<std::size_t>(w) * h, std::uint8_t{0});
        return;
      }
      std::uint8_t bgr[3];
      for (std::uint32_t y = 0; y < h; ++y)
        for (std::uint32_t x = 0; x < w; ++x) {
          demosaic(f, std::clamp<std::uint32_t>(x, 1, w - 2), std::clamp<std::uint32_t>(y, 1, h - 2), bgr);
          out[static_cast<std::size_t>(y) * w + x] = grey_of(bgr);
        }
      return;
    }
  }
}

}  // namespace ag::v4l2
