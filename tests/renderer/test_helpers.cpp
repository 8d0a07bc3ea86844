#include "test_helpers.h"

#include <clipstream/renderer/config.h>

#include <clipstream/store/tile_store.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <string>

namespace clipstream::test {

HeadlessContext* sharedContext(std::string* why) {
  static std::unique_ptr<HeadlessContext> context;
  static Status status = HeadlessContext::create(&context);
  if (why != nullptr) *why = status.toString();
  return context.get();
}

bool glRequired() {
  const char* value = std::getenv("CLIPSTREAM_REQUIRE_GL");
  return value != nullptr && *value != '\0' && std::string(value) != "0";
}

std::vector<LevelResidency> fullResidency(const ClipmapPlan& plan, uint32_t finest_loaded) {
  std::vector<LevelResidency> out;
  for (const ClipLevelPlan& l : plan.stack) {
    LevelResidency r;
    r.level = l.level;
    r.window = l.window;
    r.resident.assign(size_t(l.window.width()) * size_t(l.window.height()),
                      l.level >= finest_loaded ? 1 : 0);
    out.push_back(std::move(r));
  }
  return out;
}

void loadPlan(ClipmapRenderer& renderer, TileSource& source, const ClipmapPlan& plan,
              uint32_t finest_loaded) {
  const PyramidGeometry& g = source.geometry();
  renderer.beginFrame();
  auto upload = [&](uint32_t level, int64_t x, int64_t y) {
    auto px = std::make_shared<std::vector<uint8_t>>();
    if (!source.fetch({level, uint32_t(x), uint32_t(y)}, px.get())) return;
    renderer.uploadTile({level, uint32_t(x), uint32_t(y)}, px);
  };
  for (uint32_t l = plan.pyramid_level; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) upload(l, x, y);
  for (const ClipLevelPlan& l : plan.stack) {
    if (l.level < finest_loaded) continue;
    for (int64_t y = l.window.y0; y < l.window.y1; ++y)
      for (int64_t x = l.window.x0; x < l.window.x1; ++x) upload(l.level, x, y);
  }
  renderer.setResidency(fullResidency(plan, finest_loaded));
  renderer.setMaxTextureLod(0);
  renderer.endUploads();
  // Double-buffered: bring the other set up to date too, so a following
  // frame that uploads nothing draws the same.
  renderer.beginFrame();
  renderer.endUploads();
}

std::vector<uint8_t> renderFrame(ClipmapRenderer& renderer, OffscreenTarget& target,
                                 const Camera& camera) {
  target.bind();
  ClipmapRenderer::clearSky();
  renderer.draw(camera, target.viewport());
  std::vector<uint8_t> rgba;
  target.readRgba(&rgba);
  return rgba;
}

}  // namespace clipstream::test

namespace clipstream::test {
void dumpPpm(const std::string& name, const std::vector<uint8_t>& rgba, const Viewport& vp) {
  const char* dir = std::getenv("CLIPSTREAM_TEST_DUMP");
  if (dir == nullptr) return;
  FILE* f = std::fopen((std::string(dir) + "/" + name + ".ppm").c_str(), "wb");
  if (f == nullptr) return;
  std::fprintf(f, "P6 %u %u 255\n", vp.width_px, vp.height_px);
  for (size_t i = 0; i < rgba.size(); i += 4) std::fwrite(&rgba[i], 1, 3, f);
  std::fclose(f);
}
}  // namespace clipstream::test

namespace clipstream::test {

Status damageTilePayload(const std::string& path, const TileKey& key, PayloadDamage damage) {
  std::unique_ptr<TileStoreReader> reader;
  if (Status s = TileStoreReader::open(path, &reader); !s) return s;
  TileLocation where;
  if (Status s = reader->locate(key, &where); !s) return s;
  if (where.constant || where.stored_bytes < 16)
    return Status::error(ErrorCode::kInvalidArgument,
                         "damageTilePayload: tile has no payload to damage");
  const PyramidGeometry geometry = reader->geometry();
  const StoreEncoding encoding = reader->info().encoding;
  std::vector<uint8_t> clean_pixels;
  if (Status s = reader->readTile(key, &clean_pixels); !s) return s;
  reader.reset();

  RawTile raw;
  raw.key = key;
  raw.location = where;
  raw.payload.resize(where.stored_bytes);
  {
    std::ifstream in(path, std::ios::binary);
    in.seekg(std::streamoff(where.offset));
    in.read(reinterpret_cast<char*>(raw.payload.data()), std::streamsize(raw.payload.size()));
    if (!in) return Status::error(ErrorCode::kIo, "damageTilePayload: cannot read the payload");
  }
  // Decodes without the checksum: what a reader that trusted the bytes
  // would get.
  std::vector<uint8_t> pixels(geometry.tileBytes());
  auto decodes = [&]() {
    return decodeTile(geometry, encoding, raw, std::span<uint8_t>(pixels)).ok() &&
           pixels != clean_pixels;
  };
  if (damage == PayloadDamage::kBreakFrame) {
    for (size_t i = 0; i < 4; ++i) raw.payload[i] ^= 0xFF;  // the zstd magic number
    if (decodeTile(geometry, encoding, raw, std::span<uint8_t>(pixels)).ok())
      return Status::error(ErrorCode::kInvalidArgument, "damageTilePayload: frame still decodes");
  } else {
    // Entropy-coded bytes usually break the frame when flipped; search from
    // the middle for one whose flip still decodes (literals, raw blocks).
    bool found = false;
    for (size_t i = raw.payload.size() / 2; i < raw.payload.size() && !found; ++i) {
      raw.payload[i] ^= 0x04;
      found = decodes();
      if (!found) raw.payload[i] ^= 0x04;
    }
    if (!found)
      return Status::error(ErrorCode::kInvalidArgument,
                           "damageTilePayload: no flip keeps the frame decodable");
  }
  std::fstream out(path, std::ios::binary | std::ios::in | std::ios::out);
  out.seekp(std::streamoff(where.offset));
  out.write(reinterpret_cast<const char*>(raw.payload.data()), std::streamsize(raw.payload.size()));
  out.flush();
  if (!out)
    return Status::error(ErrorCode::kIo, "damageTilePayload: cannot write the payload back");
  return okStatus();
}

size_t terrainCracks(const std::vector<uint8_t>& rgba, const Camera& camera, const Viewport& viewport,
                     double lowest, double lo, double hi, size_t* ground, std::vector<uint8_t>* marked,
                     double highest) {
  if (marked) *marked = rgba;
  if (ground) *ground = 0;
  Camera lowered = camera;
  lowered.position.y -= lowest;
  Camera top = camera;
  top.position.y -= highest;
  size_t cracks = 0;
  for (uint32_t py = 0; py < viewport.height_px; ++py)
    for (uint32_t px = 0; px < viewport.width_px; ++px) {
      const uint8_t* p = rgba.data() + (size_t(py) * viewport.width_px + px) * 4;
      const bool background = std::equal(p, p + 3, renderer_config::kSkyRgba);
      if (ground && !background) ++*ground;
      glm::dvec2 hit;
      if (!background || !groundHit(lowered, viewport, px + 0.5, py + 0.5, &hit)) continue;
      if (hit.x < lo || hit.y < lo || hit.x > hi || hit.y > hi) continue;
      if (!std::isnan(highest)) {
        // The ray must also come down through y = highest inside the square.
        glm::dvec2 enter;
        if (top.position.y > 0.0 && !groundHit(top, viewport, px + 0.5, py + 0.5, &enter)) continue;
        if (top.position.y > 0.0 && (enter.x < lo || enter.y < lo || enter.x > hi || enter.y > hi)) continue;
      }
      ++cracks;
      if (marked) {
        uint8_t* m = marked->data() + (size_t(py) * viewport.width_px + px) * 4;
        m[0] = 255, m[1] = 0, m[2] = 0;
      }
    }
  return cracks;
}

}  // namespace clipstream::test
