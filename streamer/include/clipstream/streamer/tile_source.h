// Where tiles come from: a store file, a procedural generator, or a test
// wrapper that injects latency and failures. Sources hand out tiles already
// converted to the GPU layout (RGBA8, tile_px * tile_px * 4 bytes).
#pragma once

#include <clipstream/store/types.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace clipstream {

// Thread-safe: fetch() may be called from any number of threads at once and
// must not hold a lock across I/O or decompression.
class TileSource {
 public:
  virtual ~TileSource() = default;

  // Geometry of the pyramid this source serves (format is the stored one;
  // fetch() always returns RGBA8).
  virtual const PyramidGeometry& geometry() const = 0;

  // Reads, verifies, decodes and converts one tile to RGBA8 into *rgba
  // (resized to tile_px * tile_px * 4). A failure leaves *rgba unspecified
  // and returns kCorruptTile, kIo, kUnavailable, kOutOfRange, ...
  virtual Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) = 0;

  // Short human name for logs: "store:path", "procedural:67108864x67108864".
  virtual std::string describe() const = 0;
};

// Opens a tile store file as a source. On failure returns null and sets *status.
std::shared_ptr<TileSource> openStoreSource(const std::string& path, Status* status);

// Deterministic procedural texture of any size up to 2^31 texels a side,
// computed per tile (no disk). Every texel is a pure function of (level, x, y)
// in that level's texel coordinates; coarser levels are the exact 2x2 box
// average of the finer level's definition where it matters for tests
// (see proceduralTexel()).
struct ProceduralSpec {
  uint64_t width_px = uint64_t(1) << 26;
  uint64_t height_px = uint64_t(1) << 26;
  uint32_t tile_px = 128;
  uint32_t seed = 1;
};
std::shared_ptr<TileSource> makeProceduralSource(const ProceduralSpec& spec);

// The RGBA8 value the procedural source gives texel (tx, ty) of `level`.
// Exposed so renderer tests can compute CPU references without the source.
void proceduralTexel(const ProceduralSpec& spec, uint32_t level, uint64_t tx, uint64_t ty,
                     uint8_t rgba[4]);

// Test/benchmark wrapper: adds latency to every fetch and fails a chosen
// fraction of tiles (deterministically by key) or all of them.
struct FaultSpec {
  double latency_ms = 0.0;
  double fail_fraction = 0.0;     // 0..1, chosen by hashing the key
  ErrorCode fail_code = ErrorCode::kCorruptTile;
  uint32_t seed = 7;
};
std::shared_ptr<TileSource> makeFaultySource(std::shared_ptr<TileSource> inner,
                                             const FaultSpec& spec);

}  // namespace clipstream
