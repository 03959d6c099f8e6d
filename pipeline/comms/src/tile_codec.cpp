// Map tile payloads: shuffle + zstd with static (preallocated) contexts.
#define ZSTD_STATIC_LINKING_ONLY
#include "airground/comms/tile_codec.hpp"

#include <zstd.h>

#include <cstring>

#include "airground/comms/bytes.hpp"

namespace ag::comms {

TileCodec::TileCodec(int level) : level_(level) {
  cwork_.resize(ZSTD_estimateCCtxSize(level));
  dwork_.resize(ZSTD_estimateDCtxSize());
  raw_.resize(kTileRawBytes);
  cctx_ = ZSTD_initStaticCCtx(cwork_.data(), cwork_.size());
  dctx_ = ZSTD_initStaticDCtx(dwork_.data(), dwork_.size());
}

TileCodec::~TileCodec() = default;  // static contexts live in the vectors

std::size_t TileCodec::max_payload_bytes() noexcept { return kTileHeaderBytes + ZSTD_COMPRESSBOUND(kTileRawBytes); }

std::size_t TileCodec::encode(const MapTileMsg& tile, std::span<std::uint8_t> out) noexcept {
  if (cctx_ == nullptr || out.size() < kTileHeaderBytes) return 0;
  std::memcpy(raw_.data(), tile.cls.data(), kTileCellCount);
  std::uint8_t* planes = raw_.data() + kTileCellCount;
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    std::uint8_t b[4];
    std::memcpy(b, &tile.elevation[i], 4);
    for (std::size_t p = 0; p < 4; ++p) planes[p * kTileCellCount + i] = b[p];
  }
  ByteWriter w(out.first(kTileHeaderBytes));
  w.u8(1);
  w.u32(static_cast<std::uint32_t>(tile.tx));
  w.u32(static_cast<std::uint32_t>(tile.ty));
  w.u64(tile.version);
  w.i64(tile.stamp);
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
  if (!r.ok() || format != 1) return false;
  const auto z = payload.subspan(kTileHeaderBytes);
  // The frame must say exactly the raw size, before anything is decompressed.
  const unsigned long long content = ZSTD_getFrameContentSize(z.data(), z.size());
  if (content != kTileRawBytes) return false;
  const std::size_t n = ZSTD_decompressDCtx(dctx_, raw_.data(), raw_.size(), z.data(), z.size());
  if (ZSTD_isError(n) || n != kTileRawBytes) return false;
  tile.tx = static_cast<std::int32_t>(tx);
  tile.ty = static_cast<std::int32_t>(ty);
  tile.version = version;
  tile.stamp = stamp;
  std::memcpy(tile.cls.data(), raw_.data(), kTileCellCount);
  const std::uint8_t* planes = raw_.data() + kTileCellCount;
  for (std::size_t i = 0; i < kTileCellCount; ++i) {
    std::uint8_t b[4];
    for (std::size_t p = 0; p < 4; ++p) b[p] = planes[p * kTileCellCount + i];
    std::memcpy(&tile.elevation[i], b, 4);
  }
  return true;
}

}  // namespace ag::comms
