// Private: the tiler's three-stage pipeline. A reader thread decodes strips
// of one tile row (block by block of the panel layout, run_plan.h), the
// calling thread builds the pyramid from them (pyramid_builder.h), and
// encoder threads encode the finished tiles and hand them to `write`.
// Queues between the stages are bounded (bounded_queue.h), which is what
// bounds memory (docs/tiler.md, "Memory model").
//
// Thread rule: runPipeline() may be called from any thread; it starts and
// joins its own reader and encoder threads before returning, and is the
// building stage itself. `progress` runs on the calling thread; `write`
// runs on the encoder threads, several at once; the source is read on the
// reader thread only.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>
#include <clipstream/tiler/downsample.h>
#include <clipstream/tiler/image_source.h>

#include "run_plan.h"

#include <atomic>
#include <cstdint>
#include <functional>

namespace clipstream {

struct PipelineInputs {
  ImageSource* source = nullptr;  // level-0 rows; info() is not called during the run
  const PyramidGeometry* geometry = nullptr;  // of the source's size and format
  const Downsampler* downsampler = nullptr;
  const PanelLayout* layout = nullptr;        // planLayout()'s for this geometry
  const StoreEncoding* encoding = nullptr;    // what encodeTile() makes of each tile
  unsigned threads = 1;                       // encoder threads, at least 1
  // progress(done_px, total_px) as TilerOptions::progress: once with 0 when
  // the threads are started, then after each strip. Empty: none.
  std::function<void(uint64_t done_px, uint64_t total_px)> progress;
  const std::atomic<int>* cancel = nullptr;   // non-zero stops the run (kCancelled)
  // Stores one encoded tile (TileStoreWriter::write). Every tile of the
  // pyramid is passed once, each after the tiles under it at the level
  // below; with one encoder thread, in the order the builders finish them.
  std::function<Status(EncodedTile&& tile)> write;
};

// What a successful run did.
struct PipelineFigures {
  uint64_t tiles = 0;     // tiles passed to `write`
  double read_s = 0.0;    // reader thread CPU time (decode + convert)
  double build_s = 0.0;   // building thread CPU time (filter + tile copies)
  double encode_s = 0.0;  // encoder threads' CPU time, summed (encode + write)
};

// Runs the pipeline over the whole source. When elevation->present, each
// tile's height bounds and error go into its location (height_bounds.h) and
// the coarsest tile's bounds into elevation->min_height / max_height.
// The first error of any stage stops every stage and is returned (kIo
// naming a thread the system refused, the reader's or `write`'s error,
// kOutOfMemory naming the stage, kCancelled "interrupted"); the threads are
// joined either way, and *figures is written only on success.
Status runPipeline(const PipelineInputs& in, ElevationInfo* elevation, PipelineFigures* figures);

}  // namespace clipstream
