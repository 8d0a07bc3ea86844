// The synthetic tile pattern and the one store writer of the tests.
//
// Every byte of a synthetic tile is a function of (level, x, y, pixel,
// channel), so a tile read back can be compared with the one written, and a
// mixed-up tile, pixel or channel shows. Every tile that is not constant
// also carries its key, stamped into the first twelve pixels of row 0, so a
// test handed a tile can tell which one it got (syntheticTileKey()), even
// after a store source converted it to RGBA8.
//
// With ConstantTiles::kSome, one key in five (isConstantTile()) holds a
// single pixel value throughout, so stores written this way exercise the
// writer's constant-tile path and the reader's constant entries too.
//
// Thread rule: every function here may be called from any thread; the
// writers call their fill function on the calling thread only.
#pragma once

#include <clipstream/store/tile_store.h>

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

namespace clipstream::test {

enum class ConstantTiles {
  kSome,  // keys where isConstantTile() holds are one value
  kNone,  // every tile varies (and carries its key)
};

// True for the keys that are constant under ConstantTiles::kSome: about one
// in five, spread over levels and positions.
bool isConstantTile(const TileKey& key);

// Pixel (px, py) of tile `key` in `format`: bytesPerPixel(format) bytes
// written to `out`.
void syntheticPixel(PixelFormat format, const TileKey& key, uint32_t px, uint32_t py, uint8_t* out,
                    ConstantTiles constant = ConstantTiles::kSome);

// The same pixel as a store source hands it out (RGBA8; R8 and R16 become
// grey, R16 from its high byte; A = 255 unless stored): the reference a test
// of a TileSource compares with, computed here and not by the streamer.
void syntheticRgba(PixelFormat format, const TileKey& key, uint32_t px, uint32_t py,
                   uint8_t rgba[4], ConstantTiles constant = ConstantTiles::kSome);

// A whole tile: geometry.tileBytes() bytes in the geometry's format.
std::vector<uint8_t> syntheticTile(const PyramidGeometry& geometry, const TileKey& key,
                                   ConstantTiles constant = ConstantTiles::kSome);

// Which tile `pixels` is: reads the stamp of a non-constant synthetic tile.
// `format` is that of the bytes given: the store's for what a reader
// returns, kRGBA8 for what a TileSource returns (the stamp survives the
// conversion from every format). `pixels` must hold at least row 0 of a
// tile of 12 or more pixels a side. False, leaving *key alone, when there is
// no valid stamp: a constant tile, another pattern, or damaged bytes.
bool syntheticTileKey(PixelFormat format, std::span<const uint8_t> pixels, TileKey* key);

// Fills *pixels (resized to tileBytes() by the callee) with tile `key`.
using TileFill = std::function<Status(const TileKey& key, std::vector<uint8_t>* pixels)>;

// Writes every tile of `geometry`, finest level first and row by row, as
// `fill` makes it, into a new store at `path` with `options`. Returns the
// first failure of fill, encodeTile() or the writer (the unfinished writer
// then removes its temporaries), else finish()'s status.
Status writeStore(const std::string& path, const PyramidGeometry& geometry,
                  const WriterOptions& options, const TileFill& fill);

// An F32 elevation store of w x h samples whose level-0 sample (x, y) is
// height(x, y); levels are decimated (level L's (i, j) is level 0's
// (i 2^L, j 2^L)) and each tile's bounds are those of every level-0 sample
// under it (its own samples and its children's bounds), as the tiler
// records them.
Status writeElevationStore(const std::string& path, uint64_t w, uint64_t h,
                           const std::function<float(uint64_t x, uint64_t y)>& height);

// writeStore() with syntheticTile(). `options` has no default so that
// writeSyntheticStore(path, {.width_px = ...}) means the overload below
// (PyramidGeometry has fields of the same names).
Status writeSyntheticStore(const std::string& path, const PyramidGeometry& geometry,
                           const WriterOptions& options,
                           ConstantTiles constant = ConstantTiles::kSome);

// A synthetic store described by its size: what most tests outside the
// store's own need.
struct SyntheticStoreSpec {
  uint64_t width_px = 256;
  uint64_t height_px = 256;
  uint32_t tile_px = 64;
  PixelFormat format = PixelFormat::kRGBA8;
  ConstantTiles constant = ConstantTiles::kSome;
};

// Writes `spec` with the writer's default encoding and no fsync (a test
// store need not survive a power cut). kInvalidArgument naming the size and
// tile size when makePyramidGeometry() refuses them.
Status writeSyntheticStore(const std::string& path, const SyntheticStoreSpec& spec);

}  // namespace clipstream::test
