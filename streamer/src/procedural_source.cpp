// Procedural texture of planet size (up to 2^31 texels a side), generated per
// tile: no disk, deterministic, every texel a pure function of its level and
// coordinates (definition in tile_source.h above proceduralTexel()).
#include <clipstream/streamer/tile_source.h>
#include <clipstream/streamer/testing/procedural_texel.h>

#include <algorithm>
#include <string>

namespace clipstream {
namespace {

constexpr int kLayers = 6;              // cells of 8 << j texels, j = 0..5
constexpr int kFinestLayerShift = 3;    // 8x8 blocks
// Weights grow slowly with cell size: fine blocks stay visible while each
// level keeps most of its neighbours' weight on shared cells, so a coarser
// level correlates with the box average of the finer one (r ~ 0.8).
constexpr int kLayerWeight[kLayers] = {2, 2, 3, 3, 4, 4};
constexpr int kWeightSum = 18;
constexpr int kContrast = 110;          // peak deviation from mid-grey

uint64_t mix64(uint64_t x) {
  // splitmix64 finaliser: cheap and well distributed for structured keys.
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Hashed colour of one cell: `scale_log2` is the cell size in level-0
// texels (log2), (cx, cy) its index at that size. Levels share cells.
uint64_t cellHash(uint32_t seed, uint32_t scale_log2, uint64_t cx, uint64_t cy) {
  return mix64(mix64(mix64((uint64_t(seed) << 32) | scale_log2) ^ cx) ^ (cy * 0x2545F4914F6CDD1Dull));
}

// Colour of the 8x8 block (bx, by) of `level` (bx = tx >> 3): every layer's
// cell is aligned to 8 texels, so the whole block shares it.
void blockColour(uint32_t seed, uint32_t level, uint64_t bx, uint64_t by, uint8_t rgb[3]) {
  int acc[3] = {0, 0, 0};
  for (int j = 0; j < kLayers; ++j) {
    const uint64_t h = cellHash(seed, level + kFinestLayerShift + j, bx >> j, by >> j);
    for (int c = 0; c < 3; ++c) acc[c] += kLayerWeight[j] * (int((h >> (8 * c)) & 0xFF) - 128);
  }
  for (int c = 0; c < 3; ++c)
    rgb[c] = uint8_t(std::clamp(128 + acc[c] * kContrast / (128 * kWeightSum), 0, 255));
}

class ProceduralSource final : public TileSource {
 public:
  ProceduralSource(const ProceduralSpec& spec, const PyramidGeometry& geometry)
      : m_spec(spec), m_geometry(geometry) {}

  const PyramidGeometry& geometry() const override { return m_geometry; }

  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    if (!m_geometry.contains(key))
      return Status::error(ErrorCode::kOutOfRange,
                           "procedural: tile (" + std::to_string(key.x) + ", " +
                               std::to_string(key.y) + ") of level " + std::to_string(key.level) +
                               " is outside the pyramid");
    const uint32_t t = m_spec.tile_px;
    rgba->resize(size_t(t) * t * 4);
    const uint64_t x0 = uint64_t(key.x) * t, y0 = uint64_t(key.y) * t;
    uint8_t* out = rgba->data();
    uint8_t rgb[3] = {0, 0, 0};
    for (uint32_t y = 0; y < t; ++y) {
      const uint64_t ty = y0 + y;
      uint64_t last_block = ~uint64_t(0);
      for (uint32_t x = 0; x < t; ++x, out += 4) {
        const uint64_t tx = x0 + x;
        if ((tx >> 3) != last_block) {
          last_block = tx >> 3;
          blockColour(m_spec.seed, key.level, tx >> 3, ty >> 3, rgb);
        }
        const bool grid = (tx % t) == 0 || (ty % t) == 0;
        out[0] = grid ? rgb[0] / 2 : rgb[0];
        out[1] = grid ? rgb[1] / 2 : rgb[1];
        out[2] = grid ? rgb[2] / 2 : rgb[2];
        out[3] = 255;
      }
    }
    return okStatus();
  }

  std::string describe() const override {
    return "procedural:" + std::to_string(m_spec.width_px) + "x" + std::to_string(m_spec.height_px);
  }

 private:
  ProceduralSpec m_spec;
  PyramidGeometry m_geometry;
};

}  // namespace

void proceduralTexel(const ProceduralSpec& spec, uint32_t level, uint64_t tx, uint64_t ty,
                     uint8_t rgba[4]) {
  blockColour(spec.seed, level, tx >> 3, ty >> 3, rgba);
  const uint32_t t = spec.tile_px ? spec.tile_px : 1;
  if (tx % t == 0 || ty % t == 0) {
    for (int c = 0; c < 3; ++c) rgba[c] = rgba[c] / 2;
  }
  rgba[3] = 255;
}

std::shared_ptr<TileSource> makeProceduralSource(const ProceduralSpec& spec) {
  PyramidGeometry geometry;
  if (spec.width_px > kMaxProceduralSidePx || spec.height_px > kMaxProceduralSidePx || spec.tile_px < 8 ||
      !makePyramidGeometry(spec.width_px, spec.height_px, spec.tile_px, PixelFormat::kRGBA8,
                           &geometry))
    return nullptr;
  return std::make_shared<ProceduralSource>(spec, geometry);
}

}  // namespace clipstream
