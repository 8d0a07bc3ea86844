// The renderer's choices by name and their defaults: buffering, texture
// memory (stack or paged, and `auto`), the planner and pool sizes each
// needs. Pure functions; thread-safe. The renderer itself is
// clipmap_renderer.cpp.
#include <clipstream/renderer/renderer.h>

#include <clipstream/renderer/config.h>

#include <algorithm>
#include <cmath>
#include <string>

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

Status textureMemoryFromName(const std::string& name, TextureMemory* out) {
  if (name == "stack") *out = TextureMemory::kStack;
  else if (name == "paged") *out = TextureMemory::kPaged;
  else
    return Status::error(ErrorCode::kInvalidArgument,
                         "texture memory '" + name + "' is not one of: stack, paged");
  return okStatus();
}

TextureMemory automaticTextureMemory(bool terrain, Buffering buffering) {
  const bool doubled = buffering == Buffering::kDoubleUploadTwice || buffering == Buffering::kDoubleCopy;
  return terrain || doubled ? TextureMemory::kStack : TextureMemory::kPaged;
}

Status textureMemoryFromChoice(const std::string& name, bool terrain, Buffering buffering, bool pool_given,
                               TextureMemory* out) {
  const bool automatic = name == "auto";
  if (automatic) *out = automaticTextureMemory(terrain, buffering);
  else if (!textureMemoryFromName(name, out))
    return Status::error(ErrorCode::kInvalidArgument,
                         "--texture-memory " + name + " is not one of: auto, stack, paged");
  if (!pool_given || *out == TextureMemory::kPaged) return okStatus();
  if (!automatic)
    return Status::error(ErrorCode::kInvalidArgument, "--pool-mb sizes the pool of --texture-memory paged");
  return Status::error(ErrorCode::kInvalidArgument,
                       std::string("--pool-mb sizes the page pool, and auto chose the stack (the pool does not draw ") +
                           (terrain ? "--elevation" : "double buffering") + " yet)");
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

Status bufferingFromName(const std::string& name, Buffering* out) {
  for (Buffering b : {Buffering::kSingle, Buffering::kDoubleUploadTwice, Buffering::kDoubleCopy,
                      Buffering::kStaged})
    if (name == bufferingName(b)) {
      *out = b;
      return okStatus();
    }
  return Status::error(ErrorCode::kInvalidArgument,
                       "buffering \"" + printableText(name, 40) + "\" is not single, double-upload, double-copy or staged");
}


}  // namespace clipstream
