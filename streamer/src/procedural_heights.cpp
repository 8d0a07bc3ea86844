// Procedural heights of planet size (up to 2^31 samples a side), generated
// per tile like the procedural texture: value noise over five octaves plus
// a 120-unit cliff every 2^14 samples, every sample a pure function of its
// level-0 coordinates (integer cell arithmetic, exact at any size).
#include <clipstream/streamer/tile_source.h>

#include <algorithm>
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
// tileHeightBounds(): octaves with fewer than this many cells across a tile
// per side are bounded cell by cell, the rest by their amplitude (at most
// 1024 octave values per octave and tile).
constexpr uint64_t kBoundCells = 16;

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

// Octave o's value in [-1, 1] at level-0 sample (x, y): its cell's corner
// values blended by the smoothstep of the position in the cell.
double octave(uint32_t seed, uint32_t o, uint64_t x, uint64_t y) {
  const uint32_t s = kOctaves[o].cell_log2;
  const uint64_t cx = x >> s, cy = y >> s;
  const uint64_t mask = (uint64_t(1) << s) - 1;
  const double fx = smooth(double(x & mask) / double(uint64_t(1) << s));
  const double fy = smooth(double(y & mask) / double(uint64_t(1) << s));
  const double a = corner(seed, o, cx, cy), b = corner(seed, o, cx + 1, cy);
  const double c = corner(seed, o, cx, cy + 1), d = corner(seed, o, cx + 1, cy + 1);
  return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy;
}

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

  // Bounds without sampling every sample: inside one cell an octave is
  // bilinear in the smoothsteps of x and y, which grow with x and y, so
  // over a rectangle of samples in the cell it is extreme at the
  // rectangle's corners. Each cell the tile touches gives its piece's four
  // corners; octaves whose cells are far smaller than the tile take their
  // full amplitude. Widened by one float step each way, since fetch()
  // rounds heights to float. The error of a coarse tile is not worked out:
  // the bounds' width stands for it (both surfaces lie between them).
  Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const override {
    *out = {};
    if (!m_geometry.contains(key))
      return Status::error(ErrorCode::kOutOfRange, "procedural heights: tile outside the pyramid");
    const uint64_t span = uint64_t(m_spec.tile_px) << key.level;  // level-0 samples a side
    const uint64_t x0 = uint64_t(key.x) * span, y0 = uint64_t(key.y) * span;
    const uint64_t x1 = std::min(x0 + span, m_spec.width_px) - 1;
    const uint64_t y1 = std::min(y0 + span, m_spec.height_px) - 1;
    double lo = kBase, hi = kBase;
    for (uint32_t o = 0; o < sizeof(kOctaves) / sizeof(kOctaves[0]); ++o) {
      const uint32_t s = kOctaves[o].cell_log2;
      const uint64_t cx0 = x0 >> s, cx1 = x1 >> s, cy0 = y0 >> s, cy1 = y1 >> s;
      double a = -1.0, b = 1.0;
      if (cx1 - cx0 < kBoundCells && cy1 - cy0 < kBoundCells) {
        a = INFINITY, b = -INFINITY;
        for (uint64_t cy = cy0; cy <= cy1; ++cy)
          for (uint64_t cx = cx0; cx <= cx1; ++cx) {
            const uint64_t xa = std::max(x0, cx << s), xb = std::min(x1, ((cx + 1) << s) - 1);
            const uint64_t ya = std::max(y0, cy << s), yb = std::min(y1, ((cy + 1) << s) - 1);
            for (const uint64_t x : {xa, xb})
              for (const uint64_t y : {ya, yb}) {
                const double v = octave(m_spec.seed, o, x, y);
                a = std::min(a, v), b = std::max(b, v);
              }
          }
      }
      lo += kOctaves[o].amplitude * a;
      hi += kOctaves[o].amplitude * b;
    }
    const uint64_t band0 = x0 >> kCliffBandLog2, band1 = x1 >> kCliffBandLog2;
    if (band0 == band1 && (band0 & 1)) lo += kCliff;
    if (band0 != band1 || (band0 & 1)) hi += kCliff;
    out->min_height = std::nextafter(float(lo), -INFINITY);
    out->max_height = std::nextafter(float(hi), INFINITY);
    out->error = key.level == 0 ? 0.0f : out->max_height - out->min_height;
    return okStatus();
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
    return okStatus();
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
  for (uint32_t o = 0; o < sizeof(kOctaves) / sizeof(kOctaves[0]); ++o)
    h += kOctaves[o].amplitude * octave(spec.seed, o, x, y);
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
