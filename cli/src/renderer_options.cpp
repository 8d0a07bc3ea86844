// The renderer's option values. See renderer_options.h. Each parser walks
// the enum through its name function, so a program accepts exactly the
// words the reports print.
#include <clipstream/cli/renderer_options.h>

#include <cmath>
#include <cstdlib>
#include <vector>

namespace clipstream::cli {

Status parseBuffering(const std::string& name, Buffering* out) {
  for (Buffering b : {Buffering::kSingle, Buffering::kDoubleUploadTwice, Buffering::kDoubleCopy,
                      Buffering::kStaged})
    if (name == bufferingName(b)) {
      *out = b;
      return okStatus();
    }
  return Status::error(ErrorCode::kInvalidArgument,
                       "buffering \"" + printableText(name, 40) + "\" is not single, double-upload, double-copy or staged");
}

Status parseTextureMemory(const std::string& name, bool terrain, Buffering buffering, bool pool_given,
                          TextureMemory* out) {
  const bool automatic = name == "auto";
  if (automatic) {
    *out = automaticTextureMemory(terrain, buffering);
  } else if (name == textureMemoryName(TextureMemory::kStack)) {
    *out = TextureMemory::kStack;
  } else if (name == textureMemoryName(TextureMemory::kPaged)) {
    *out = TextureMemory::kPaged;
  } else {
    return Status::error(ErrorCode::kInvalidArgument,
                         "--texture-memory " + name + " is not one of: auto, stack, paged");
  }
  if (!pool_given || *out == TextureMemory::kPaged) return okStatus();
  if (!automatic)
    return Status::error(ErrorCode::kInvalidArgument, "--pool-mb sizes the pool of --texture-memory paged");
  return Status::error(ErrorCode::kInvalidArgument,
                       std::string("--pool-mb sizes the page pool, and auto chose the stack (the pool does not draw ") +
                           (terrain ? "--elevation" : "double buffering") + " yet)");
}

Status parseTileFormat(const std::string& name, TileContent* out) {
  for (TileContent c : {TileContent::kRgba8, TileContent::kBc1})
    if (name == tileContentName(c)) {
      *out = c;
      return okStatus();
    }
  return Status::error(ErrorCode::kInvalidArgument,
                       "tile format \"" + printableText(name, 40) + "\" is not rgba8 or bc1");
}

Status parseTerrainMethod(const std::string& name, TerrainMethod* out) {
  for (TerrainMethod m : {TerrainMethod::kClipmap, TerrainMethod::kQuadtree, TerrainMethod::kFlat,
                          TerrainMethod::kFull}) {
    if (name == terrainMethodName(m)) {
      *out = m;
      return okStatus();
    }
  }
  return Status::error(ErrorCode::kInvalidArgument,
                       "terrain method '" + name + "': must be clipmap, quadtree, flat or full");
}

Status parseLookAt(const std::string& given, LookAt* out) {
  // "lonlat:LON,LAT[,HEIGHT]": degrees, WGS 84.
  static constexpr char kLonLat[] = "lonlat:";
  const bool lon_lat = given.rfind(kLonLat, 0) == 0;
  const std::string text = lon_lat ? given.substr(sizeof kLonLat - 1) : given;
  std::vector<double> v;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = std::min(text.find(',', start), text.size());
    const std::string part = text.substr(start, comma - start);
    char* end = nullptr;
    const double d = part.empty() ? NAN : std::strtod(part.c_str(), &end);
    if (part.empty() || end != part.c_str() + part.size() || !std::isfinite(d))
      return Status::error(ErrorCode::kInvalidArgument,
                           "look-at point \"" + printableText(text, 60) + "\": give X,Y or X,Y,HEIGHT (finite numbers)");
    v.push_back(d);
    start = comma + 1;
  }
  if (v.size() < 2 || v.size() > 3)
    return Status::error(ErrorCode::kInvalidArgument,
                         "look-at point \"" + printableText(text, 60) + "\": give X,Y or X,Y,HEIGHT");
  if (lon_lat && (std::abs(v[0]) > 180.0 || std::abs(v[1]) > 90.0))
    return Status::error(ErrorCode::kInvalidArgument, "look-at point \"" + printableText(given, 60) +
                                                          "\": longitude -180..180, latitude -90..90");
  out->map = {v[0], v[1]};
  out->height = v.size() == 3 ? std::optional<double>(v[2]) : std::nullopt;
  out->lon_lat = lon_lat;
  return okStatus();
}

Status parseTerrainLighting(const std::string& name, TerrainLighting* out) {
  for (TerrainLighting l : {TerrainLighting::kVertex, TerrainLighting::kPixel}) {
    if (name == terrainLightingName(l)) {
      *out = l;
      return okStatus();
    }
  }
  return Status::error(ErrorCode::kInvalidArgument,
                       "terrain lighting '" + printableText(name, 40) + "': must be vertex or pixel");
}

}  // namespace clipstream::cli
