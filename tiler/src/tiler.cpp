// The tiling pipeline: a reader thread decodes strips of one tile row, the
// calling thread builds the pyramid from them, and encoder threads compress
// and store finished tiles. Queues between the stages are bounded, which is
// what bounds memory (see planLayout and docs/tiler.md).
#include <clipstream/tiler/tiler.h>

#include <clipstream/store/output_file.h>
#include <clipstream/store/process_memory.h>
#include <clipstream/tiler/downsample.h>
#include <clipstream/tiler/georef.h>
#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/mosaic.h>
#include <clipstream/tiler/shard.h>

#include "bounded_queue.h"
#include "height_bounds.h"
#include "height_source.h"
#include "relief_source.h"
#include "pyramid_builder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <optional>
#include <filesystem>
#include <mutex>
#include <system_error>
#include <thread>

#include <time.h>
#include <unistd.h>

namespace clipstream {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// Strip buffers that may exist at once: one being read, one queued, one
// being built from. Two would stall the reader while the builder works.
constexpr uint32_t kStripsInFlight = 3;
// Finished tiles waiting for an encoder, per encoder thread.
constexpr uint32_t kTileJobsPerThread = 4;
// Allowance for what the pipeline allocates besides strips and levels:
// OIIO's decode scratch (capped at 8 MiB in image_source.cpp), zstd
// contexts, the writer's index, allocator slack.
constexpr uint64_t kPipelineReserveBytes = uint64_t(16) << 20;
constexpr uint64_t kPerThreadReserveBytes = uint64_t(1) << 20;

double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// CPU time of the calling thread: stage costs that do not count time spent
// waiting on queues or preempted by other processes.
double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

// First error wins; later ones are usually consequences of it.
class ErrorSlot {
 public:
  void set(Status s) {
    std::lock_guard lock(m_mutex);
    if (m_status.ok()) m_status = std::move(s);
    m_failed.store(true, std::memory_order_release);
  }
  bool failed() const { return m_failed.load(std::memory_order_acquire); }
  Status get() {
    std::lock_guard lock(m_mutex);
    return m_status;
  }

 private:
  std::mutex m_mutex;  // guards m_status
  Status m_status;
  std::atomic<bool> m_failed{false};
};

struct StripItem {
  uint64_t bx = 0, by = 0;  // panel block
  uint64_t y0 = 0;          // first row, relative to the block
  uint32_t rows = 0;
  uint64_t width_px = 0;
  std::vector<uint8_t> pixels;
};

struct TileJob {
  TileKey key;
  std::vector<uint8_t> pixels;
  TileHeights heights;  // elevation stores
};

// How the image is cut: panels of panel_px columns (and rows), whose first
// `local_levels` levels are built per block; the rest by one coarse builder
// over the whole of level local_levels - 1.
struct PanelLayout {
  uint32_t local_levels = 1;
  uint64_t panel_px = 0;  // block size at level 0 (tile_px << (local_levels - 1))
  uint64_t blocks_x = 1, blocks_y = 1;
  uint64_t estimate_bytes = 0;
};

Status planLayout(const PyramidGeometry& g, const Downsampler& ds, unsigned threads,
                  uint64_t budget_bytes, uint64_t base_bytes, bool need_single, PanelLayout* out) {
  const uint32_t levels = g.levelCount();
  const uint64_t bpp = bytesPerPixel(g.format);
  const uint64_t jobs = uint64_t(threads) * kTileJobsPerThread * g.tileBytes() * 2;
  const uint64_t fixed = base_bytes + kPipelineReserveBytes + threads * kPerThreadReserveBytes + jobs;
  uint64_t smallest = UINT64_MAX;
  for (int32_t m = int32_t(levels) - 1; m >= 0; --m) {
    const uint64_t panel = uint64_t(g.tile_px) << m;
    const uint64_t block_w = std::min<uint64_t>(panel, g.width_px);
    uint64_t need = fixed;
    need += PyramidBuilder::bufferBytes(g, ds, block_w, uint32_t(m) + 1);
    need += kStripsInFlight * uint64_t(g.tile_px) * block_w * bpp;
    if (uint32_t(m) + 1 < levels) {
      const uint64_t wm = g.levels[size_t(m)].width_px;
      need += PyramidBuilder::bufferBytes(g, ds, wm, levels - uint32_t(m));
      need += uint64_t(g.tile_px) * wm * bpp;  // staging rows of level m
    }
    smallest = std::min(smallest, need);
    if (need <= budget_bytes) {
      if (need_single && uint32_t(m) + 1 < levels) break;
      out->local_levels = uint32_t(m) + 1;
      out->panel_px = panel;
      out->blocks_x = (g.width_px + panel - 1) / panel;
      out->blocks_y = (g.height_px + panel - 1) / panel;
      out->estimate_bytes = need;
      return okStatus();
    }
    if (need_single) break;
  }
  const uint64_t mb = uint64_t(1) << 20;
  if (need_single) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--memory-mb " + std::to_string(budget_bytes / mb) +
                             " is too small: the Lanczos filter needs full-width strips of " +
                             std::to_string(g.width_px) + " px, about " +
                             std::to_string((smallest + mb - 1) / mb) + " MB in all");
  }
  return Status::error(ErrorCode::kInvalidArgument,
                       "--memory-mb " + std::to_string(budget_bytes / mb) +
                           " is too small for a " + std::to_string(g.width_px) + "x" +
                           std::to_string(g.height_px) + " " + pixelFormatName(g.format) +
                           " image with " + std::to_string(threads) + " threads: needs about " +
                           std::to_string((smallest + mb - 1) / mb) + " MB");
}

// Rows [y0, y0 + height) of another source, as an image of their own: the
// band a shard tiles. Its pixels are the full image's, converted the same.
class BandSource final : public ImageSource {
 public:
  BandSource(std::unique_ptr<ImageSource> inner, uint64_t y0_px, uint64_t height_px)
      : m_inner(std::move(inner)), m_y0(y0_px), m_info(m_inner->info()) {
    m_info.height_px = height_px;
  }
  const SourceInfo& info() const override {
    m_info.clamped_samples = m_inner->info().clamped_samples;
    return m_info;
  }
  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    return m_inner->readRows(m_y0 + y0, rows, x0, width, dst, dst_stride);
  }

 private:
  std::unique_ptr<ImageSource> m_inner;
  uint64_t m_y0 = 0;
  mutable SourceInfo m_info;  // the inner one's, with the band's height
};

// FNV-1a, 64 bit: the run fingerprint must be the same on every machine and
// build that runs a shard, which std::hash does not promise.
struct Fnv1a {
  uint64_t h = 0xcbf29ce484222325ull;
  void bytes(const void* data, size_t n) {
    const auto* p = static_cast<const uint8_t*>(data);
    for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
  }
  void u64(uint64_t v) { bytes(&v, sizeof(v)); }
  void text(const std::string& t) {
    u64(t.size());
    bytes(t.data(), t.size());
  }
};

// Up to 64 KiB from the start and the end of a file, and its size: enough
// to tell inputs apart without reading them whole in every shard. The path
// is left out on purpose: shards may see the input under different mounts.
Status hashFileSample(const std::string& path, Fnv1a* h) {
  constexpr size_t kSampleBytes = size_t(64) << 10;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return Status::error(ErrorCode::kIo, path + ": cannot open to fingerprint it");
  std::vector<uint8_t> buf(kSampleBytes);
  std::fseek(f, 0, SEEK_END);
  const long size = std::ftell(f);
  h->u64(uint64_t(size < 0 ? 0 : size));
  for (long at : {0L, std::max(0L, size - long(kSampleBytes))}) {
    std::fseek(f, at, SEEK_SET);
    const size_t n = std::fread(buf.data(), 1, buf.size(), f);
    h->bytes(buf.data(), n);
  }
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) return Status::error(ErrorCode::kIo, path + ": read failed while fingerprinting it");
  return okStatus();
}

// What a shard's tiles depend on: the input (sampled, above), its size and
// georeference, and every option that changes a tile's bytes. Equal across
// the shards of one run, and checked by the merge.
Status runFingerprint(const TilerOptions& o, const SourceInfo& src, const GeoReference& geo,
                      const std::vector<std::string>& sheets, uint64_t* out) {
  Fnv1a h;
  h.text("clipstream shard run 1");
  if (o.input_path.empty()) {
    h.text("synthetic");
  } else {
    Status s = hashFileSample(o.input_path, &h);
    if (!s) return s;
  }
  h.u64(o.mosaic ? 1 : 0);
  h.u64(o.fill);
  for (const std::string& sheet : sheets) {
    Status s = hashFileSample(sheet, &h);
    if (!s) return s;
  }
  h.u64(src.width_px);
  h.u64(src.height_px);
  h.text(src.input_type);
  h.u64(src.input_channels);
  h.u64(uint64_t(src.format));
  h.u64(o.tile_px);
  h.u64(uint64_t(o.zstd_level));
  h.u64(o.predictor ? 1 : 0);
  h.u64(uint64_t(o.filter));
  h.u64(o.linear_light ? 1 : 0);
  h.u64(geo.present ? 1 : 0);
  h.bytes(geo.transform, sizeof(geo.transform));
  h.text(geo.crs);
  h.u64(o.shard_count);
  *out = h.h;
  return okStatus();
}

}  // namespace

Status validateOptions(const TilerOptions& o) {
  if (o.tile_px < kMinTilePx || o.tile_px > kMaxTilePx || (o.tile_px & (o.tile_px - 1)) != 0) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "tile size " + std::to_string(o.tile_px) + " must be a power of two from " +
                             std::to_string(kMinTilePx) + " to " + std::to_string(kMaxTilePx));
  }
  if (o.threads > kMaxThreads) {
    return Status::error(ErrorCode::kInvalidArgument, "--threads " + std::to_string(o.threads) +
                                                          " is more than the maximum of " +
                                                          std::to_string(kMaxThreads));
  }
  if (o.zstd_level < 1 || o.zstd_level > 22) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--zstd-level " + std::to_string(o.zstd_level) + " must be 1..22");
  }
  if (o.memory_budget_bytes < kMinMemoryBudgetBytes) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--memory-mb must be at least " + std::to_string(kMinMemoryBudgetBytes >> 20));
  }
  const uint64_t physical = uint64_t(sysconf(_SC_PHYS_PAGES)) * uint64_t(sysconf(_SC_PAGE_SIZE));
  if (physical > 0 && o.memory_budget_bytes > physical) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--memory-mb " + std::to_string(o.memory_budget_bytes >> 20) +
                             " is more than this machine's " + std::to_string(physical >> 20) +
                             " MB of memory");
  }
  if (o.relief_scale > 0) {
    if (o.relief_scale > kMaxReliefScale) {
      return Status::error(ErrorCode::kInvalidArgument, "--relief-scale " + std::to_string(o.relief_scale) +
                                                            " must be from 1 to " +
                                                            std::to_string(kMaxReliefScale));
    }
    const char* conflict = o.input_path.empty()         ? "--synthetic"
                           : o.layer != LayerKind::kAuto ? "--layer"
                           : o.format                    ? "--format"
                           : o.height_step > 0.0         ? "--height-step"
                           : o.shard_count != 0          ? "--shard"
                                                         : nullptr;
    if (conflict != nullptr) {
      return Status::error(ErrorCode::kInvalidArgument,
                           std::string("--relief draws a DEM as an RGB8 picture; it does not go "
                                       "with ") + conflict);
    }
  }
  if (o.input_path.empty() && (o.synthetic_width_px == 0 || o.synthetic_height_px == 0)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "synthetic image size " + std::to_string(o.synthetic_width_px) + "x" +
                             std::to_string(o.synthetic_height_px) + " is empty");
  }
  if (o.input_path.empty() &&
      (o.synthetic_width_px > kMaxSyntheticSidePx || o.synthetic_height_px > kMaxSyntheticSidePx)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "synthetic image size " + std::to_string(o.synthetic_width_px) + "x" +
                             std::to_string(o.synthetic_height_px) + " is larger than " +
                             std::to_string(kMaxSyntheticSidePx) + " px on a side");
  }
  if (o.output_path.empty()) return Status::error(ErrorCode::kInvalidArgument, "no output path");
  if (o.linear_light && o.filter != DownsampleFilter::kLanczos3) {
    return Status::error(ErrorCode::kInvalidArgument, "--linear-light needs --filter lanczos3");
  }
  if (o.filter == DownsampleFilter::kDecimate) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "the decimate filter is chosen by the tiler for elevation stores only");
  }
  if (!std::isfinite(o.height_step) || o.height_step < 0.0 || o.height_step > kMaxHeightStep) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--height-step " + std::to_string(o.height_step) + " must be in (0, " +
                             std::to_string(int(kMaxHeightStep)) + "]");
  }
  if (o.height_step > 0.0 && o.layer == LayerKind::kColour) {
    return Status::error(ErrorCode::kInvalidArgument, "--height-step applies to elevation stores");
  }
  if (o.nodata && std::isinf(*o.nodata)) {
    return Status::error(ErrorCode::kInvalidArgument, "--nodata must be a finite number or nan");
  }
  if (o.input_path.empty() &&
      (o.layer == LayerKind::kElevation || (o.format && !isColourFormat(*o.format)))) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--synthetic makes colour images; elevation needs an input DEM");
  }
  if (o.mosaic && o.input_path.empty()) {
    return Status::error(ErrorCode::kInvalidArgument, "a mosaic needs a list file of sheets");
  }
  if (o.fill > 65535) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--fill " + std::to_string(o.fill) + " must be 0..65535");
  }
  if (o.shard_count != 0 || o.shard_index != 0) {
    if (o.shard_count == 0 || o.shard_count > kMaxShards || o.shard_index == 0 ||
        o.shard_index > o.shard_count) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "--shard " + std::to_string(o.shard_index) + "/" +
                               std::to_string(o.shard_count) + " needs 1 <= K <= N <= " +
                               std::to_string(kMaxShards));
    }
    if (o.filter != DownsampleFilter::kBox) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "--shard needs the box filter: Lanczos reaches across the bands");
    }
    if (o.layer == LayerKind::kElevation || (o.format && !isColourFormat(*o.format))) {
      return Status::error(ErrorCode::kUnsupported, "--shard: elevation stores are not sharded");
    }
  }
  if (o.format && o.layer == LayerKind::kColour && !isColourFormat(*o.format)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         std::string("--format ") + pixelFormatName(*o.format) +
                             " holds heights, not colour");
  }
  return okStatus();
}

namespace {

// The output rule of OutputFile (only regular files replaced, and only with
// overwrite), checked before any work; the writer checks again at the end.
// An output that is the input itself (also through a link) is refused even
// with overwrite: replacing it would destroy the input.
Status checkOutput(const TilerOptions& o) {
  if (!o.input_path.empty() && sameFile(o.input_path, o.output_path)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         o.output_path + " is the input file " + o.input_path +
                             " (the same file, maybe through a link); refusing to overwrite it");
  }
  OutputOptions options;
  options.existing = o.overwrite ? ExistingOutput::kReplaceRegular : ExistingOutput::kRefuse;
  Status s = checkOutputPath(o.output_path, options);
  if (s.code == ErrorCode::kAlreadyExists) {
    s.message = o.output_path + " (use --force to overwrite)";
  }
  return s;
}

}  // namespace

namespace {

// Decides whether an opened input becomes an elevation store (LayerKind)
// and, if so, reopens it delivering native height samples behind a
// HeightSource (no-data fill, quantisation). *heights points into *source.
// Opens the input again delivering native samples in `native`; `conversion`
// says the no-data value (a mosaic fills its gaps with it).
using ReopenHeights = std::function<Status(PixelFormat native, const HeightConversion& conversion,
                                           std::unique_ptr<ImageSource>* out)>;

Status openElevation(const TilerOptions& o, const GeoReference& geo, const std::string& tags_path,
                     const ReopenHeights& reopen_input, std::unique_ptr<ImageSource>* source,
                     HeightSource** heights, ElevationInfo* elevation, TilerSummary* summary) {
  const SourceInfo& first = (*source)->info();
  const std::string& type = first.input_type;
  const bool int16 = type == "int16", uint16 = type == "uint16";
  const bool floating = type == "float" || type == "half" || type == "double";
  const bool forced_height = o.format && !isColourFormat(*o.format);
  bool wanted = false;
  switch (o.layer) {
    case LayerKind::kColour: wanted = false; break;
    case LayerKind::kElevation: wanted = true; break;
    case LayerKind::kAuto:
      wanted = forced_height ||
               (!o.format && first.input_channels == 1 &&
                (int16 || ((uint16 || floating) && geo.present)));
      break;
  }
  if (!wanted) {
    if (o.height_step > 0.0) {
      return Status::error(ErrorCode::kInvalidArgument,
                           o.input_path + ": --height-step applies to elevation stores, and this "
                                          "input is tiled as colour (use --layer elevation)");
    }
    return okStatus();
  }
  if (first.input_channels != 1) {
    return Status::error(ErrorCode::kUnsupported,
                         o.input_path + ": " + std::to_string(first.input_channels) +
                             " channels; an elevation store needs a single-band DEM");
  }
  // R16 is both a grey colour format and a height format: in an elevation
  // store it means quantised or unsigned 16-bit heights.
  const bool height_format = o.format && (*o.format == PixelFormat::kI16 || *o.format == PixelFormat::kR16 ||
                                          *o.format == PixelFormat::kF32);
  if (o.format && !height_format) {
    return Status::error(ErrorCode::kInvalidArgument,
                         std::string("--format ") + pixelFormatName(*o.format) +
                             " is a colour format; elevation stores hold I16, R16 or F32");
  }
  if (o.filter != DownsampleFilter::kBox || o.linear_light) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--filter and --linear-light are for colour: heights are decimated "
                         "(every other sample), never filtered like colour");
  }
  const PixelFormat native = int16 ? PixelFormat::kI16 : uint16 ? PixelFormat::kR16 : PixelFormat::kF32;
  const bool integer = int16 || uint16 || type == "uint8";
  if (integer && o.height_step > 0.0) {
    return Status::error(ErrorCode::kInvalidArgument,
                         o.input_path + ": integer heights (" + type +
                             ") are stored exactly; --height-step is for floating-point DEMs");
  }
  PixelFormat stored = o.height_step > 0.0 ? PixelFormat::kR16 : native;
  if (height_format) {
    const bool widen = *o.format == PixelFormat::kF32;
    if (*o.format != stored && !widen) {
      return Status::error(ErrorCode::kInvalidArgument,
                           std::string("--format ") + pixelFormatName(*o.format) + " cannot hold " +
                               type + " heights " +
                               (o.height_step > 0.0 ? "quantised (R16 does)"
                                : stored == PixelFormat::kF32
                                    ? "exactly (use F32)"
                                    : "exactly (use " + std::string(pixelFormatName(stored)) + " or F32)"));
    }
    stored = *o.format;
  }
  // A no-data value no sample of an integer DEM can hold (NaN included)
  // would turn no-data off without a word.
  if (integer && o.nodata) {
    const double lo = int16 ? -32768.0 : 0.0, hi = int16 ? 32767.0 : uint16 ? 65535.0 : 255.0;
    if (*o.nodata < lo || *o.nodata > hi || *o.nodata != std::floor(*o.nodata)) {
      char text[160];
      std::snprintf(text, sizeof text, "--nodata %.9g: no %s sample can hold it (whole numbers %.0f to %.0f)",
                    *o.nodata, type.c_str(), lo, hi);
      return Status::error(ErrorCode::kInvalidArgument, o.input_path + ": " + text);
    }
  }
  ElevationTags tags;
  Status s = readElevationTags(tags_path, &tags);
  if (!s) return s;
  HeightConversion conversion;
  conversion.stored = stored;
  conversion.has_nodata = o.nodata.has_value() || tags.has_nodata;
  conversion.nodata = o.nodata.value_or(tags.nodata);

  // The reader for native samples (the file is opened again: cheap, and
  // it starts from the top).
  const PixelFormat native_format = stored == PixelFormat::kF32 || o.height_step > 0.0
                                        ? PixelFormat::kF32
                                        : native;
  auto reopen = [&]() {
    source->reset();
    return reopen_input(native_format, conversion, source);
  };
  s = reopen();
  if (!s) return s;
  if (o.height_step > 0.0) {
    double lo = 0.0, hi = 0.0;
    s = scanHeightRange(source->get(), conversion, &lo, &hi);
    if (!s) return Status::error(s.code, o.input_path + ": " + s.message);
    conversion.scale = o.height_step;
    conversion.offset = std::floor(lo / o.height_step) * o.height_step;
    if ((hi - conversion.offset) / o.height_step > 65535.0) {
      return Status::error(ErrorCode::kInvalidArgument,
                           o.input_path + ": heights " + std::to_string(lo) + " to " +
                               std::to_string(hi) + " need more than 65536 steps of " +
                               std::to_string(o.height_step) + "; use --height-step " +
                               std::to_string((hi - conversion.offset) / 65535.0) +
                               " or more, or store them exactly");
    }
    s = reopen();
    if (!s) return s;
  }
  auto wrapped = std::make_unique<HeightSource>(std::move(*source), conversion);
  *heights = wrapped.get();
  *source = std::move(wrapped);

  *elevation = ElevationInfo{};
  elevation->present = true;
  elevation->scale = conversion.scale;
  elevation->quantised = o.height_step > 0.0;
  elevation->offset = conversion.offset;
  elevation->has_nodata = conversion.has_nodata;
  elevation->nodata = conversion.nodata;
  if (o.vertical_units) {
    elevation->units = *o.vertical_units;
    elevation->units_assumed = false;
  } else if (tags.units) {
    elevation->units = *tags.units;
    elevation->units_assumed = false;
  } else {
    elevation->units = HeightUnits::kMetre;
    elevation->units_assumed = true;
  }
  if (!geo.present) {
    summary->warnings.push_back(o.input_path +
                                ": the DEM has no georeference; a scene will stretch it over the "
                                "colour layer's extent");
  }
  return okStatus();
}

// Replaces the source of heights by the shaded relief drawn from them
// (relief_source.h): a colour store, georeferenced like the DEM with pixels
// relief_scale times smaller.
Status makeRelief(const TilerOptions& o, GeoReference* geo, std::unique_ptr<ImageSource>* source,
                  ElevationInfo* elevation) {
  const SourceInfo& dem = (*source)->info();
  ReliefOptions relief;
  relief.scale = o.relief_scale;
  relief.metres_per_height = metresPerUnit(elevation->units);
  if (geo->present) {
    const double* t = geo->transform;
    const double latitude = t[3] + t[5] * double(dem.height_px) * 0.5;
    const CrsUnitMetres unit = metresPerCrsUnit(geo->crs, latitude);
    relief.sample_x_metres = std::hypot(t[1], t[4]) * unit.x;
    relief.sample_y_metres = std::hypot(t[2], t[5]) * unit.y;
    // A CRS unit not known here is taken as a metre (unit.assumed).
    for (int i : {1, 2, 4, 5}) geo->transform[i] /= double(o.relief_scale);
  }
  if (!(relief.sample_x_metres > 0.0) || !(relief.sample_y_metres > 0.0)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         o.input_path + ": the georeference gives samples no size; cannot shade it");
  }
  std::unique_ptr<ImageSource> shaded;
  Status s = ReliefSource::open(std::move(*source), relief, &shaded);
  if (!s) return Status::error(s.code, o.input_path + ": " + s.message);
  *source = std::move(shaded);
  *elevation = ElevationInfo{};
  return okStatus();
}

Status tileImageImpl(const TilerOptions& o, TilerSummary* summary) {
  const auto start = Clock::now();
  *summary = TilerSummary{};
  Status s = validateOptions(o);
  if (!s) return s;
  s = checkOutput(o);
  if (!s) return s;

  std::unique_ptr<ImageSource> source;
  GeoReference geo;
  MosaicInfo mosaic;
  ImageReadOptions read;
  read.reader = o.reader;
  read.decode_threads = o.threads;
  read.memory_budget_bytes = o.memory_budget_bytes;
  if (o.input_path.empty()) {
    s = makeSyntheticSource(o.synthetic_width_px, o.synthetic_height_px,
                            o.format.value_or(PixelFormat::kRGB8), &source);
  } else if (o.mosaic) {
    // As for one file: a height format is the elevation path's to choose.
    const bool height_format = o.format && !isColourFormat(*o.format);
    s = openMosaic(o.input_path, height_format ? std::nullopt : o.format, o.fill, &source, &mosaic,
                   read);
    if (s) geo = mosaic.geo;
    for (const std::string& sheet : mosaic.sheets) {
      if (s && sameFile(sheet, o.output_path)) {
        s = Status::error(ErrorCode::kInvalidArgument,
                          o.output_path + " is the mosaic's sheet " + sheet +
                              " (the same file, maybe through a link); refusing to overwrite it");
      }
    }
  } else {
    // A height format asked for by --format is the elevation path's to
    // choose; the first open only looks at the input.
    const bool height_format = o.format && !isColourFormat(*o.format);
    s = openImageFile(o.input_path, height_format ? std::nullopt : o.format, &source, read);
    if (s) s = findGeoReference(o.input_path, &geo);
  }
  if (!s) return s;
  HeightSource* heights = nullptr;
  ElevationInfo elevation;
  // A relief is drawn from the input's heights: read them as for an
  // elevation store, exactly (F32), before shading.
  TilerOptions elevation_options = o;
  if (o.relief_scale > 0) {
    elevation_options.layer = LayerKind::kElevation;
    elevation_options.format = PixelFormat::kF32;
    elevation_options.filter = DownsampleFilter::kBox;
    elevation_options.linear_light = false;
  }
  if (o.mosaic) {
    // DEM sheets: gaps hold the no-data value (NaN for float samples when
    // the sheets declare none), so they are filled like any void.
    const uint64_t gap_px = mosaic.gap_px;
    auto reopen = [&](PixelFormat native, const HeightConversion& conversion,
                      std::unique_ptr<ImageSource>* out) {
      double gap = conversion.has_nodata ? conversion.nodata : std::nan("");
      if (!conversion.has_nodata && native != PixelFormat::kF32) {
        if (gap_px > 0) {
          return Status::error(ErrorCode::kInvalidArgument,
                               o.input_path + ": the sheets leave " + std::to_string(gap_px) +
                                   " px uncovered and declare no no-data value to fill them "
                                   "with; give --nodata");
        }
        gap = 0.0;  // never read: no gaps
      }
      MosaicInfo again;
      return openHeightMosaic(o.input_path, native, gap, out, &again, read);
    };
    s = openElevation(elevation_options, geo, mosaic.sheets.front(), reopen, &source, &heights,
                      &elevation, summary);
    if (!s) return s;
  } else if (!o.input_path.empty()) {
    auto reopen = [&](PixelFormat native, const HeightConversion&, std::unique_ptr<ImageSource>* out) {
      return openImageFile(o.input_path, native, out, read);
    };
    s = openElevation(elevation_options, geo, o.input_path, reopen, &source, &heights, &elevation,
                      summary);
    if (!s) return s;
  }
  if (o.relief_scale > 0) {
    s = makeRelief(o, &geo, &source, &elevation);
    if (!s) return s;
    heights = nullptr;  // a colour store: no height statistics
    summary->relief_scale = o.relief_scale;
  }
  ShardInfo shard;
  if (o.shard_count != 0) {
    if (elevation.present) {
      return Status::error(ErrorCode::kUnsupported,
                           o.input_path + " becomes an elevation store, and elevation stores are "
                                          "not sharded (use --layer colour for a picture of it)");
    }
    const SourceInfo& whole = source->info();
    ShardPlan plan;
    s = planShard(whole.width_px, whole.height_px, o.tile_px, o.shard_index, o.shard_count, &plan);
    if (!s) return s;
    shard.present = true;
    shard.index = o.shard_index;
    shard.count = o.shard_count;
    shard.full_width_px = whole.width_px;
    shard.full_height_px = whole.height_px;
    shard.y0_px = plan.y0_px;
    shard.owned_levels = plan.owned_levels;
    s = runFingerprint(o, whole, geo, mosaic.sheets, &shard.fingerprint);
    if (!s) return s;
    source = std::make_unique<BandSource>(std::move(source), plan.y0_px, plan.height_px);
  }
  const SourceInfo& src = source->info();
  for (const std::string& w : src.warnings) summary->warnings.push_back(w);

  WriterOptions wopt;
  wopt.elevation = elevation;
  wopt.encoding.compression = Compression::kZstd;
  wopt.encoding.zstd_level = o.zstd_level;
  wopt.encoding.predictor = o.predictor ? Predictor::kLeftDelta : Predictor::kNone;
  wopt.encoding.filter = elevation.present ? DownsampleFilter::kDecimate : o.filter;
  wopt.encoding.linear_light = o.linear_light;
  wopt.fsync = o.fsync;
  wopt.replace = o.overwrite;
  wopt.payload_order = o.payload_order;
  wopt.geo = geo;  // a shard's is the whole image's (ShardInfo)
  wopt.shard = shard;

  PyramidGeometry geometry;
  if (!makePyramidGeometry(src.width_px, src.height_px, o.tile_px, src.format, &geometry)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "cannot make a pyramid for " + std::to_string(src.width_px) + "x" +
                             std::to_string(src.height_px) + " with tile size " +
                             std::to_string(o.tile_px));
  }
  const Downsampler downsampler(wopt.encoding.filter, o.linear_light, src.format);
  const unsigned threads =
      o.threads != 0 ? o.threads : std::max(1u, std::thread::hardware_concurrency());

  PanelLayout layout;
  const uint64_t base_bytes = currentRssBytes();
  // Box and decimate read only the 2x2 samples under each output sample, so
  // levels can be built per panel; Lanczos reaches across panel borders.
  const bool need_single = wopt.encoding.filter == DownsampleFilter::kLanczos3;
  s = planLayout(geometry, downsampler, threads, o.memory_budget_bytes, base_bytes, need_single,
                 &layout);
  if (!s && base_bytes > o.memory_budget_bytes / 2) {
    // Most of the budget is gone before the first row: the libraries and the
    // decoder's own state (a progressive JPEG keeps every DCT coefficient, 2
    // bytes per sample). Nothing the tiler does can undo that, so plan our
    // part within half the budget on top of it, and say so.
    Status retry = planLayout(geometry, downsampler, threads,
                              base_bytes + o.memory_budget_bytes / 2, base_bytes, need_single,
                              &layout);
    if (retry) {
      s = retry;
      summary->warnings.push_back(
          std::to_string(base_bytes >> 20) +
          " MB are resident before tiling starts (image libraries and decoder state; a "
          "progressive JPEG keeps all its coefficients); "
          "peak memory will exceed --memory-mb " + std::to_string(o.memory_budget_bytes >> 20));
    }
  }
  if (!s) return s;

  std::unique_ptr<TileStoreWriter> writer;
  s = TileStoreWriter::create(o.output_path, geometry, wopt, &writer);
  if (s) {
    for (const std::string& swept : writer->sweptTemporaries()) {
      summary->warnings.push_back("removed a temporary file left by an interrupted earlier run: " + swept);
    }
  }
  if (!s) return s;

  // ---- pipeline ----
  const uint32_t tile = geometry.tile_px;
  const uint32_t bpp = bytesPerPixel(geometry.format);
  const uint32_t levels = geometry.levelCount();
  const uint32_t m = layout.local_levels - 1;
  ErrorSlot error;
  BoundedQueue<StripItem> filled(kStripsInFlight - 1);
  BoundedQueue<std::vector<uint8_t>> free_buffers(kStripsInFlight);
  BoundedQueue<TileJob> jobs(size_t(threads) * kTileJobsPerThread);
  for (uint32_t i = 0; i < kStripsInFlight; ++i) {
    std::vector<uint8_t> buffer;
    (void)free_buffers.push(std::move(buffer));
  }
  std::atomic<uint64_t> tiles_done{0};
  // Tile buffers go back here after encoding, so steady state allocates
  // (and zero-fills) nothing per tile. Bounded by the job queue's size.
  std::mutex recycled_mutex;  // guards recycled
  std::vector<std::vector<uint8_t>> recycled;
  auto takeBuffer = [&]() -> std::vector<uint8_t> {
    std::lock_guard lock(recycled_mutex);
    if (recycled.empty()) return {};
    std::vector<uint8_t> b = std::move(recycled.back());
    recycled.pop_back();
    return b;
  };
  double read_s = 0.0;
  std::mutex encode_time_mutex;  // guards encode_s
  double encode_s = 0.0;
  auto cancelled = [&] { return o.cancel != nullptr && o.cancel->load(std::memory_order_relaxed) != 0; };
  auto abortAll = [&] {
    filled.abort();
    free_buffers.abort();
    jobs.abort();
  };

  // A refused thread (the system's thread or memory limit) fails the run
  // like any other resource: reported, temporaries removed.
  auto threadRefused = [](const char* which, const std::system_error& e) {
    return Status::error(ErrorCode::kIo, std::string("cannot start the ") + which + " thread: " + e.what());
  };
  std::thread reader;
  try {
    reader = std::thread([&] {
    try {
    const double cpu0 = threadCpuSeconds();
    for (uint64_t by = 0; by < layout.blocks_y && !error.failed(); ++by) {
      const uint64_t y_origin = by * layout.panel_px;
      const uint64_t block_h = std::min(layout.panel_px, src.height_px - y_origin);
      for (uint64_t bx = 0; bx < layout.blocks_x && !error.failed(); ++bx) {
        const uint64_t x_origin = bx * layout.panel_px;
        const uint64_t block_w = std::min(layout.panel_px, src.width_px - x_origin);
        for (uint64_t y = 0; y < block_h; y += tile) {
          if (error.failed()) break;
          if (cancelled()) {
            error.set(Status::error(ErrorCode::kCancelled, "interrupted"));
            abortAll();
            break;
          }
          StripItem item;
          if (!free_buffers.pop(&item.pixels)) break;
          item.bx = bx, item.by = by, item.y0 = y, item.width_px = block_w;
          item.rows = uint32_t(std::min<uint64_t>(tile, block_h - y));
          item.pixels.resize(size_t(item.rows) * block_w * bpp);
          Status rs = source->readRows(y_origin + y, item.rows, x_origin, block_w,
                                       item.pixels.data(), size_t(block_w) * bpp);
          if (!rs) {
            error.set(std::move(rs));
            abortAll();
            break;
          }
          if (!filled.push(std::move(item))) break;
        }
      }
    }
    read_s = threadCpuSeconds() - cpu0;
    } catch (const std::bad_alloc&) {
      error.set(Status::error(ErrorCode::kOutOfMemory, "an allocation failed while reading the input"));
      abortAll();
    }
    filled.close();
    });
  } catch (const std::system_error& e) {
    writer.reset();  // removes the temporary file
    return threadRefused("reader", e);
  }

  std::vector<std::thread> encoders;
  for (unsigned t = 0; t < threads; ++t) {
    try {
    encoders.emplace_back([&] {
      const double cpu0 = threadCpuSeconds();
      TileJob job;
      EncodedTile encoded;
      while (jobs.pop(&job)) {
        Status es;
        try {
          es = encodeTile(geometry, wopt.encoding, job.key, job.pixels, &encoded);
          encoded.location.min_height = job.heights.min_height;
          encoded.location.max_height = job.heights.max_height;
          encoded.location.error = job.heights.error;
          if (es) es = writer->write(std::move(encoded));
        } catch (const std::bad_alloc&) {
          es = Status::error(ErrorCode::kOutOfMemory, "an allocation failed while encoding tiles");
        }
        {
          std::lock_guard lock(recycled_mutex);
          if (recycled.size() < size_t(threads) * (kTileJobsPerThread + 2)) {
            recycled.push_back(std::move(job.pixels));
          }
        }
        if (!es) {
          error.set(std::move(es));
          abortAll();
          break;
        }
        tiles_done.fetch_add(1, std::memory_order_relaxed);
      }
      std::lock_guard lock(encode_time_mutex);
      encode_s += threadCpuSeconds() - cpu0;
    });
    } catch (const std::system_error& e) {
      error.set(threadRefused("encoder", e));
      abortAll();
      break;
    }
  }

  const uint64_t total_px = src.width_px * src.height_px;
  uint64_t done_px = 0;
  const double build_cpu0 = threadCpuSeconds();
  try {
    if (o.progress) o.progress(0, total_px);
    std::optional<HeightBoundsTracker> bounds;
    if (elevation.present) bounds.emplace(geometry, elevation);
    auto tile_sink = [&](const TileKey& key, std::vector<uint8_t>&& pixels) {
      TileHeights tile_heights;
      if (bounds) {
        tile_heights = bounds->add(key, pixels);
        if (key.level + 1 == levels) {
          elevation.min_height = tile_heights.min_height;
          elevation.max_height = tile_heights.max_height;
        }
      }
      if (!jobs.push(TileJob{key, std::move(pixels), tile_heights}) && !error.failed()) {
        error.set(Status::error(ErrorCode::kCancelled, "encoder queue closed"));
      }
    };
    // Coarse builder over level m, fed from the per-block builders' level-m
    // rows through a staging strip one tile row high.
    std::unique_ptr<PyramidBuilder> coarse;
    std::vector<uint8_t> staging;
    uint64_t staging_rows = 0;
    const uint64_t wm = geometry.levels[m].width_px;
    if (m + 1 < levels) {
      RegionSpec cr;
      cr.first_level = m;
      cr.last_level = levels - 1;
      cr.emit_first = false;
      coarse = std::make_unique<PyramidBuilder>(geometry, downsampler, cr, tile_sink,
                                                PyramidBuilder::RowSink{}, takeBuffer);
      staging.resize(size_t(tile) * wm * bpp);
    }
    std::unique_ptr<PyramidBuilder> local;
    uint64_t cur_bx = UINT64_MAX, cur_by = UINT64_MAX;
    StripItem item;
    while (filled.pop(&item)) {
      if (error.failed()) break;
      if (cancelled()) {
        error.set(Status::error(ErrorCode::kCancelled, "interrupted"));
        break;
      }
      if (item.bx != cur_bx || item.by != cur_by) {
        cur_bx = item.bx, cur_by = item.by;
        RegionSpec rs;
        rs.first_level = 0;
        rs.last_level = m;
        rs.x0_px = item.bx * layout.panel_px;
        rs.y0_px = item.by * layout.panel_px;
        rs.width_px = item.width_px;
        rs.height_px = std::min(layout.panel_px, src.height_px - rs.y0_px);
        PyramidBuilder::RowSink row_sink;
        if (coarse) {
          const uint64_t col = item.bx * tile;  // block origin at level m
          row_sink = [&, col](uint64_t row, const uint8_t* px, uint64_t w) {
            std::memcpy(staging.data() + (row * wm + col) * bpp, px, size_t(w) * bpp);
            staging_rows = std::max(staging_rows, row + 1);
          };
        }
        local = std::make_unique<PyramidBuilder>(geometry, downsampler, rs, tile_sink, row_sink,
                                                 takeBuffer);
      }
      local->appendRows(item.pixels.data(), size_t(item.width_px) * bpp, item.rows);
      if (coarse && local->complete() && item.bx + 1 == layout.blocks_x) {
        coarse->appendRows(staging.data(), size_t(wm) * bpp, staging_rows);
        staging_rows = 0;
      }
      done_px += uint64_t(item.rows) * item.width_px;
      if (o.progress) o.progress(done_px, total_px);
      if (!free_buffers.push(std::move(item.pixels))) break;
    }
  } catch (const std::bad_alloc&) {
    error.set(Status::error(ErrorCode::kOutOfMemory, "an allocation failed while building levels"));
  }
  if (error.failed() || cancelled()) {
    if (!error.failed()) error.set(Status::error(ErrorCode::kCancelled, "interrupted"));
    abortAll();
  } else {
    jobs.close();
  }
  const double build_s = threadCpuSeconds() - build_cpu0;
  reader.join();
  for (std::thread& t : encoders) t.join();

  if (error.failed()) {
    writer.reset();  // removes the temporary file
    return error.get();
  }
  summary->constant_tiles = writer->constantTiles();
  if (heights != nullptr) {
    elevation.filled_samples = heights->filledSamples();
    elevation.max_error = heights->maxError();
    s = writer->setElevationFigures(elevation.filled_samples, elevation.max_error,
                                    elevation.min_height, elevation.max_height);
    if (s) s = writer->finish();
    if (s && elevation.filled_samples == src.width_px * src.height_px) {
      summary->warnings.push_back("every sample of the input is no-data: the store is flat at 0");
    }
  } else {
    s = writer->finish();
  }
  if (!s) {
    writer.reset();
    return s;
  }
  writer.reset();

  summary->width_px = src.width_px;
  summary->height_px = src.height_px;
  summary->format = src.format;
  summary->input_type = src.input_type;
  summary->decoder = src.decoder;
  summary->input_channels = src.input_channels;
  summary->levels = levels;
  summary->tiles = tiles_done.load();
  summary->input_bytes = src.file_bytes;
  summary->raw_bytes = src.width_px * src.height_px * bpp;
  std::error_code ec;
  summary->output_bytes = fs::file_size(o.output_path, ec);
  summary->clamped_samples = src.clamped_samples;
  summary->panel_px = std::min<uint64_t>(layout.panel_px, src.width_px);
  summary->panels = uint32_t(layout.blocks_x);
  summary->memory_budget_bytes = o.memory_budget_bytes;
  summary->geo = wopt.geo;
  summary->elevation = elevation;
  summary->shard = shard;
  summary->mosaic_sheets = mosaic.sheets.size();
  summary->gap_px = mosaic.gap_px;
  summary->read_s = read_s;
  summary->build_s = build_s;
  summary->encode_s = encode_s;
  summary->peak_rss_bytes = peakRssBytes();
  summary->wall_s = secondsSince(start);
  return okStatus();
}

}  // namespace

Status tileImage(const TilerOptions& options, TilerSummary* summary) {
  // Allocation failure is the one exception the pipeline can meet (huge
  // budgets on small machines); every thread turns it into a Status, and
  // this catches the building thread's. The writer is destroyed on the way
  // out, removing its temporary files.
  try {
    return tileImageImpl(options, summary);
  } catch (const std::bad_alloc&) {
    return Status::error(ErrorCode::kOutOfMemory,
                         "an allocation failed (lower --memory-mb, or the image is too large for it)");
  }
}

}  // namespace clipstream
