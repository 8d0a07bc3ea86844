// The renderer's option values on the command line of the programs that
// draw (clipstream-fly, clipstream-view): --buffering, --texture-memory,
// --tile-format and --terrain turned into the renderer's and the streamer's
// enums. The other way, enum to word,
// stays with each enum (bufferingName(), textureMemoryName(),
// terrainMethodName()): the reports and the renderer's messages use it, and
// these parsers accept exactly those words (docs/decisions.md D274).
// Library clipstream_cli_renderer, built with the renderer and linked only
// by those programs, so the others link no GL.
//
// Thread rule: pure functions of their arguments, thread-safe.
#pragma once

#include <clipstream/renderer/renderer.h>
#include <clipstream/renderer/terrain.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/look_at.h>

#include <string>

namespace clipstream::cli {

// --buffering: "single", "double-upload", "double-copy" or "staged"
// (bufferingName()). kInvalidArgument naming the choices otherwise; *out
// is set only on success.
Status parseBuffering(const std::string& name, Buffering* out);

// --texture-memory: "auto" (automaticTextureMemory() of the frames' terrain
// and buffering), "stack" or "paged"; kInvalidArgument naming the three
// otherwise, or when `pool_given` (--pool-mb) but the choice is not paged
// (saying why auto chose the stack).
Status parseTextureMemory(const std::string& name, bool terrain, Buffering buffering, bool pool_given,
                          TextureMemory* out);

// --tile-format (and --reference-tile-format): the colour tiles on the GPU,
// "rgba8" or "bc1" (tileContentName()). kInvalidArgument naming the two
// otherwise (heights are not a colour tile format); *out is set only on
// success.
Status parseTileFormat(const std::string& name, TileContent* out);

// --terrain: "clipmap", "quadtree", "flat" or "full" (terrainMethodName()).
// kInvalidArgument naming the choices otherwise; *out is set only on
// success.
Status parseTerrainMethod(const std::string& name, TerrainMethod* out);

// --look-at X,Y[,HEIGHT] or lonlat:LON,LAT[,HEIGHT]: a map point (or
// longitude and latitude in degrees) and optionally its height, finite
// numbers separated by commas. kInvalidArgument naming the text otherwise.
Status parseLookAt(const std::string& text, LookAt* out);

// --terrain-lighting (and --reference-lighting): "vertex" or "pixel"
// (terrainLightingName()). kInvalidArgument naming the choices otherwise;
// *out is set only on success.
Status parseTerrainLighting(const std::string& name, TerrainLighting* out);

}  // namespace clipstream::cli
