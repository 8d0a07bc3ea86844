// The renderer's modes by name (the words reports and messages use) and
// their defaults: buffering, texture memory (stack or paged, and the
// automatic choice), the planner and pool sizes each needs. Pure functions;
// thread-safe. Parsing the words is the programs' (cli/renderer_options.h);
// the renderer itself is clipmap_renderer.cpp.
#include <clipstream/renderer/renderer.h>

#include <clipstream/renderer/config.h>

#include <algorithm>
#include <cmath>

namespace clipstream {

const char* bufferingName(Buffering buffering) {
  switch (buffering) {
    case Buffering::kSingle: return "single";
    case Buffering::kDoubleUploadTwice: return "double-upload";
    case Buffering::kDoubleCopy: return "double-copy";
    case Buffering::kStaged: return "staged";
  }
  return "?";
}

const char* textureMemoryName(TextureMemory memory) {
  return memory == TextureMemory::kPaged ? "paged" : "stack";
}

TextureMemory automaticTextureMemory(bool terrain, Buffering buffering) {
  const bool doubled = buffering == Buffering::kDoubleUploadTwice || buffering == Buffering::kDoubleCopy;
  return terrain || doubled ? TextureMemory::kStack : TextureMemory::kPaged;
}

PlannerConfig plannerFor(TextureMemory memory, PlannerConfig planner) {
  if (memory == TextureMemory::kPaged && planner.pyramid_tiles == 0)
    planner.pyramid_tiles = renderer_config::kPagedPyramidTiles;
  return planner;
}

uint64_t defaultPoolBytes(const Viewport& viewport, uint32_t tile_px, TileContent content) {
  if (tile_px == 0) return 0;
  const double screen_tiles =
      double(viewport.width_px) * double(viewport.height_px) / (double(tile_px) * double(tile_px));
  const uint64_t pages =
      std::max<uint64_t>(renderer_config::kPoolMinPages,
                         uint64_t(std::ceil(renderer_config::kDefaultPoolPagesPerScreenTile * screen_tiles)));
  return pages * pageBytes(tile_px, content);
}

}  // namespace clipstream
