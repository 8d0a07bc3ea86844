// The writer options, pyramid geometry and panel layout of a tiler run
// (run_plan.h).
#include "run_plan.h"

#include "pyramid_builder.h"

#include <algorithm>
#include <thread>

namespace clipstream {

WriterOptions writerOptions(const TilerOptions& o, const ElevationInfo& elevation,
                            const GeoReference& geo, const ShardInfo& shard) {
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
  return wopt;
}

Status pyramidGeometryFor(const SourceInfo& src, uint32_t tile_px, PyramidGeometry* out) {
  if (!makePyramidGeometry(src.width_px, src.height_px, tile_px, src.format, out)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "cannot make a pyramid for " + std::to_string(src.width_px) + "x" +
                             std::to_string(src.height_px) + " with tile size " +
                             std::to_string(tile_px));
  }
  return okStatus();
}

unsigned encoderThreads(const TilerOptions& o) {
  return o.threads != 0 ? o.threads : std::max(1u, std::thread::hardware_concurrency());
}

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

Status planLayoutInBudget(const PyramidGeometry& g, const Downsampler& ds, unsigned threads,
                          uint64_t budget_bytes, uint64_t base_bytes, bool need_single,
                          PanelLayout* out, std::vector<std::string>* warnings) {
  Status s = planLayout(g, ds, threads, budget_bytes, base_bytes, need_single, out);
  if (s || base_bytes <= budget_bytes / 2) return s;
  // Most of the budget is gone before the first row: the libraries and the
  // decoder's own state (a progressive JPEG keeps every DCT coefficient, 2
  // bytes per sample). Nothing the tiler does can undo that, so plan our
  // part within half the budget on top of it, and say so.
  Status retry = planLayout(g, ds, threads, base_bytes + budget_bytes / 2, base_bytes, need_single, out);
  if (!retry) return s;
  warnings->push_back(
      std::to_string(base_bytes >> 20) +
      " MB are resident before tiling starts (image libraries and decoder state; a "
      "progressive JPEG keeps all its coefficients); "
      "peak memory will exceed --memory-mb " + std::to_string(budget_bytes >> 20));
  return retry;
}

}  // namespace clipstream
