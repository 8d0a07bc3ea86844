// Where tiles come from: a store file, a procedural generator, or a test
// wrapper that injects latency and failures. Sources hand out tiles already
// converted to the GPU layout: colour as RGBA8 (or BC1 blocks through
// makeBc1Source()), heights as float32 (TileContent).
#pragma once

#include <clipstream/store/remote.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace clipstream {

// What one fetch cost, for the streamer's statistics.
struct FetchInfo {
  uint64_t bytes_read = 0;  // payload bytes taken from the medium (0 for generated tiles)
  double decode_ms = 0.0;   // decompression + conversion time
};

// What the bytes of a fetched tile are (tileContentBytes() says how many).
enum class TileContent : uint8_t {
  kRgba8,      // colour: R, G, B, A bytes per texel
  kHeightF32,  // heights: one native float per texel, in the store's height
               // unit (offset and scale applied; elevationInfo())
  kBc1,        // colour as BC1 blocks (bc1.h): half a byte per texel, opaque
};

// What an elevation source knows of one tile's heights without reading its
// pixels, in its height unit (TileSource::tileHeightBounds()).
struct TileHeightBounds {
  float min_height = 0.0f;  // lowest and highest level-0 height under the tile's footprint
  float max_height = 0.0f;
  // An upper bound of |level-0 surface - the bilinear surface of the
  // tile's own samples| over its footprint (0 at level 0): a coarse tile's
  // samples, widened by it, bound the ground between them.
  float error = 0.0f;
};

// Bytes of one fetched tile: tile_px^2 * 4 for kRgba8 and kHeightF32,
// bc1TileBytes(tile_px) for kBc1. The streamer's RAM cache counts these.
uint64_t tileContentBytes(TileContent content, uint32_t tile_px);

// A tile content's name: "rgba8", "f32" or "bc1" (reports and messages
// use it; programs parse it with cli::parseTileFormat()).
const char* tileContentName(TileContent content);

// Thread-safe: fetch() may be called from any number of threads at once and
// must not hold a lock across I/O or decompression.
class TileSource {
 public:
  virtual ~TileSource() = default;

  // Geometry of the pyramid this source serves (format is the stored one;
  // fetch() always returns content()'s layout).
  virtual const PyramidGeometry& geometry() const = 0;

  // What fetch() hands out. The default, RGBA8, is every colour source's.
  virtual TileContent content() const { return TileContent::kRgba8; }

  // For kHeightF32 sources: what the elevation store says about its
  // heights (unit, no-data fill, quantisation, range). present = false for
  // colour sources (the default).
  virtual ElevationInfo elevationInfo() const { return {}; }

  // For kHeightF32 sources: the lowest and highest level-0 height under
  // tile `key`'s footprint (every level-0 sample the tile covers, not only
  // its own decimated samples, so a coarse tile bounds every finer tile
  // below it) and its geometric error, in the store's height unit, without
  // reading the tile's pixels. An elevation store answers from its index
  // (which may read an index page: a request over HTTP), so ask when
  // opening or on a loader thread, never per frame on the render thread
  // (loadTerrainBounds()). Thread-safe like fetch(). kUnsupported: the
  // source has no bounds (the default); kOutOfRange for a key outside the
  // pyramid; an index page that fails its checks: its error.
  virtual Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const {
    (void)key;
    *out = {};
    return Status::error(ErrorCode::kUnsupported, describe() + " has no per-tile height bounds");
  }

  // Reads, verifies, decodes and converts one tile into *rgba (resized to
  // tileContentBytes(content(), tile_px)): RGBA8 texels, float32 heights
  // for a kHeightF32 source, BC1 blocks for a kBc1 one (the buffer keeps
  // its name). A failure leaves *rgba unspecified and returns
  // kCorruptTile, kIo, kUnavailable, kOutOfRange, ...
  virtual Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) = 0;

  // fetch() that also reports its cost. The default calls fetch() and
  // reports nothing; sources that read a medium override it.
  virtual Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) {
    *info = {};
    return fetch(key, rgba);
  }

  // Short human name for logs: "store:path", "procedural:67108864x67108864".
  virtual std::string describe() const = 0;

  // Tiles worth fetching together with fetchBatch(): more than 1 for a
  // source where one read of neighbours costs about what one tile does (a
  // store over HTTP: one range request instead of several round trips).
  // The streamer then hands a loader up to this many queued tiles of one
  // level at once, shaped as batchShape() says. 1 = fetch tiles one by one.
  virtual size_t maxBatch() const { return 1; }
  // Which queued tiles go together in a batch: kRow, neighbours in the
  // popped tile's row (within maxBatch() columns); kSquare, those in its
  // aligned square (4 x 4 tiles for a batch of 16, 8 x 8 for 64). A store
  // source answers what its file's payload order favours
  // (TileStoreReader::suggestedBatchShape()). Any thread, cheap.
  virtual BatchShape batchShape() const { return BatchShape::kRow; }

  // fetchWithInfo() for several tiles: *rgba[i], statuses[i] and infos[i]
  // for keys[i] (spans of equal size). Same thread rule as fetch(). The
  // default fetches them one by one.
  virtual void fetchBatch(std::span<const TileKey> keys, std::span<std::vector<uint8_t>* const> rgba,
                          std::span<Status> statuses, std::span<FetchInfo> infos) {
    for (size_t i = 0; i < keys.size(); ++i) statuses[i] = fetchWithInfo(keys[i], rgba[i], &infos[i]);
  }

  // Loader threads worth running against this source when the streamer is
  // not told a number (StreamerConfig::io_threads = 0): a store read over
  // HTTP wants one per connection, since each thread waits out a round trip.
  // 0 = no preference (the streamer runs one per core).
  virtual unsigned suggestedLoaderThreads() const { return 0; }

  // What reading a store by URL cost so far (requests, bytes, connections,
  // disk cache hits; TileStoreReader::remoteStats()). All zero for other
  // sources. Any thread.
  virtual RemoteStats remoteStats() const { return {}; }
};

// Opens a colour tile store file, or a URL of one (isStoreUrl()), as a
// source; a path that is no store but a TIFF is opened as a
// Cloud-Optimized GeoTIFF, streamed without tiling (CogReader, store/cog.h;
// describe() "cog:PATH"). On failure returns null and sets *status; an
// elevation store is refused (kUnsupported, naming the path): heights are
// not colour, and openElevationSource() opens them.
// Conversion to RGBA8: R8 -> (v, v, v, 255); R16 -> grey of the high byte
// (v >> 8: a linear rescale, exact for data that uses the full 16-bit range;
// data sets needing a window belong in the tiler); RGB8 -> A = 255.
std::shared_ptr<TileSource> openStoreSource(const std::string& path, Status* status);
// The same for a path that may be an http:// or https:// URL, read with
// `remote`'s settings (the first form uses RemoteOptions{}).
std::shared_ptr<TileSource> openStoreSource(const std::string& path, const RemoteOptions& remote,
                                            Status* status);

// Opens an elevation store (format version 2, ElevationInfo::present) as a
// kHeightF32 source: each tile is tile_px^2 floats, the store's heights
// after scale and offset (decodeTileHeights()), in its height unit. On
// failure returns null and sets *status; a colour store is refused
// (kUnsupported, naming the path).
std::shared_ptr<TileSource> openElevationSource(const std::string& path, Status* status);
// The same for a path that may be an http:// or https:// URL.
std::shared_ptr<TileSource> openElevationSource(const std::string& path,
                                                const RemoteOptions& remote, Status* status);

// Deterministic procedural texture of any size up to 2^31 texels a side,
// computed per tile (no disk). Every texel is a pure function of (level, x, y)
// in that level's texel coordinates: six layers of hashed colours over
// aligned cells of 8 to 256 texels, the tile grid drawn darker (the
// definition: clipstream/streamer/testing/procedural_texel.h). Texels of edge
// tiles beyond the level's size follow the same function (no padding rule).
// Largest procedural side makeProceduralSource() accepts (2^31 texels: a
// planet at 2 cm per texel, and positions stay exact in double precision).
inline constexpr uint64_t kMaxProceduralSidePx = uint64_t(1) << 31;

struct ProceduralSpec {
  uint64_t width_px = uint64_t(1) << 26;
  uint64_t height_px = uint64_t(1) << 26;
  uint32_t tile_px = 128;
  uint32_t seed = 1;
};
std::shared_ptr<TileSource> makeProceduralSource(const ProceduralSpec& spec);

// An in-memory TileSource over an RGBA8 image (top row first): level 0 is
// the image, each coarser level the 2x2 box average of the one below (edge
// texels repeated for odd sizes), tile padding is black: an image a
// program already holds in memory, streamed like a store (the tests and the
// frame benchmark use it).
std::shared_ptr<TileSource> makeImageSource(std::vector<uint8_t> rgba, uint32_t width_px,
                                            uint32_t height_px, uint32_t tile_px);

// Deterministic procedural heights (a kHeightF32 source, metres) of any
// size up to kMaxProceduralSidePx samples a side, computed per tile:
// rolling value noise over five octaves (cells of 2^13 down to 2^5
// samples) and a 120-unit cliff on every other band of 2^14 columns. Every
// sample is proceduralHeight() of its level-0 coordinates, and level L's
// sample (i, j) is level 0's (i 2^L, j 2^L), as the tiler decimates. Null
// for an empty or too large size.
std::shared_ptr<TileSource> makeProceduralHeightSource(const ProceduralSpec& spec);
double proceduralHeight(const ProceduralSpec& spec, uint64_t x, uint64_t y);

// Synthesized relief below a DEM's resolution (docs/terrain.md,
// "Synthesized relief"): a kHeightF32 source of `levels` more levels than
// `dem` (a kHeightF32 source), each 2x finer: its level-0 sample (x, y) lies
// at the DEM's level-0 sample (x, y) / 2^levels, level `levels` and up are
// the DEM's own levels, and the samples between the DEM's are its cell's
// bilinear surface plus fractal value noise that vanishes at the DEM's
// samples, scaled by the DEM's local roughness. A pure function of
// position: deterministic, continuous across tiles, and each level the
// decimation of the finer. Reads the DEM's level-0 tiles in fetch(), on
// the caller's thread. Null with *status = kInvalidArgument for a source
// that is not heights or `levels` outside 1..kMaxSynthesizedLevels.
inline constexpr uint32_t kMaxSynthesizedLevels = 4;
std::shared_ptr<TileSource> makeSynthesizedHeightSource(std::shared_ptr<TileSource> dem, uint32_t levels,
                                                         Status* status);

// Transcoding wrapper: hands out `rgba8`'s colour tiles as BC1 blocks
// (kBc1), encoded by encodeBc1Tile() inside fetch(), so the streamer's
// loader threads do the work and its RAM cache holds the compressed tiles
// (an eighth of the bytes). Null with *status = kInvalidArgument when the
// inner source is missing, is not an RGBA8 colour source, or its tile size
// is not a multiple of 4.
std::shared_ptr<TileSource> makeBc1Source(std::shared_ptr<TileSource> rgba8, Status* status);

}  // namespace clipstream
