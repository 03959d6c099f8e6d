// Map tile payloads: shuffle + zstd with static (preallocated) contexts.
#define ZSTD_STATIC_LINKING_ONLY
#include "airground/comms/tile_codec.hpp"

#include <algorithm>

#include <zstd.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "airground/comms/bytes.hpp"

namespace ag::comms {

TileCodec::TileCodec(int level) : level_(level) {
  cwork_.resize(ZSTD_estimateCCtxSize(level));
  dwork_.resize(ZSTD_estimateDCtxSize());
  raw_.resize(kTileCodedBytes);
  cctx_ = ZSTD_initStaticCCtx(cwork_.data(), cwork_.size());
  dctx_ = ZSTD_initStaticDCtx(dwork_.data(), dwork_.size());
}

TileCodec::~TileCodec() = default;  // static contexts live in the vectors

std::size_t TileCodec::max_payload_bytes() noexcept { return kTileHeaderBytes + ZSTD_COMPRESSBOUND(kTileCodedBytes); }

std::size_t TileCodec::encode(const MapTileMsg& tile, std::span<std::uint8_t> out) noexcept {
  if (cctx_ == nullptr || out.size() < kTileHeaderBytes) return 0;
  std::memcpy(raw_.data(), tile.cls.data(), kTileCellCount);
  float base = std::numeric_limits<float>::infinity();
  for (const float e : tile.elevation)
    if (std::isfinite(e)) base = std::min(base, e);
  if (!std::isfinite(base)) base = 0.0f;
  std::uint8_t* lo = raw_.data() + kTileCellCount;
  std::uint8_t* hi = lo + kTileCellCount;
  std::uint16_t prev = 0;
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    const float e = tile.elevation[i];
    std::uint16_t q = 0xFFFF;
    if (std::isfinite(e)) q = static_cast<std::uint16_t>(std::clamp(std::lround((static_cast<double>(e) - static_cast<double>(base)) / kTileElevationStepM), 0L, 65534L));
    const auto d = static_cast<std::uint16_t>(q - prev);
    prev = q;
    lo[i] = static_cast<std::uint8_t>(d & 0xFF);
    hi[i] = static_cast<std::uint8_t>(d >> 8);
  }
  ByteWriter w(out.first(kTileHeaderBytes));
  w.u8(2);
  w.u32(static_cast<std::uint32_t>(tile.tx));
  w.u32(static_cast<std::uint32_t>(tile.ty));
  w.u64(tile.version);
  w.i64(tile.stamp);
  std::uint32_t base_bits = 0;
  std::memcpy(&base_bits, &base, 4);
  w.u32(base_bits);
  const std::size_t z = ZSTD_compressCCtx(cctx_, out.data() + kTileHeaderBytes, out.size() - kTileHeaderBytes,
                                          raw_.data(), raw_.size(), level_);
  if (ZSTD_isError(z)) return 0;
  return kTileHeaderBytes + z;
}

bool TileCodec::decode(std::span<const std::uint8_t> payload, MapTileMsg& tile) noexcept {
  if (dctx_ == nullptr) return false;
  ByteReader r(payload);
  std::uint8_t format = 0;
  std::uint32_t tx = 0, ty = 0;
  std::uint64_t version = 0;
  std::int64_t stamp = 0;
  r.u8(format);
  r.u32(tx);
  r.u32(ty);
  r.u64(version);
  r.i64(stamp);
  std::uint32_t base_bits = 0;
  r.u32(base_bits);
  float base = 0;
  std::memcpy(&base, &base_bits, 4);
  if (!r.ok() || format != 2 || !std::isfinite(base)) return false;
  const auto z = payload.subspan(kTileHeaderBytes);
  // The frame must say exactly the raw size, before anything is decompressed.
  const unsigned long long content = ZSTD_getFrameContentSize(z.data(), z.size());
  if (content != kTileCodedBytes) return false;
  const std::size_t n = ZSTD_decompressDCtx(dctx_, raw_.data(), raw_.size(), z.data(), z.size());
  if (ZSTD_isError(n) || n != kTileCodedBytes) return false;
  tile.tx = static_cast<std::int32_t>(tx);
  tile.ty = static_cast<std::int32_t>(ty);
  tile.version = version;
  tile.stamp = stamp;
  std::memcpy(tile.cls.data(), raw_.data(), kTileCellCount);
  const std::uint8_t* lo = raw_.data() + kTileCellCount;
  const std::uint8_t* hi = lo + kTileCellCount;
  std::uint16_t q = 0;
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    q = static_cast<std::uint16_t>(q + (lo[i] | (hi[i] << 8)));
    tile.elevation[i] = q == 0xFFFF ? std::numeric_limits<float>::quiet_NaN()
                                    : static_cast<float>(static_cast<double>(base) + q * kTileElevationStepM);
  }
  return true;
}

}  // namespace ag::comms
