// The tile store: one file holding a full mip pyramid of square tiles.
// Reader and writer live side by side here and in src/; nothing else in the
// project parses these bytes. The byte layout is specified in
// docs/tile-store.md.
#pragma once

#include <clipstream/store/remote.h>
#include <clipstream/store/types.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace clipstream {

enum class Compression : uint32_t { kNone = 0, kZstd = 1 };
// Reversible transform applied to each tile before compression.
enum class Predictor : uint32_t {
  kNone = 0,
  kLeftDelta = 1,  // per row, per channel: p[x] - p[x-1] (mod 2^bits)
};

// Everything the header records besides geometry.
struct StoreEncoding {
  Compression compression = Compression::kZstd;
  int zstd_level = 1;
  Predictor predictor = Predictor::kLeftDelta;
  DownsampleFilter filter = DownsampleFilter::kBox;
  bool linear_light = false;  // filter ran in linear light (informational)
};

// Unit of an elevation store's heights. Values are part of the on-disk format.
enum class HeightUnits : uint32_t { kMetre = 1, kFoot = 2, kUsSurveyFoot = 3 };
bool isValidHeightUnits(uint32_t raw);
const char* heightUnitsName(HeightUnits units);  // "metre", "foot", "US survey foot"
double metresPerUnit(HeightUnits units);

// What an elevation store says about its heights (format version 2). A
// height is offset + scale * sample for integer formats, the sample itself
// for F32 (scale 1, offset 0). No-data samples of the input were filled
// from valid neighbours before tiling (docs/tile-store.md, "Elevation"), so
// every stored sample is a height.
struct ElevationInfo {
  bool present = false;        // false: a colour store
  double scale = 1.0;
  double offset = 0.0;
  HeightUnits units = HeightUnits::kMetre;
  bool units_assumed = true;   // the input did not say; metres taken
  bool has_nodata = false;     // the input declared a no-data value
  double nodata = 0.0;
  uint64_t filled_samples = 0; // level-0 samples that were no-data (or NaN) and were filled
  bool quantised = false;      // float heights stored in steps of `scale`: error <= scale / 2
  double max_error = 0.0;      // largest |stored - input| height measured at level 0
  double min_height = 0.0;     // lowest and highest stored height
  double max_height = 0.0;
};

// What a partial store says about the sharded run it is one part of
// (docs/tile-store.md, section 10, "Shard record"; docs/tiler.md, "Sharded
// runs"). A partial store is a whole, valid store of a band of the image;
// its levels 0..owned_levels-1 hold exactly the tiles of those levels of
// the store the single run makes, shifted by (x0_px, y0_px) / (tile_px * 2^l)
// tiles. Its georeference is the whole image's, not the band's.
struct ShardInfo {
  bool present = false;        // false: an ordinary, whole store
  uint32_t index = 0;          // 1..count
  uint32_t count = 0;
  uint64_t full_width_px = 0;  // level 0 of the whole image
  uint64_t full_height_px = 0;
  uint64_t x0_px = 0;          // this store's level-0 origin in the whole image
  uint64_t y0_px = 0;
  uint32_t owned_levels = 0;   // 1..level_count of this store
  uint64_t fingerprint = 0;    // the run's input and options; equal across its shards
};

// What a store says about itself.
struct StoreInfo {
  PyramidGeometry geometry;
  StoreEncoding encoding;
  GeoReference geo;
  ElevationInfo elevation;
  ShardInfo shard;             // present for a partial store
  uint64_t file_bytes = 0;
  uint32_t format_version = 0;
};

// Where one tile's payload lives, as recorded in the index.
struct TileLocation {
  bool constant = false;     // all pixels equal; no payload, value in constant_pixel
  uint8_t constant_pixel[8] = {};  // first bytesPerPixel() bytes valid
  uint64_t offset = 0;       // payload byte offset in the file (non-constant)
  uint32_t stored_bytes = 0; // payload size on disk
  uint32_t checksum = 0;     // checksum of the stored payload bytes
  // Elevation stores: the lowest and highest level-0 height under the
  // tile's footprint (so a coarse tile bounds every finer tile below it),
  // and its geometric error: an upper bound of |finest surface - this
  // level's surface| over the footprint, in height units (0 at level 0).
  float min_height = 0.0f;
  float max_height = 0.0f;
  float error = 0.0f;
};

// A payload as read from disk, verified against its checksum, not yet decoded.
struct RawTile {
  TileKey key;
  TileLocation location;
  std::vector<uint8_t> payload;  // empty for constant tiles
};

// Per-level totals for `clipstream-info`.
struct LevelStats {
  uint64_t tiles = 0;
  uint64_t constant_tiles = 0;
  uint64_t stored_bytes = 0;  // payload bytes on disk
  uint64_t raw_bytes = 0;     // tiles * tileBytes()
};

// Reads a tile store. Opening reads only the header, the level table and the
// small per-level page directories; index pages are read on first use.
//
// Thread-safe: all const methods may be called from any number of threads at
// once. Tile reads are positional (pread, or HTTP range requests for a URL)
// and take no lock around I/O.
class TileStoreReader {
 public:
  // Opens and validates header, level table and page directories. On
  // failure *out is left empty and the Status names the problem.
  static Status open(const std::string& path, std::unique_ptr<TileStoreReader>* out);
  // The same for a path that may be an http:// or https:// URL
  // (isStoreUrl()), read by range requests with `remote`'s settings; the
  // first overload uses RemoteOptions{}. A store replaced on the server
  // after open makes every later read fail (kIo, "changed on the server").
  static Status open(const std::string& path, const RemoteOptions& remote,
                     std::unique_ptr<TileStoreReader>* out);
  ~TileStoreReader();
  TileStoreReader(const TileStoreReader&) = delete;
  TileStoreReader& operator=(const TileStoreReader&) = delete;

  const StoreInfo& info() const;
  const PyramidGeometry& geometry() const { return info().geometry; }

  // Looks up a tile's index entry (reads and verifies its index page on
  // first use). kOutOfRange for keys outside the pyramid.
  Status locate(const TileKey& key, TileLocation* out) const;

  // Reads a tile's payload and verifies its checksum. No decompression.
  Status readRaw(const TileKey& key, RawTile* out) const;

  // Decodes a verified raw tile into `pixels`, which must hold exactly
  // geometry().tileBytes() bytes, in the store's pixel format. Pure: safe on
  // any thread. kCorruptTile if the payload does not decode to that size.
  Status decode(const RawTile& raw, std::span<uint8_t> pixels) const;

  // readRaw() for several tiles: out[i] and statuses[i] for keys[i] (the
  // spans are of equal size). Payloads lying close together in the file are
  // read with one read (RemoteOptions: coalesce_gap_bytes apart at most,
  // coalesce_max_bytes per read); a failed read fails each of its tiles.
  // Every payload is verified against its own checksum.
  void readRawBatch(std::span<const TileKey> keys, std::span<RawTile> out,
                    std::span<Status> statuses) const;
  // Tiles worth asking readRawBatch() for at once: RemoteOptions::
  // batch_tiles for a URL, 1 for a local file (a local read costs no round
  // trip, so batching gains nothing).
  unsigned suggestedBatchTiles() const;
  // Which tiles lie together in this file, as its index pages show:
  // kSquare once a loaded page shows its aligned 2 x 2 squares of tiles
  // lying in one stretch each (a store in curve order), kRow otherwise and
  // until a page has told (the file records no order; docs/tile-store.md).
  // Any thread; a relaxed atomic read.
  BatchShape suggestedBatchShape() const;

  // readRaw + decode. `pixels` is resized to tileBytes().
  Status readTile(const TileKey& key, std::vector<uint8_t>* pixels) const;

  // Totals per level; reads every index page that is not a constant page.
  Status levelStats(std::vector<LevelStats>* out) const;

  // Bytes read from the file so far by this reader (open, index pages and
  // payloads), for statistics; a relaxed atomic counter.
  uint64_t bytesRead() const;
  // Number of index pages loaded so far (a page read twice by racing
  // threads counts once: only the published copy counts).
  uint64_t indexPagesLoaded() const;
  // Reader threads worth running: RemoteOptions::connections for a URL,
  // 0 (no preference) for a local file.
  unsigned suggestedReadThreads() const;
  // Requests, retries and bytes of a URL store so far (zero for a file).
  RemoteStats remoteStats() const;

  struct Problem {
    TileKey key;
    Status status;
  };
  // Reads, verifies and decodes every tile. Calls progress(done, total)
  // now and then from the calling thread. Returns ok only when no problem
  // was found; problems lists each failing tile (capped at max_problems).
  Status verifyAll(std::vector<Problem>* problems, size_t max_problems = 100,
                   const std::function<void(uint64_t, uint64_t)>& progress = {},
                   unsigned threads = 0) const;

 private:
  TileStoreReader();
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

// Where payloads lie inside each level's region of the file. Readers find
// every payload through the index, so any order is the same format: stores
// of either order open in every reader (docs/tile-store.md, "Payload
// order").
enum class PayloadOrder : uint32_t {
  kWritten = 0,  // in the order write() was called (the tiler's: row by row)
  // Along a Hilbert curve over the level's tile grid: every aligned square
  // of 2, 4, 8, ... tiles lies in one stretch of the file and neighbours
  // mostly lie close, so a window of tiles is read with few range
  // requests. Costs one more copy of the payloads in finish().
  kCurve = 1,
};
const char* payloadOrderName(PayloadOrder order);  // "written", "curve"

// Options for writing a store.
struct WriterOptions {
  StoreEncoding encoding;
  GeoReference geo;
  ElevationInfo elevation;  // present: write an elevation store (a height format)
  ShardInfo shard;          // present: write a partial store (the tiler's --shard)
  bool fsync = true;     // flush to disk before the final rename
  bool replace = false;  // a regular file at the path may be replaced (OutputFile's rule)
  PayloadOrder payload_order = PayloadOrder::kWritten;
};

// Encodes one tile: constant detection, predictor, compression, checksum.
// Pure and thread-safe: the tiler runs it on worker threads.
// `pixels` holds tileBytes() bytes in the geometry's format.
struct EncodedTile {
  TileKey key;
  TileLocation location;        // constant/checksum/stored_bytes filled; offset by writer
  std::vector<uint8_t> payload; // empty when constant
};
Status encodeTile(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                  const TileKey& key, std::span<const uint8_t> pixels, EncodedTile* out);

// Decodes a raw tile (checksum already verified) into `pixels`, which must
// hold exactly geometry.tileBytes() bytes. The inverse of encodeTile(); pure
// and thread-safe. kCorruptTile if the payload is not exactly one zstd frame
// (when compressed) or does not decode to exactly that size; never reads
// outside raw.payload.
Status decodeTile(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                  const RawTile& raw, std::span<uint8_t> pixels);

// decodeTile() straight to RGBA8: `rgba` must hold exactly tile_px^2 * 4
// bytes. R8/R16 become grey (R16 keeps the high byte), RGB8 gets A = 255.
// Same checks and errors as decodeTile(); the predictor inverse runs fused
// with the expansion (one pass, per-thread scratch, no allocation per tile
// once warm). Pure and thread-safe.
Status decodeTileRgba8(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                       const RawTile& raw, std::span<uint8_t> rgba);

// The height of one stored sample (`pixel`, bytesPerPixel(format) bytes) of
// an elevation store: offset + scale * value (R16, I16) or the value (F32).
double heightOfSample(PixelFormat format, const ElevationInfo& elevation, const uint8_t* pixel);

// decodeTile() straight to heights: `heights` must hold tile_px^2 floats.
// kUnsupported for a format that is not a height format. Pure and
// thread-safe.
Status decodeTileHeights(const PyramidGeometry& geometry, const StoreEncoding& encoding,
                         const ElevationInfo& elevation, const RawTile& raw,
                         std::span<float> heights);

// Writes a store atomically through an OutputFile (output_file.h): everything
// goes to a temporary file next to the final path, which appears (fsync +
// rename, replacing nothing it did not own) only in finish(). Destroying an
// unfinished writer, or a failed finish(), removes every temporary file.
//
// Thread-safe: write() and writeConstantTiles() may be called from several
// threads at once (payload bytes are written outside the writer's lock);
// create() and finish() from one thread, finish() after every write returned.
//
// Memory: 64 bytes per index page of the pyramid plus 16 bytes per tile of
// each index page that has begun but not finished (pages are flushed to a
// temporary file as soon as their last tile arrives); see docs/tile-store.md.
// With PayloadOrder::kCurve, finish() also holds 16 bytes per index page of
// one level and one page's entries at a time, and the disk holds a level's
// payloads twice while that level is copied into curve order.
class TileStoreWriter {
 public:
  // Fails (kIo / kNotFound / kInvalidArgument) if the directory of `path`
  // does not exist or is not writable, or the geometry is invalid;
  // kAlreadyExists / kInvalidArgument as OutputFile::create() for what is
  // already at `path`.
  static Status create(const std::string& path, const PyramidGeometry& geometry,
                       const WriterOptions& options, std::unique_ptr<TileStoreWriter>* out);
  ~TileStoreWriter();
  TileStoreWriter(const TileStoreWriter&) = delete;
  TileStoreWriter& operator=(const TileStoreWriter&) = delete;

  // Stores one encoded tile. Each tile of the pyramid must be written exactly
  // once, in any order. kInvalidArgument if the payload disagrees with its
  // location (size, checksum) or is too large (uncompressed: not exactly
  // tileBytes()); kNoSpace when the disk is full.
  Status write(EncodedTile&& tile);

  // Marks every tile in [x0, x1) x [y0, y1) of `level` as constant with
  // `pixel` (bytesPerPixel() bytes) without per-tile calls: index pages
  // entirely inside the rectangle become page-level constants costing no
  // per-tile memory or disk. Tiles in the rectangle must not have been
  // written. kInvalidArgument / kOutOfRange on bad arguments.
  Status writeConstantTiles(uint32_t level, uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1,
                            std::span<const uint8_t> pixel);

  // Elevation stores: the figures of the elevation record known only once
  // the input was read (samples filled, largest error, lowest and highest
  // height), written by finish(). kInvalidArgument for a colour store or
  // figures that are not finite and ordered.
  Status setElevationFigures(uint64_t filled_samples, double max_error, double min_height,
                             double max_height);

  // Writes the index and header, flushes and renames into place. Fails
  // (kInvalidArgument) if any tile is missing.
  Status finish();

  // Bytes written so far (payloads), for progress and summaries.
  uint64_t bytesWritten() const;
  uint64_t constantTiles() const;

  // Temporaries of an earlier, killed run for the same path that create()
  // removed (OutputFile::swept()), for the program to report.
  const std::vector<std::string>& sweptTemporaries() const;

 private:
  TileStoreWriter();
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

}  // namespace clipstream
