// Sharded tiler runs: `clipstream-tile --shard K/N` tiles one horizontal band
// of the image into a partial store, and mergeShards() (`clipstream-merge`)
// joins the N partial stores and builds the coarse levels no band holds
// alone, giving the store a single run gives, tile for tile (docs/tiler.md,
// "Sharded runs").
//
// Thread rule: free functions. planShard() is pure. mergeShards() may be
// called from any thread; it reads and writes on the calling thread only;
// MergeOptions::progress runs on that thread.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/store/types.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace clipstream {

// Most shards of one run (a band is at least one tile row, so an image has
// at most as many shards as tile rows anyway).
constexpr uint32_t kMaxShards = 65536;

// The band shard `index` of `count` tiles. Levels 0..a are cut into blocks
// of tile_px * 2^a level-0 rows, where a is the coarsest level that still
// has at least `count` block rows; block rows are dealt out in order,
// floor((K-1) * B / N) .. floor(K * B / N) for shard K of B block rows, so
// shards differ by at most one block row when N does not divide B. The band
// is the full width. Levels a+1.. are left to the merge.
struct ShardPlan {
  uint32_t owned_levels = 0;  // a + 1
  uint64_t y0_px = 0;         // first level-0 row of the band (multiple of tile_px * 2^a)
  uint64_t height_px = 0;     // level-0 rows of the band
};

// kInvalidArgument when index is not 1..count, count is 0 or above
// kMaxShards, or the image has fewer tile rows than `count` (naming how many
// it has).
Status planShard(uint64_t width_px, uint64_t height_px, uint32_t tile_px, uint32_t index,
                 uint32_t count, ShardPlan* out);

struct MergeOptions {
  std::vector<std::string> input_paths;  // the partial stores, any order
  std::string output_path;
  bool overwrite = false;  // replace an existing regular file at output_path
  bool fsync = true;
  PayloadOrder payload_order = PayloadOrder::kCurve;  // as clipstream-tile's default
  uint64_t memory_budget_bytes = uint64_t(256) << 20;  // for the coarse levels' rows
  // progress(done_tiles, total_tiles) on the calling thread: once with 0,
  // then now and then. Empty: none.
  std::function<void(uint64_t done, uint64_t total)> progress;
  const std::atomic<int>* cancel = nullptr;  // non-zero stops the merge
};

struct MergeSummary {
  uint64_t width_px = 0;
  uint64_t height_px = 0;
  PixelFormat format = PixelFormat::kRGB8;
  uint32_t shards = 0;
  uint32_t levels = 0;
  uint32_t merged_levels = 0;  // levels copied from the shards (0..merged_levels-1)
  uint64_t copied_tiles = 0;   // payloads copied as they are
  uint64_t built_tiles = 0;    // tiles of the coarse levels built here
  uint64_t output_bytes = 0;
  GeoReference geo;
  double wall_s = 0.0;
};

// Joins the partial stores of one sharded run into the whole store at
// options.output_path: levels 0..a are copied payload by payload (each
// verified against its checksum, never re-encoded), levels a+1.. are built
// from level a with the run's filter and encoded with its encoding. Every
// shard 1..N must be given exactly once. Errors name the file and the
// problem: kInvalidArgument (no inputs, a store that is not a partial store,
// a shard of another run, a duplicate or missing shard, the output is an
// input, an existing output without overwrite, a budget too small),
// kBadHeader (a shard record that does not fit the run), the reader's codes
// for a store that does not open or a tile that fails its checks,
// kUnsupported (elevation shards), kNoSpace, kCancelled. Nothing is left at
// output_path, and no temporary, on failure.
Status mergeShards(const MergeOptions& options, MergeSummary* summary);

}  // namespace clipstream
