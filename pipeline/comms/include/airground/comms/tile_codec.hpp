// Map tiles as gossip payloads: classes and byte-shuffled elevations compressed with zstd.
//   format u8 (1) | tx i32 | ty i32 | version u64 | stamp i64 | zstd frame of
//   [cls: kTileCellCount bytes][elevation: kTileCellCount float32, byte plane 0 of every cell, then 1, 2, 3]
// Shuffling puts the slowly varying exponent bytes together, which zstd then squeezes well; lossless.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/core/messages.hpp"

typedef struct ZSTD_CCtx_s ZSTD_CCtx;
typedef struct ZSTD_DCtx_s ZSTD_DCtx;

namespace ag::comms {

inline constexpr std::size_t kTileRawBytes = kTileCellCount * (1 + sizeof(float));
inline constexpr std::size_t kTileHeaderBytes = 1 + 4 + 4 + 8 + 8;

class TileCodec {
 public:
  explicit TileCodec(int level = 3);  // allocates its zstd workspaces once
  ~TileCodec();
  TileCodec(const TileCodec&) = delete;
  TileCodec& operator=(const TileCodec&) = delete;

  [[nodiscard]] static std::size_t max_payload_bytes() noexcept;
  // No allocation. Returns the payload size (0 on failure: out too small).
  std::size_t encode(const MapTileMsg& tile, std::span<std::uint8_t> out) noexcept;
  // No allocation. False (and nothing written to the tile's cells beyond scratch) for anything malformed.
  bool decode(std::span<const std::uint8_t> payload, MapTileMsg& tile) noexcept;

 private:
  std::vector<std::uint8_t> cwork_, dwork_, raw_;
  ZSTD_CCtx* cctx_{nullptr};
  ZSTD_DCtx* dctx_{nullptr};
  int level_;
};

}  // namespace ag::comms
