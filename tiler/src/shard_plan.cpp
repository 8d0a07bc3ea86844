// The band each shard of a sharded run tiles (shard.h). Kept apart from the
// merge: clipstream-tile links this file, and the merge pulls in the store
// reader (and with it the HTTP client's ~30 shared libraries, 2 MB of
// resident memory that the tiler's memory budget would have to pay for).
#include <clipstream/tiler/shard.h>

#include <algorithm>

namespace clipstream {

Status planShard(uint64_t width_px, uint64_t height_px, uint32_t tile_px, uint32_t index,
                 uint32_t count, ShardPlan* out) {
  const std::string name = "--shard " + std::to_string(index) + "/" + std::to_string(count);
  if (count == 0 || count > kMaxShards || index == 0 || index > count) {
    return Status::error(ErrorCode::kInvalidArgument,
                         name + ": K/N needs 1 <= K <= N <= " + std::to_string(kMaxShards));
  }
  PyramidGeometry g;
  if (!makePyramidGeometry(width_px, height_px, tile_px, PixelFormat::kR8, &g)) {
    return Status::error(ErrorCode::kInvalidArgument, name + ": no pyramid for this image size");
  }
  if (g.levels[0].tiles_y < count) {
    return Status::error(ErrorCode::kInvalidArgument,
                         name + ": the image has only " + std::to_string(g.levels[0].tiles_y) +
                             " tile rows of " + std::to_string(tile_px) +
                             " px, and each shard needs one; use at most that many shards");
  }
  // The coarsest level with at least `count` block rows (level 0 has,
  // checked above). Block rows of tile_px * 2^a level-0 rows are the tile
  // rows of level a.
  uint32_t a = 0;
  while (a + 1 < g.levelCount() && g.levels[a + 1].tiles_y >= count) ++a;
  const uint64_t block_px = uint64_t(tile_px) << a;
  const uint64_t blocks = g.levels[a].tiles_y;
  const uint64_t r0 = (uint64_t(index) - 1) * blocks / count;
  const uint64_t r1 = uint64_t(index) * blocks / count;
  out->owned_levels = a + 1;
  out->y0_px = r0 * block_px;
  out->height_px = std::min(r1 * block_px, height_px) - out->y0_px;
  return okStatus();
}

}  // namespace clipstream
