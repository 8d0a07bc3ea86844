// Procedural heights of planet size (up to 2^31 samples a side), generated
// per tile like the procedural texture: value noise over five octaves plus
// a 120-unit cliff every 2^14 samples, every sample a pure function of its
// level-0 coordinates (integer cell arithmetic, exact at any size).
#include <clipstream/streamer/tile_source.h>

#include <cmath>
#include <cstring>
#include <string>

namespace clipstream {
namespace {

struct Octave {
  uint32_t cell_log2;  // cell size in level-0 samples, log2
  double amplitude;
};
constexpr Octave kOctaves[] = {{13, 400.0}, {11, 150.0}, {9, 60.0}, {7, 20.0}, {5, 5.0}};
constexpr double kBase = 1000.0;      // keeps every height positive
constexpr double kCliff = 120.0;      // added on every other band of 2^14 samples
constexpr uint32_t kCliffBandLog2 = 14;

uint64_t mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// A value in [-1, 1] for lattice corner (cx, cy) of an octave.
double corner(uint32_t seed, uint32_t octave, uint64_t cx, uint64_t cy) {
  const uint64_t h = mix(mix((uint64_t(seed) << 8 | octave) ^ mix(cx)) ^ (cy * 0xD6E8FEB86659FD93ull));
  return double(h >> 11) * (2.0 / 9007199254740992.0) - 1.0;
}

double smooth(double t) { return t * t * (3.0 - 2.0 * t); }

class ProceduralHeightSource final : public TileSource {
 public:
  ProceduralHeightSource(const ProceduralSpec& spec, const PyramidGeometry& geometry)
      : m_spec(spec), m_geometry(geometry) {}

  const PyramidGeometry& geometry() const override { return m_geometry; }
  TileContent content() const override { return TileContent::kHeightF32; }
  ElevationInfo elevationInfo() const override {
    ElevationInfo e;
    e.present = true;
    e.units_assumed = false;
    double amplitude = 0.0;
    for (const Octave& o : kOctaves) amplitude += o.amplitude;
    e.min_height = kBase - amplitude;
    e.max_height = kBase + amplitude + kCliff;
    return e;
  }

  Status fetch(const TileKey& key, std::vector<uint8_t>* out) override {
    if (!m_geometry.contains(key))
      return Status::error(ErrorCode::kOutOfRange,
                           "procedural heights: tile (" + std::to_string(key.x) + ", " +
                               std::to_string(key.y) + ") of level " + std::to_string(key.level) +
                               " is outside the pyramid");
    const uint32_t t = m_spec.tile_px;
    const LevelInfo& info = m_geometry.levels[key.level];
    out->resize(size_t(t) * t * sizeof(float));
    for (uint32_t y = 0; y < t; ++y)
      for (uint32_t x = 0; x < t; ++x) {
        // Samples past the level's edge repeat the last one, as the tiler pads.
        const uint64_t i = std::min<uint64_t>(uint64_t(key.x) * t + x, info.width_px - 1);
        const uint64_t j = std::min<uint64_t>(uint64_t(key.y) * t + y, info.height_px - 1);
        const float h = float(proceduralHeight(m_spec, i << key.level, j << key.level));
        std::memcpy(out->data() + (size_t(y) * t + x) * sizeof(float), &h, sizeof(float));
      }
    return Status::ok();
  }

  std::string describe() const override {
    return "procedural-heights:" + std::to_string(m_spec.width_px) + "x" + std::to_string(m_spec.height_px);
  }

 private:
  ProceduralSpec m_spec;
  PyramidGeometry m_geometry;
};

}  // namespace

double proceduralHeight(const ProceduralSpec& spec, uint64_t x, uint64_t y) {
  double h = kBase;
  for (uint32_t o = 0; o < sizeof(kOctaves) / sizeof(kOctaves[0]); ++o) {
    const uint32_t s = kOctaves[o].cell_log2;
    const uint64_t cx = x >> s, cy = y >> s;
    const uint64_t mask = (uint64_t(1) << s) - 1;
    const double fx = smooth(double(x & mask) / double(uint64_t(1) << s));
    const double fy = smooth(double(y & mask) / double(uint64_t(1) << s));
    const double a = corner(spec.seed, o, cx, cy), b = corner(spec.seed, o, cx + 1, cy);
    const double c = corner(spec.seed, o, cx, cy + 1), d = corner(spec.seed, o, cx + 1, cy + 1);
    h += kOctaves[o].amplitude * ((a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy);
  }
  if ((x >> kCliffBandLog2) & 1) h += kCliff;
  return h;
}

std::shared_ptr<TileSource> makeProceduralHeightSource(const ProceduralSpec& spec) {
  if (spec.width_px == 0 || spec.height_px == 0 || spec.width_px > kMaxProceduralSidePx ||
      spec.height_px > kMaxProceduralSidePx)
    return nullptr;
  PyramidGeometry geometry;
  if (!makePyramidGeometry(spec.width_px, spec.height_px, spec.tile_px, PixelFormat::kF32, &geometry))
    return nullptr;
  return std::make_shared<ProceduralHeightSource>(spec, geometry);
}

}  // namespace clipstream
