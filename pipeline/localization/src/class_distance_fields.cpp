// Aerial class distance fields: truncated exact Euclidean distance transforms over a tiled class map,
// recomputed only around the tiles that changed.
#include "airground/localization/class_distance_fields.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace ag::loc {

namespace {
constexpr std::uint64_t kNeverSet = std::numeric_limits<std::uint64_t>::max();
}  // namespace

DistanceFieldParams load_distance_field_params(const SectionView& s, double resolution_m, int tile_cells) {
  DistanceFieldParams p = load_params(s, kDistanceFieldFields);
  p.resolution_m = resolution_m;
  p.tile_cells = tile_cells;
  return p;
}

ClassDistanceFields::ClassDistanceFields(const DistanceFieldParams& params, const LocalizationChannels& channels,
                                         const TileExtent& extent)
    : p_(params), channels_(channels), extent_(extent) {
  if (p_.resolution_m <= 0.0 || p_.tile_cells < 1 || p_.truncation_m <= 0.0 || p_.full_block_tiles < 1)
    throw std::invalid_argument("ClassDistanceFields: resolution, tile size, truncation and block must be positive");
  if (extent_.tiles_x < 1 || extent_.tiles_y < 1) throw std::invalid_argument("ClassDistanceFields: empty extent");
  if (channels_.count() < 1 || channels_.count() > kMaxChannels) throw std::invalid_argument("ClassDistanceFields: channel count");
  width_ = extent_.tiles_x * p_.tile_cells;
  height_ = extent_.tiles_y * p_.tile_cells;
  origin_x_ = static_cast<double>(extent_.tile_x0) * p_.tile_cells * p_.resolution_m;
  origin_y_ = static_cast<double>(extent_.tile_y0) * p_.tile_cells * p_.resolution_m;
  quantum_m_ = p_.truncation_m / 255.0;
  const double trunc_cells = p_.truncation_m / p_.resolution_m;
  margin_ = static_cast<std::int32_t>(std::ceil(trunc_cells - 1e-9));
  if (margin_ > 16000) throw std::invalid_argument("ClassDistanceFields: truncation too large for the resolution");

  for (std::size_t c = 0; c < 256; ++c) source_mask_[c] = channels_.map_sources(static_cast<std::uint8_t>(c));
  if (p_.unknown_is_source) source_mask_[255] = static_cast<std::uint8_t>((1U << static_cast<unsigned>(channels_.count())) - 1U);
  else source_mask_[255] = 0;

  const std::size_t n_cells = outside_index() + 1;
  cells_.assign(n_cells * kStride, p_.unknown_is_source ? 0 : 255);
  for (std::size_t i = 0; i < n_cells; ++i) cells_[i * kStride + kStride - 1] = 255;
  const auto n_tiles = static_cast<std::size_t>(extent_.tiles_x) * static_cast<std::size_t>(extent_.tiles_y);
  tile_version_.assign(n_tiles, kNeverSet);
  tile_dirty_.assign(n_tiles, 0);
  dirty_.assign(n_tiles, 0);

  // squared distance [cells^2] -> byte; beyond the truncation: 255
  const auto max_d2 = static_cast<std::size_t>(std::floor(trunc_cells * trunc_cells));
  quantise_.resize(max_d2 + 1);
  for (std::size_t d2 = 0; d2 <= max_d2; ++d2) {
    const double d = std::sqrt(static_cast<double>(d2)) * p_.resolution_m;
    quantise_[d2] = static_cast<std::uint8_t>(std::min(255.0, std::round(d / quantum_m_)));
  }

  reach_ = margin_ + (channels_.surface_channels() != 0 ? 1 : 0);
  max_out_ = p_.full_block_tiles * p_.tile_cells + 2 * reach_;  // a group of tiles in update() and its margins
  const auto in = static_cast<std::size_t>(max_out_ + 2 * margin_);
  src_.resize(in * in);
  g_.resize(static_cast<std::size_t>(channels_.count()) * static_cast<std::size_t>(max_out_) * in);
  run_.resize(static_cast<std::size_t>(channels_.count()) * in);
  envelope_.resize(in);
  recompute_all();
}

std::size_t ClassDistanceFields::memory_bytes() const noexcept {
  return sizeof(*this) + cells_.capacity() + tile_version_.capacity() * sizeof(std::uint64_t) + tile_dirty_.capacity() +
         dirty_.capacity() * sizeof(std::uint32_t) + quantise_.capacity() + src_.capacity() +
         g_.capacity() * sizeof(std::int16_t) + run_.capacity() * sizeof(std::int16_t) + envelope_.bytes();
}

std::uint64_t ClassDistanceFields::tile_version(std::int32_t tx, std::int32_t ty) const noexcept {
  const std::int32_t lx = tx - extent_.tile_x0, ly = ty - extent_.tile_y0;
  if (lx < 0 || ly < 0 || lx >= extent_.tiles_x || ly >= extent_.tiles_y) return 0;
  const std::uint64_t v = tile_version_[static_cast<std::size_t>(ly) * static_cast<std::size_t>(extent_.tiles_x) + static_cast<std::size_t>(lx)];
  return v == kNeverSet ? 0 : v;
}

bool ClassDistanceFields::set_tile(std::int32_t tx, std::int32_t ty, std::uint64_t version,
                                   std::span<const std::uint8_t> cls) noexcept {
  const std::int32_t lx = tx - extent_.tile_x0, ly = ty - extent_.tile_y0;
  const auto tc = static_cast<std::size_t>(p_.tile_cells);
  if (lx < 0 || ly < 0 || lx >= extent_.tiles_x || ly >= extent_.tiles_y || cls.size() != tc * tc) return false;
  const std::size_t t = static_cast<std::size_t>(ly) * static_cast<std::size_t>(extent_.tiles_x) + static_cast<std::size_t>(lx);
  if (tile_version_[t] == version) return false;
  tile_version_[t] = version;
  const auto w = static_cast<std::size_t>(width_);
  bool changed = false;
  for (std::size_t r = 0; r < tc; ++r) {
    std::uint8_t* row = &cells_[((static_cast<std::size_t>(ly) * tc + r) * w + static_cast<std::size_t>(lx) * tc) * kStride];
    for (std::size_t c = 0; c < tc; ++c) {
      std::uint8_t& cell = row[c * kStride + kStride - 1];
      changed |= cell != cls[r * tc + c];
      cell = cls[r * tc + c];
    }
  }
  // A new version with the same classes (the ortho-map re-sends a tile a keyframe touched without
  // changing its labels) leaves the fields as they are.
  if (changed && tile_dirty_[t] == 0) {
    tile_dirty_[t] = 1;
    dirty_[(dirty_head_ + n_dirty_) % dirty_.size()] = static_cast<std::uint32_t>(t);
    ++n_dirty_;
  }
  return true;
}

double ClassDistanceFields::rect_cost(std::int32_t tiles_w, std::int32_t tiles_h) const noexcept {
  const double tc = p_.tile_cells, m = margin_, r = reach_;
  const double in_w = tiles_w * tc + 2.0 * (m + r), in_h = tiles_h * tc + 2.0 * (m + r), out_h = tiles_h * tc + 2.0 * r;
  return in_w * in_h + out_h * in_w;  // pass 1 runs over the input rectangle, pass 2 along the output rows
}

std::size_t ClassDistanceFields::update(std::size_t max_tiles) noexcept {
  const std::int32_t tc = p_.tile_cells, block = p_.full_block_tiles;
  const auto tiles_x = static_cast<std::uint32_t>(extent_.tiles_x);
  const double one = rect_cost(1, 1);
  const double budget = max_tiles >= n_dirty_ ? std::numeric_limits<double>::infinity() : static_cast<double>(max_tiles) * one;
  double spent = 0.0;
  std::size_t done = 0;
  while (n_dirty_ > 0 && (done == 0 || spent + one <= budget)) {
    // The oldest changed tile, grouped with the later ones that share one rectangle of at most block x
    // block tiles with it when one pass over the union costs no more than a pass of its own (adjacent
    // tiles share their margins), within what is left of the budget.
    const std::uint32_t seed = dirty_[dirty_head_];
    std::int32_t bx0 = static_cast<std::int32_t>(seed % tiles_x), by0 = static_cast<std::int32_t>(seed / tiles_x);
    std::int32_t bx1 = bx0, by1 = by0;
    tile_dirty_[seed] = 2;
    std::size_t group = 1;
    double cost = one;  // of the group's rectangle so far
    const double cap = std::max(budget - spent, one);
    for (std::size_t i = 1; i < n_dirty_; ++i) {
      const std::uint32_t t = dirty_[(dirty_head_ + i) % dirty_.size()];
      const auto tx = static_cast<std::int32_t>(t % tiles_x), ty = static_cast<std::int32_t>(t / tiles_x);
      const std::int32_t nx0 = std::min(bx0, tx), ny0 = std::min(by0, ty), nx1 = std::max(bx1, tx), ny1 = std::max(by1, ty);
      if (nx1 - nx0 >= block || ny1 - ny0 >= block) continue;
      const double c = rect_cost(nx1 - nx0 + 1, ny1 - ny0 + 1);
      if (c > cost + one || c > cap) continue;
      bx0 = nx0, by0 = ny0, bx1 = nx1, by1 = ny1;
      cost = c;
      tile_dirty_[t] = 2;
      ++group;
    }
    // Take the group out of the ring, keeping the others in order of change.
    std::size_t kept = 0;
    for (std::size_t i = 0; i < n_dirty_; ++i) {
      const std::uint32_t t = dirty_[(dirty_head_ + i) % dirty_.size()];
      if (tile_dirty_[t] == 2) tile_dirty_[t] = 0;
      else dirty_[(dirty_head_ + kept++) % dirty_.size()] = t;
    }
    n_dirty_ = kept;
    if (n_dirty_ == 0) dirty_head_ = 0;
    recompute_rect(bx0 * tc - reach_, by0 * tc - reach_, (bx1 + 1) * tc + reach_, (by1 + 1) * tc + reach_);
    spent += cost;
    done += group;
  }
  return done;
}

void ClassDistanceFields::recompute_all() noexcept {
  const std::int32_t b = p_.full_block_tiles * p_.tile_cells;
  for (std::int32_t y = 0; y < height_; y += b)
    for (std::int32_t x = 0; x < width_; x += b) recompute_rect(x, y, x + b, y + b);
  for (std::size_t i = 0; i < n_dirty_; ++i) tile_dirty_[dirty_[(dirty_head_ + i) % dirty_.size()]] = 0;
  n_dirty_ = 0;
  dirty_head_ = 0;
}

void ClassDistanceFields::recompute_rect(std::int32_t x0, std::int32_t y0, std::int32_t x1, std::int32_t y1) noexcept {
  x0 = std::max(x0, 0);
  y0 = std::max(y0, 0);
  x1 = std::min(x1, width_);
  y1 = std::min(y1, height_);
  if (x1 <= x0 || y1 <= y0) return;
  const std::int32_t m = margin_;
  const std::int32_t ow = x1 - x0, oh = y1 - y0;
  if (ow > max_out_ || oh > max_out_) return;  // internal callers never ask for more than the scratch holds
  const std::int32_t iw = ow + 2 * m, ih = oh + 2 * m;
  const std::int32_t ix0 = x0 - m, iy0 = y0 - m;
  const auto uiw = static_cast<std::size_t>(iw);
  const auto w = static_cast<std::size_t>(width_);
  const int n_ch = channels_.count();

  // Source bits of the input rectangle (outside the extent: unknown).
  const std::uint8_t outside_bits = source_mask_[255];
  const std::uint8_t surface = channels_.surface_channels();
  for (std::int32_t yi = 0; yi < ih; ++yi) {
    std::uint8_t* dst = &src_[static_cast<std::size_t>(yi) * uiw];
    const std::int32_t gy = iy0 + yi;
    if (gy < 0 || gy >= height_) {
      std::fill_n(dst, uiw, outside_bits);
      continue;
    }
    const std::uint8_t* row = &cells_[static_cast<std::size_t>(gy) * w * kStride + kStride - 1];
    for (std::int32_t xi = 0; xi < iw; ++xi) {
      const std::int32_t gx = ix0 + xi;
      dst[xi] = (gx < 0 || gx >= width_) ? outside_bits : source_mask_[row[static_cast<std::size_t>(gx) * kStride]];
    }
    if (surface != 0) keep_faces(gy, ix0, iw, dst);
  }

  // Pass 1: vertical distance to the nearest source in each input column, for the output rows: a run
  // length per column swept down the rows, then up, a whole row at a time (contiguous, vectorisable).
  // The downward sweep stops at the last output row, the upward one at the first.
  const auto none = static_cast<std::int16_t>(m + 1);
  const std::size_t plane = static_cast<std::size_t>(oh) * uiw;
  for (int up = 0; up < 2; ++up) {
    std::fill_n(run_.begin(), static_cast<std::size_t>(n_ch) * uiw, none);
    for (std::int32_t step = 0; step < ih - m; ++step) {
      const std::int32_t yi = up ? ih - 1 - step : step;
      const std::uint8_t* bits = &src_[static_cast<std::size_t>(yi) * uiw];
      const std::int32_t yo = yi - m;
      const bool out_row = yo >= 0 && yo < oh;
      for (int k = 0; k < n_ch; ++k) {
        std::int16_t* run = &run_[static_cast<std::size_t>(k) * uiw];
        const auto bit = static_cast<std::uint8_t>(1U << static_cast<unsigned>(k));
        for (std::size_t xi = 0; xi < uiw; ++xi) {
          const auto next = static_cast<std::int16_t>(run[xi] + 1);
          run[xi] = (bits[xi] & bit) != 0 ? std::int16_t{0} : (next < none ? next : none);
        }
        if (!out_row) continue;
        std::int16_t* g = &g_[static_cast<std::size_t>(k) * plane + static_cast<std::size_t>(yo) * uiw];
        if (up) {
          for (std::size_t xi = 0; xi < uiw; ++xi) g[xi] = std::min(g[xi], run[xi]);
        } else {
          std::copy_n(run, uiw, g);
        }
      }
    }
  }

  // Pass 2: lower envelope of the parabolas (x - q)^2 + g(q)^2 along each output row (Felzenszwalb-Huttenlocher).
  const std::size_t max_d2 = quantise_.size() - 1;
  for (int k = 0; k < n_ch; ++k)
    for (std::int32_t yo = 0; yo < oh; ++yo) {
      const std::int16_t* g = &g_[static_cast<std::size_t>(k) * plane + static_cast<std::size_t>(yo) * uiw];
      std::uint8_t* out = &cells_[(static_cast<std::size_t>(y0 + yo) * w + static_cast<std::size_t>(x0)) * kStride + static_cast<std::size_t>(k)];
      const bool any = dt::squared_distance_line(
          iw, [&](std::int32_t q) { return g[q] < none; }, [&](std::int32_t q) { return static_cast<double>(static_cast<std::int32_t>(g[q]) * g[q]); },
          m, m + ow, envelope_, [&](std::int32_t xi, double d2) {
            const auto i = static_cast<std::size_t>(d2);
            out[static_cast<std::size_t>(xi - m) * kStride] = i <= max_d2 ? quantise_[i] : std::uint8_t{255};
          });
      if (!any)
        for (std::int32_t xo = 0; xo < ow; ++xo) out[static_cast<std::size_t>(xo) * kStride] = 255;
    }
}

void ClassDistanceFields::keep_faces(std::int32_t gy, std::int32_t gx0, std::int32_t n, std::uint8_t* bits) const noexcept {
  if (gy < 0 || gy >= height_) return;  // outside: unknown, not a member
  const std::uint8_t surface = channels_.surface_channels(), outside = source_mask_[255];
  const auto w = static_cast<std::size_t>(width_);
  const std::uint8_t* row = &cells_[static_cast<std::size_t>(gy) * w * kStride + kStride - 1];  // class of cell gx at [gx * kStride]
  const std::uint8_t* south = gy > 0 ? row - w * kStride : nullptr;
  const std::uint8_t* north = gy + 1 < height_ ? row + w * kStride : nullptr;
  const std::int32_t first = std::max(0, -gx0), last = std::min(n, width_ - gx0);
  for (std::int32_t i = first; i < last; ++i) {
    if ((bits[i] & surface) == 0) continue;  // a member of no surface channel (most cells: ground)
    const auto gx = static_cast<std::size_t>(gx0 + i);
    if (row[gx * kStride] == 255) continue;  // unknown cells stay sources of every channel they are a source of (the optimism)
    const std::uint8_t west = gx > 0 ? source_mask_[row[(gx - 1) * kStride]] : outside;
    const std::uint8_t east = gx + 1 < w ? source_mask_[row[(gx + 1) * kStride]] : outside;
    const std::uint8_t s = south != nullptr ? source_mask_[south[gx * kStride]] : outside;
    const std::uint8_t nn = north != nullptr ? source_mask_[north[gx * kStride]] : outside;
    bits[i] = static_cast<std::uint8_t>(bits[i] & ~(surface & west & east & s & nn));
  }
}

std::size_t ClassDistanceFields::index_at(double x, double y) const noexcept {
  const double fc = (x - origin_x_) / p_.resolution_m, fr = (y - origin_y_) / p_.resolution_m;
  if (!(fc >= 0.0) || !(fr >= 0.0) || fc >= width_ || fr >= height_) return outside_index();
  return static_cast<std::size_t>(fr) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(fc);
}

std::uint8_t ClassDistanceFields::class_at(double x, double y) const noexcept {
  return cells_[index_at(x, y) * kStride + kStride - 1];
}

double ClassDistanceFields::distance_m(double x, double y, int channel) const noexcept {
  if (channel < 0 || channel >= channels_.count()) return p_.truncation_m;
  return cells_[index_at(x, y) * kStride + static_cast<std::size_t>(channel)] * quantum_m_;
}

}  // namespace ag::loc
