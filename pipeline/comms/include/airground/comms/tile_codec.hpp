// Map tiles as gossip payloads: classes and 1-cm elevations, delta-coded and compressed with zstd.
//   format u8 (2) | tx i32 | ty i32 | version u64 | stamp i64 | base f32 [m] | zstd frame of
//   [cls: kTileCellCount bytes][elevation low bytes][elevation high bytes]
// Elevation travels as q = round((e - base) / 1 cm) in 0..65534 (65535 = unknown/NaN), base the tile's
// lowest known cell, so a tile may span 655 m of height; each q is sent as its difference to the cell
// before it in row-major order, split into byte planes. Classes are exact; elevations within 5 mm (the
// map itself is good to decimetres).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "airground/messages/messages.hpp"

typedef struct ZSTD_CCtx_s ZSTD_CCtx;
typedef struct ZSTD_DCtx_s ZSTD_DCtx;

namespace ag::comms {

inline constexpr std::size_t kTileRawBytes = kTileCellCount * (1 + sizeof(float));  // a tile in memory
inline constexpr std::size_t kTileCodedBytes = kTileCellCount * 3;                    // what zstd sees
inline constexpr std::size_t kTileHeaderBytes = 1 + 4 + 4 + 8 + 8 + 4;
inline constexpr double kTileElevationStepM = 0.01;

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
