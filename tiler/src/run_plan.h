// Private: how a tiler run writes its output, decided before the first row
// is read: the store's writer options, the pyramid's geometry, the encoder
// thread count and how the image is cut into panels so that the pipeline
// (pipeline.h) stays within the memory budget. The memory model is
// docs/tiler.md, "Memory model".
//
// Thread-safe: free functions of their arguments alone (none reads the
// process's memory: the caller measures what is resident and passes it in).
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>
#include <clipstream/tiler/downsample.h>
#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/tiler.h>

#include <cstdint>
#include <string>
#include <vector>

namespace clipstream {

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

// How the image is cut: panels of panel_px columns (and rows), whose first
// `local_levels` levels are built per block; the rest by one coarse builder
// over the whole of level local_levels - 1.
struct PanelLayout {
  uint32_t local_levels = 1;
  uint64_t panel_px = 0;  // block size at level 0 (tile_px << (local_levels - 1))
  uint64_t blocks_x = 1, blocks_y = 1;
  uint64_t estimate_bytes = 0;
};

// The writer options of a run: zstd at the options' level, the predictor,
// the filter (decimate for an elevation store), and the elevation, the
// georeference (a shard's is the whole image's) and the shard record given.
WriterOptions writerOptions(const TilerOptions& o, const ElevationInfo& elevation,
                            const GeoReference& geo, const ShardInfo& shard);

// The pyramid of an image of src's size and format in tiles of tile_px:
// kInvalidArgument naming the size when there is none.
Status pyramidGeometryFor(const SourceInfo& src, uint32_t tile_px, PyramidGeometry* out);

// Encoder threads of a run: TilerOptions::threads, or every core when 0.
unsigned encoderThreads(const TilerOptions& o);

// The layout with the largest panels (fewest blocks) whose estimate, with
// `base_bytes` already resident, fits in `budget_bytes`. `need_single`
// (the Lanczos filter) accepts only the full-width layout. kInvalidArgument
// saying how much memory the smallest layout needs when none fits; *out is
// written only on success.
Status planLayout(const PyramidGeometry& g, const Downsampler& ds, unsigned threads,
                  uint64_t budget_bytes, uint64_t base_bytes, bool need_single, PanelLayout* out);

// planLayout() within the budget; when that fails and more than half the
// budget is resident already (libraries, a decoder's own state), the
// tiler's part is planned within half the budget on top of what is
// resident, and a warning that peak memory will exceed the budget is added
// to `warnings`. The error is the first plan's when the second fails too.
Status planLayoutInBudget(const PyramidGeometry& g, const Downsampler& ds, unsigned threads,
                          uint64_t budget_bytes, uint64_t base_bytes, bool need_single,
                          PanelLayout* out, std::vector<std::string>* warnings);

}  // namespace clipstream
