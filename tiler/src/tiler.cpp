// tileImage(): validates the options, then runs the stages of a tiling run
// in order: the input (input.h), the band of a shard (shard_run.h), the
// writer options and memory plan (run_plan.h), the pipeline (pipeline.h),
// and the store's finish.
#include <clipstream/tiler/tiler.h>

#include <clipstream/util/output_file.h>
#include <clipstream/util/process_memory.h>
#include <clipstream/tiler/downsample.h>
#include <clipstream/tiler/shard.h>

#include "input.h"
#include "pipeline.h"
#include "run_plan.h"
#include "shard_run.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include <unistd.h>

namespace clipstream {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// validateOptions() in groups, in the order the checks are made: the first
// mistake found is the one reported.

// Tile size, threads, zstd level and the memory budget.
Status checkRunSizes(const TilerOptions& o) {
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
  return okStatus();
}

// --relief and the options it does not go with.
Status checkRelief(const TilerOptions& o) {
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
  return okStatus();
}

// The synthetic image's size and the output path.
Status checkImageAndOutput(const TilerOptions& o) {
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
  return okStatus();
}

// The filter, and the height options against the layer and the input.
Status checkFilterAndHeights(const TilerOptions& o) {
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
  return okStatus();
}

// A mosaic's list and fill, and a shard's K/N against what can be sharded.
Status checkMosaicAndShard(const TilerOptions& o) {
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
  return okStatus();
}

// A height format asked for a colour store.
Status checkColourFormat(const TilerOptions& o) {
  if (o.format && o.layer == LayerKind::kColour && !isColourFormat(*o.format)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         std::string("--format ") + pixelFormatName(*o.format) +
                             " holds heights, not colour");
  }
  return okStatus();
}

// Reprojection: an input file GDAL can warp, a resampling it has, a
// positive resolution.
Status checkReprojection(const TilerOptions& o) {
  const bool asked = !o.target_crs.empty() || o.target_resolution != 0.0;
  if (!asked) return okStatus();
  if (o.target_crs.empty()) {
    return Status::error(ErrorCode::kInvalidArgument, "--t-res needs --t-srs (the CRS it is in)");
  }
  const char* conflict = o.input_path.empty()                  ? "--synthetic"
                         : o.mosaic                             ? "--mosaic (reproject a VRT of the sheets)"
                         : o.reader == ImageReader::kOpenImageIO ? "--reader openimageio (GDAL reprojects)"
                                                                 : nullptr;
  if (conflict != nullptr) {
    return Status::error(ErrorCode::kInvalidArgument, std::string("--t-srs does not go with ") + conflict);
  }
  if (!(o.target_resolution >= 0.0) || !std::isfinite(o.target_resolution)) {
    return Status::error(ErrorCode::kInvalidArgument, "--t-res must be a positive pixel size");
  }
  static const char* const kResamplings[] = {"near", "bilinear", "cubic", "cubicspline",
                                             "lanczos", "average", "mode"};
  if (std::find(std::begin(kResamplings), std::end(kResamplings), o.resampling) == std::end(kResamplings)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--resampling '" + o.resampling +
                             "' is not near, bilinear, cubic, cubicspline, lanczos, average or mode");
  }
  return okStatus();
}

}  // namespace

Status validateOptions(const TilerOptions& o) {
  for (Status (*check)(const TilerOptions&) :
       {checkRunSizes, checkRelief, checkImageAndOutput, checkFilterAndHeights, checkMosaicAndShard,
        checkColourFormat, checkReprojection}) {
    Status s = check(o);
    if (!s) return s;
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

// Creates the writer at the output path. Temporary files that an
// interrupted earlier run left, and that the writer swept away, are told as
// warnings.
Status createWriter(const std::string& path, const PyramidGeometry& geometry,
                    const WriterOptions& wopt, std::unique_ptr<TileStoreWriter>* writer,
                    std::vector<std::string>* warnings) {
  Status s = TileStoreWriter::create(path, geometry, wopt, writer);
  if (s) {
    for (const std::string& swept : (*writer)->sweptTemporaries()) {
      warnings->push_back("removed a temporary file left by an interrupted earlier run: " + swept);
    }
  }
  return s;
}

// Finishes the store after the pipeline ran through; an elevation store's
// figures (filled samples, largest error, height range) go in first, and a
// store whose `samples` were all no-data is warned about.
Status finishStore(TileStoreWriter* writer, const HeightSource* heights, uint64_t samples,
                   ElevationInfo* elevation, std::vector<std::string>* warnings) {
  if (heights == nullptr) return writer->finish();
  elevation->filled_samples = heights->filledSamples();
  elevation->max_error = heights->maxError();
  Status s = writer->setElevationFigures(elevation->filled_samples, elevation->max_error,
                                         elevation->min_height, elevation->max_height);
  if (s) s = writer->finish();
  if (s && elevation->filled_samples == samples) {
    warnings->push_back("every sample of the input is no-data: the store is flat at 0");
  }
  return s;
}

// The summary of a finished run, but its wall time. `src` is the source's
// info() as taken before the pipeline ran.
void fillSummary(const TilerOptions& o, const SourceInfo& src, const TilerInput& input,
                 const WriterOptions& wopt, const PyramidGeometry& geometry,
                 const PanelLayout& layout, const PipelineFigures& figures, TilerSummary* summary) {
  summary->width_px = src.width_px;
  summary->height_px = src.height_px;
  summary->format = src.format;
  summary->input_type = src.input_type;
  summary->decoder = src.decoder;
  summary->reprojection = src.reprojection;
  summary->input_channels = src.input_channels;
  summary->levels = geometry.levelCount();
  summary->tiles = figures.tiles;
  summary->input_bytes = src.file_bytes;
  summary->raw_bytes = src.width_px * src.height_px * bytesPerPixel(geometry.format);
  std::error_code ec;
  summary->output_bytes = fs::file_size(o.output_path, ec);
  summary->clamped_samples = src.clamped_samples;
  summary->panel_px = std::min<uint64_t>(layout.panel_px, src.width_px);
  summary->panels = uint32_t(layout.blocks_x);
  summary->memory_budget_bytes = o.memory_budget_bytes;
  summary->geo = wopt.geo;
  summary->elevation = input.elevation;
  summary->shard = wopt.shard;
  summary->transparent_nodata = input.transparent_nodata;
  summary->mosaic_sheets = input.mosaic.sheets.size();
  summary->gap_px = input.mosaic.gap_px;
  summary->read_s = figures.read_s;
  summary->build_s = figures.build_s;
  summary->encode_s = figures.encode_s;
  summary->peak_rss_bytes = peakRssBytes();
}

Status tileImageImpl(const TilerOptions& o, TilerSummary* summary) {
  const auto start = Clock::now();
  *summary = TilerSummary{};
  Status s = validateOptions(o);
  if (!s) return s;
  s = checkOutput(o);
  if (!s) return s;

  TilerInput input;
  s = openInput(o, &input, &summary->warnings);
  if (!s) return s;
  if (o.relief_scale > 0) summary->relief_scale = o.relief_scale;
  ShardInfo shard;
  if (o.shard_count != 0) {
    s = cutShard(o, input.geo, input.mosaic.sheets, input.elevation.present, &input.source, &shard);
    if (!s) return s;
  }
  const SourceInfo& src = input.source->info();
  for (const std::string& w : src.warnings) summary->warnings.push_back(w);

  const WriterOptions wopt = writerOptions(o, input.elevation, input.geo, shard);
  PyramidGeometry geometry;
  s = pyramidGeometryFor(src, o.tile_px, &geometry);
  if (!s) return s;
  const Downsampler downsampler(wopt.encoding.filter, o.linear_light, src.format);
  const unsigned threads = encoderThreads(o);
  // Box and decimate read only the 2x2 samples under each output sample, so
  // levels can be built per panel; Lanczos reaches across panel borders.
  const bool need_single = wopt.encoding.filter == DownsampleFilter::kLanczos3;
  PanelLayout layout;
  s = planLayoutInBudget(geometry, downsampler, threads, o.memory_budget_bytes, currentRssBytes(),
                         need_single, &layout, &summary->warnings);
  if (!s) return s;

  std::unique_ptr<TileStoreWriter> writer;
  s = createWriter(o.output_path, geometry, wopt, &writer, &summary->warnings);
  if (!s) return s;
  PipelineInputs pipeline;
  pipeline.source = input.source.get();
  pipeline.geometry = &geometry;
  pipeline.downsampler = &downsampler;
  pipeline.layout = &layout;
  pipeline.encoding = &wopt.encoding;
  pipeline.threads = threads;
  pipeline.progress = o.progress;
  pipeline.cancel = o.cancel;
  pipeline.write = [&writer](EncodedTile&& tile) { return writer->write(std::move(tile)); };
  PipelineFigures figures;
  s = runPipeline(pipeline, &input.elevation, &figures);
  if (s) {
    summary->constant_tiles = writer->constantTiles();
    s = finishStore(writer.get(), input.heights, src.width_px * src.height_px, &input.elevation,
                    &summary->warnings);
  }
  if (!s) {
    writer.reset();  // removes the temporary file
    return s;
  }
  writer.reset();
  fillSummary(o, src, input, wopt, geometry, layout, figures, summary);
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
