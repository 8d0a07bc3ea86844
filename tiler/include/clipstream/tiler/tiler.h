// Turns one image (a file OpenImageIO reads, or the procedural image) into
// a tile store holding its full mip pyramid, out of core: rows stream
// through in strips of one tile row and coarser levels are built as soon as
// the finer rows they need exist, so memory is bounded by the budget, not by
// the image. See docs/tiler.md for conversions, filters and the memory model.
//
// Thread rule: tileImage() may be called from any thread; it starts and
// joins its own reader and encoder threads before returning. Concurrent
// calls are independent (different outputs). TilerOptions::progress runs on
// the thread that called tileImage().
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>
#include <clipstream/tiler/image_source.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace clipstream {

// Smallest budget tileImage accepts, and the supported tile sizes.
constexpr uint64_t kMinMemoryBudgetBytes = uint64_t(16) << 20;
constexpr uint32_t kMinTilePx = 16;
constexpr uint32_t kMaxTilePx = 4096;
constexpr unsigned kMaxThreads = 1024;
// Largest --synthetic side: 2^32 px keeps every level's tile count in 32 bits.
constexpr uint64_t kMaxSyntheticSidePx = uint64_t(1) << 32;

// Whether the input is a picture or a height field (docs/terrain.md).
// kAuto: an elevation store for a single-band int16 input, and for a
// single-band uint16 or floating-point input that is georeferenced (a DEM);
// a colour store otherwise.
enum class LayerKind { kAuto, kColour, kElevation };

// Largest --relief-scale: 64 pixels per DEM sample already draws a 30 m DEM
// at half a metre a pixel, finer than the heights can show.
constexpr uint32_t kMaxReliefScale = 64;

// Largest quantisation step for heights (--height-step), in height units.
constexpr double kMaxHeightStep = 1000.0;

struct TilerOptions {
  LayerKind layer = LayerKind::kAuto;
  // Elevation stores only. height_step > 0 stores floating-point heights as
  // R16 steps of this size from the lowest height (error bound step / 2,
  // recorded in the store); 0 keeps them exactly (F32). Integer DEMs are
  // always stored exactly.
  double height_step = 0.0;
  std::optional<double> nodata;              // overrides the input's no-data tag
  std::optional<HeightUnits> vertical_units; // overrides the input's (else metres)
  std::string input_path;            // image file (a list file with mosaic); empty when synthetic
  // input_path is a mosaic list file (one image path a line) or a VRT of
  // simple sources, the sheets placed by their georeferences (mosaic.h).
  // DEM sheets make an elevation store whose gaps are no-data.
  bool mosaic = false;
  uint32_t fill = 0;                 // colour mosaic: gap value of every channel but alpha (alpha 0)
  uint64_t synthetic_width_px = 0;   // used when input_path is empty
  uint64_t synthetic_height_px = 0;
  std::optional<PixelFormat> format; // force the store's pixel format
  // Which decoder reads the input (image_source.h): the tiler's own for the
  // TIFF, JPEG and PNG files they cover, else OpenImageIO; or OpenImageIO
  // for every file. TIFF strips and tiles decode on `threads` threads.
  ImageReader reader = ImageReader::kAuto;
  // Reprojection by GDAL's warper (ImageReadOptions::target_crs and the
  // rest): not for mosaics (give a VRT of the sheets instead) or --synthetic.
  std::string target_crs;
  std::string resampling = "bilinear";
  double target_resolution = 0.0;
  std::string output_path;
  uint32_t tile_px = 128;            // power of two in [kMinTilePx, kMaxTilePx]
  int zstd_level = 1;
  bool predictor = true;
  DownsampleFilter filter = DownsampleFilter::kBox;
  bool linear_light = false;         // Lanczos only; sRGB -> linear -> filter -> sRGB
  unsigned threads = 0;              // encoder threads; 0 = all cores
  uint64_t memory_budget_bytes = uint64_t(256) << 20;  // bound on peak RSS
  bool overwrite = false;            // replace an existing output
  // Progress in level-0 pixels: progress(done_px, total_px), total_px =
  // width x height. Called on the thread that called tileImage(), never on a
  // worker: once with 0 when tiling starts (after the input is opened and the
  // memory plan made), then after each strip of one tile row. It should
  // return quickly (the pipeline waits for it) and not throw. Empty: none.
  std::function<void(uint64_t done_px, uint64_t total_px)> progress;
  bool fsync = true;
  // Where payloads lie in each level (WriterOptions::payload_order): along
  // a Hilbert curve by default, so that a store read over HTTP needs fewer
  // range requests (docs/benchmarks.md, "Payload order").
  PayloadOrder payload_order = PayloadOrder::kCurve;
  const std::atomic<int>* cancel = nullptr;  // non-zero (e.g. a signal number) stops the run
  // Sharded run (shard.h): tile only band shard_index (1..shard_count) of
  // the image into a partial store, for mergeShards(). 0 = the whole image.
  // Colour stores with the box filter only (Lanczos reaches across bands;
  // elevation fill and height bounds too).
  uint32_t shard_index = 0;
  uint32_t shard_count = 0;
  // Shaded relief (--relief, docs/tiler.md "Shaded relief"): > 0 makes a
  // colour store (RGB8) of the input DEM drawn as a hypsometric tint with a
  // hillshade, relief_scale pixels per DEM sample along each axis (1..64),
  // georeferenced like the DEM. 0: the input is tiled as it is.
  uint32_t relief_scale = 0;
};

// What a run did, for the one-line summary and --json-summary.
struct TilerSummary {
  uint64_t width_px = 0;
  uint64_t height_px = 0;
  PixelFormat format = PixelFormat::kRGB8;
  std::string input_type;        // "uint8", "synthetic", ...
  std::string decoder;           // SourceInfo::decoder: "libtiff", "openimageio", ...
  std::string reprojection;      // SourceInfo::reprojection: "" unless warped
  std::optional<double> transparent_nodata;  // a colour input's no-data value, made alpha 0
  uint32_t input_channels = 0;
  uint32_t levels = 0;
  uint64_t tiles = 0;
  uint64_t constant_tiles = 0;
  uint64_t input_bytes = 0;      // input file size (0 for synthetic)
  uint64_t raw_bytes = 0;        // level-0 pixels in the store's format
  uint64_t output_bytes = 0;     // final store file size
  uint64_t clamped_samples = 0;  // input samples clamped by the conversion
  uint64_t panel_px = 0;         // width of the vertical panels (== width when one)
  uint32_t panels = 1;           // number of panel columns
  uint64_t memory_budget_bytes = 0;
  uint64_t peak_rss_bytes = 0;   // VmHWM of this process at the end
  double wall_s = 0.0;
  double read_s = 0.0;           // reader thread CPU time (decode + convert)
  double build_s = 0.0;          // building thread CPU time (filter + tile copies)
  double encode_s = 0.0;         // encoder threads' CPU time, summed (encode + write)
  GeoReference geo;
  ElevationInfo elevation;       // present for an elevation store
  ShardInfo shard;               // present for a partial store (width/height are the band's)
  uint64_t mosaic_sheets = 0;    // sheets of a mosaic input (0: not a mosaic)
  uint64_t gap_px = 0;           // mosaic pixels no sheet covers, filled with TilerOptions::fill
  uint32_t relief_scale = 0;     // TilerOptions::relief_scale: a shaded relief of a DEM (0: none)
  std::vector<std::string> warnings;  // things the user should know (budget exceeded, ...)
};

// Tiles an image into a store at options.output_path. Never leaves a
// partial output or temporary file behind on failure or cancellation.
// Errors name the problem: kNotFound/kIo (input, output directory),
// kInvalidArgument (options, existing output without overwrite, a budget
// too small for the image), kUnsupported (pixel type), kTruncated (damaged
// input), kNoSpace (disk full), kOutOfMemory (an allocation failed),
// kCancelled.
Status tileImage(const TilerOptions& options, TilerSummary* summary);

// The checks tileImage() makes of the options alone (sizes, tile size,
// threads, zstd level, memory budget against this machine), without touching
// any file: kInvalidArgument naming the option. Programs call it first so
// that a mistake on the command line is told apart from a failed run.
Status validateOptions(const TilerOptions& options);

}  // namespace clipstream
