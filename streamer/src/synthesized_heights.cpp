// Synthesized relief below a DEM's resolution (makeSynthesizedHeightSource(),
// docs/terrain.md "Synthesized relief"): a height source with `levels` more
// levels below the DEM's level 0, whose samples are the DEM's surface
// (bilinear across each DEM cell) plus fractal value noise that vanishes at
// the DEM's own samples, scaled by the DEM's local roughness. Every sample
// is a pure function of its position, so tiles meet without a seam, the
// same tile is the same bytes every time, and each coarser level is the
// decimation of the finer (level `levels` is the DEM's level 0 itself).
#include <clipstream/streamer/tile_source.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <string>
#include <unordered_map>

namespace clipstream {
namespace {

uint64_t mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// A value in [-1, 1] for lattice corner (cx, cy) of octave o.
double corner(uint32_t o, int64_t cx, int64_t cy) {
  const uint64_t h = mix(mix(uint64_t(o) ^ mix(uint64_t(cx))) ^ (uint64_t(cy) * 0xD6E8FEB86659FD93ull));
  return double(h >> 11) * (2.0 / 9007199254740992.0) - 1.0;
}

class SynthesizedHeightSource final : public TileSource {
 public:
  SynthesizedHeightSource(std::shared_ptr<TileSource> dem, uint32_t levels, const PyramidGeometry& geometry)
      : m_dem(std::move(dem)), m_levels(levels), m_geometry(geometry) {}

  const PyramidGeometry& geometry() const override { return m_geometry; }
  TileContent content() const override { return TileContent::kHeightF32; }
  ElevationInfo elevationInfo() const override {
    ElevationInfo e = m_dem->elevationInfo();
    const double reach = kRoughnessScale * (e.max_height - e.min_height) * kDetailReach;
    e.min_height -= reach;
    e.max_height += reach;
    return e;
  }
  std::string describe() const override {
    return "synthesized:" + std::to_string(m_levels) + "-levels:" + m_dem->describe();
  }

  // The DEM's bounds under the footprint widened by the most the detail
  // can add there: the largest roughness of the DEM's samples under it
  // (read from the DEM's level-0 tiles, once each), or, over more than
  // kRoughnessTiles of them, the range of its heights (which bounds any
  // sample's roughness).
  Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const override {
    *out = {};
    if (!m_geometry.contains(key))
      return Status::error(ErrorCode::kOutOfRange, describe() + ": tile outside the pyramid");
    TileHeightBounds b;
    if (key.level >= m_levels) {
      if (Status s = m_dem->tileHeightBounds({key.level - m_levels, key.x, key.y}, &b); !s) return s;
    } else {
      b.min_height = INFINITY, b.max_height = -INFINITY;
      b.error = 0.0f;  // the DEM's level 0 has no finer surface
    }
    // The DEM's level-0 tiles under the footprint (one DEM sample more each
    // side: the cells at the footprint's edges reach them).
    const PyramidGeometry& dg = m_dem->geometry();
    const LevelInfo& l0 = dg.levels[0];
    const int64_t span = int64_t(m_geometry.tile_px) << key.level;  // synthesized level-0 samples
    auto tileOf = [&](int64_t s, uint64_t size) {
      return uint32_t(std::clamp<int64_t>(s, 0, int64_t(size) - 1) / dg.tile_px);
    };
    const uint32_t tx0 = tileOf((int64_t(key.x) * span >> m_levels) - 1, l0.width_px);
    const uint32_t ty0 = tileOf((int64_t(key.y) * span >> m_levels) - 1, l0.height_px);
    const uint32_t tx1 = tileOf(((int64_t(key.x) + 1) * span >> m_levels) + 1, l0.width_px);
    const uint32_t ty1 = tileOf(((int64_t(key.y) + 1) * span >> m_levels) + 1, l0.height_px);
    double rough = 0.0;
    const bool exact = uint64_t(tx1 - tx0 + 1) * (ty1 - ty0 + 1) <= kRoughnessTiles;
    for (uint32_t ty = ty0; ty <= ty1; ++ty)
      for (uint32_t tx = tx0; tx <= tx1; ++tx) {
        if (key.level < m_levels) {
          TileHeightBounds t;
          if (Status s = m_dem->tileHeightBounds({0, tx, ty}, &t); !s) return s;
          b.min_height = std::min(b.min_height, t.min_height);
          b.max_height = std::max(b.max_height, t.max_height);
        }
        if (!exact) continue;
        double r = 0.0;
        if (Status s = tileRoughness(tx, ty, &r); !s) return s;
        rough = std::max(rough, r);
      }
    if (!exact) rough = double(b.max_height - b.min_height);
    const double reach = kRoughnessScale * rough * kDetailReach;
    out->min_height = float(b.min_height - reach);
    out->max_height = float(b.max_height + reach);
    out->error = float(b.error + 2.0 * reach);
    return okStatus();
  }

  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    if (!m_geometry.contains(key))
      return Status::error(ErrorCode::kOutOfRange, describe() + ": tile outside the pyramid");
    if (key.level >= m_levels) return m_dem->fetch({key.level - m_levels, key.x, key.y}, rgba);
    const uint32_t t = m_geometry.tile_px;
    const LevelInfo& info = m_geometry.levels[key.level];
    // The DEM's samples the tile reads: its cells' corners and their
    // neighbours (roughness).
    const int64_t step = int64_t(1) << key.level;  // synthesized level-0 samples a sample
    const int64_t x0 = int64_t(key.x) * t, y0 = int64_t(key.y) * t;
    const int64_t last_x = int64_t(info.width_px) - 1, last_y = int64_t(info.height_px) - 1;
    const int64_t fx0 = (std::min(x0, last_x) * step >> m_levels) - 1;
    const int64_t fy0 = (std::min(y0, last_y) * step >> m_levels) - 1;
    const int64_t fx1 = (std::min(x0 + t - 1, last_x) * step >> m_levels) + 2;
    const int64_t fy1 = (std::min(y0 + t - 1, last_y) * step >> m_levels) + 2;
    Patch patch;
    if (Status s = readDem(fx0, fy0, fx1, fy1, &patch); !s) return s;
    rgba->resize(size_t(t) * t * 4);
    float* out = reinterpret_cast<float*>(rgba->data());
    for (uint32_t y = 0; y < t; ++y)
      for (uint32_t x = 0; x < t; ++x) {
        // Samples past the level's edge repeat its last (as the tiler pads).
        const int64_t sx = std::min(x0 + x, last_x) * step, sy = std::min(y0 + y, last_y) * step;
        out[size_t(y) * t + x] = float(height(patch, sx, sy));
      }
    return okStatus();
  }

 private:
  // Of the detail's fractal noise (octaves of cells of 1/2, 1/4, ... DEM
  // cells, amplitudes halving, summing to 1): how far it strays from its
  // bilinear interpolation at the DEM's samples, at most.
  static constexpr double kDetailReach = 2.0;
  // The detail's amplitude per unit of local roughness (a sample's largest
  // distance from the mean of its two neighbours along x or y): half of
  // it, so that ground as rough as the DEM's own curvature gets detail of
  // about that size between its samples.
  static constexpr double kRoughnessScale = 0.5;
  // tileHeightBounds() reads the roughness of at most this many DEM tiles
  // a tile (the coarse levels' tiles bound it by their range instead).
  static constexpr uint64_t kRoughnessTiles = 64;

  // The largest roughness() of DEM level-0 tile (tx, ty)'s samples,
  // computed once (its tile and neighbours' edges read).
  Status tileRoughness(uint32_t tx, uint32_t ty, double* out) const {
    const uint64_t id = uint64_t(tx) | uint64_t(ty) << 32;
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      if (auto it = m_roughness.find(id); it != m_roughness.end()) {
        *out = it->second;
        return okStatus();
      }
    }
    const PyramidGeometry& dg = m_dem->geometry();
    const int64_t tp = dg.tile_px;
    const int64_t x0 = int64_t(tx) * tp, y0 = int64_t(ty) * tp;
    const int64_t x1 = std::min<int64_t>(x0 + tp, int64_t(dg.levels[0].width_px)) - 1;
    const int64_t y1 = std::min<int64_t>(y0 + tp, int64_t(dg.levels[0].height_px)) - 1;
    Patch patch;
    if (Status s = readDem(x0 - 1, y0 - 1, x1 + 1, y1 + 1, &patch); !s) return s;
    double r = 0.0;
    for (int64_t j = y0; j <= y1; ++j)
      for (int64_t i = x0; i <= x1; ++i) r = std::max(r, roughness(patch, i, j));
    std::lock_guard<std::mutex> lock(m_mutex);
    m_roughness[id] = r;
    *out = r;
    return okStatus();
  }

  // DEM level-0 heights over samples [x0, x1] x [y0, y1], clamped to the
  // DEM (as the renderer clamps).
  struct Patch {
    int64_t x0 = 0, y0 = 0, w = 0, h = 0;
    int64_t dem_w = 0, dem_h = 0;  // the DEM's level 0
    std::vector<double> heights;
    double at(int64_t i, int64_t j) const {
      return heights[size_t(std::clamp<int64_t>(j - y0, 0, h - 1) * w + std::clamp<int64_t>(i - x0, 0, w - 1))];
    }
  };
  Status readDem(int64_t x0, int64_t y0, int64_t x1, int64_t y1, Patch* p) const {
    const PyramidGeometry& dg = m_dem->geometry();
    const LevelInfo& l0 = dg.levels[0];
    const int64_t tp = dg.tile_px, W = int64_t(l0.width_px), H = int64_t(l0.height_px);
    p->x0 = x0, p->y0 = y0, p->w = x1 - x0 + 1, p->h = y1 - y0 + 1;
    p->dem_w = W, p->dem_h = H;
    p->heights.assign(size_t(p->w * p->h), 0.0);
    const int64_t tx0 = std::clamp<int64_t>(x0, 0, W - 1) / tp, tx1 = std::clamp<int64_t>(x1, 0, W - 1) / tp;
    const int64_t ty0 = std::clamp<int64_t>(y0, 0, H - 1) / tp, ty1 = std::clamp<int64_t>(y1, 0, H - 1) / tp;
    std::vector<uint8_t> bytes;
    for (int64_t ty = ty0; ty <= ty1; ++ty)
      for (int64_t tx = tx0; tx <= tx1; ++tx) {
        if (Status s = m_dem->fetch({0, uint32_t(tx), uint32_t(ty)}, &bytes); !s) return s;
        const float* f = reinterpret_cast<const float*>(bytes.data());
        for (int64_t j = y0; j <= y1; ++j) {
          const int64_t cj = std::clamp<int64_t>(j, 0, H - 1);
          if (cj / tp != ty) continue;
          for (int64_t i = x0; i <= x1; ++i) {
            const int64_t ci = std::clamp<int64_t>(i, 0, W - 1);
            if (ci / tp != tx) continue;
            p->heights[size_t((j - y0) * p->w + (i - x0))] = f[size_t((cj - ty * tp) * tp + (ci - tx * tp))];
          }
        }
      }
    return okStatus();
  }

  // The fractal noise at synthesized level-0 sample (x, y): octave o has
  // cells of 2^(levels - o) samples (o = 1..levels: half a DEM cell down to
  // one sample), amplitude 2^-o normalised to a sum of 1.
  double noise(int64_t x, int64_t y) const {
    double sum = 0.0, norm = 0.0;
    for (uint32_t o = 1; o <= m_levels; ++o) {
      const uint32_t s = m_levels - o;
      const int64_t cx = x >> s, cy = y >> s, cell = int64_t(1) << s;
      const double fx = double(x - (cx << s)) / double(cell), fy = double(y - (cy << s)) / double(cell);
      const double a = corner(o, cx, cy), b = corner(o, cx + 1, cy);
      const double c = corner(o, cx, cy + 1), d = corner(o, cx + 1, cy + 1);
      const double v = (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy;
      const double amplitude = std::ldexp(1.0, -int(o));
      sum += amplitude * v;
      norm += amplitude;
    }
    return sum / norm;
  }

  // A DEM sample's roughness: its largest distance from the mean of its
  // two neighbours along x or along y (an axis without both neighbours in
  // the DEM counts 0: the edge's clamp is no relief). Samples outside the
  // DEM take the edge's.
  static double roughness(const Patch& p, int64_t i, int64_t j) {
    i = std::clamp<int64_t>(i, 0, p.dem_w - 1);
    j = std::clamp<int64_t>(j, 0, p.dem_h - 1);
    const double h = p.at(i, j);
    const double along_x = i > 0 && i + 1 < p.dem_w ? std::abs(h - 0.5 * (p.at(i - 1, j) + p.at(i + 1, j))) : 0.0;
    const double along_y = j > 0 && j + 1 < p.dem_h ? std::abs(h - 0.5 * (p.at(i, j - 1) + p.at(i, j + 1))) : 0.0;
    return std::max(along_x, along_y);
  }

  // The synthesized height at level-0 sample (x, y): the DEM's cell
  // bilinear, plus the noise less its own bilinear across the cell (0 at
  // the DEM's samples) times the cell's roughness, bilinear.
  double height(const Patch& p, int64_t x, int64_t y) const {
    const int64_t n = int64_t(1) << m_levels;
    const int64_t i = x >> m_levels, j = y >> m_levels;
    const double fx = double(x - i * n) / double(n), fy = double(y - j * n) / double(n);
    auto bilinear = [&](double a, double b, double c, double d) {
      return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy;
    };
    const double base = bilinear(p.at(i, j), p.at(i + 1, j), p.at(i, j + 1), p.at(i + 1, j + 1));
    if (fx == 0.0 && fy == 0.0) return base;  // a DEM sample: the data, exactly
    const double detail = noise(x, y) - bilinear(noise(i * n, j * n), noise((i + 1) * n, j * n),
                                                  noise(i * n, (j + 1) * n), noise((i + 1) * n, (j + 1) * n));
    const double amplitude = kRoughnessScale * bilinear(roughness(p, i, j), roughness(p, i + 1, j),
                                                        roughness(p, i, j + 1), roughness(p, i + 1, j + 1));
    return base + amplitude * detail;
  }

  std::shared_ptr<TileSource> m_dem;
  uint32_t m_levels;
  PyramidGeometry m_geometry;
  mutable std::mutex m_mutex;  // guards m_roughness (bounds are asked from any thread)
  mutable std::unordered_map<uint64_t, double> m_roughness;  // tileRoughness() by DEM tile
};

}  // namespace

std::shared_ptr<TileSource> makeSynthesizedHeightSource(std::shared_ptr<TileSource> dem, uint32_t levels,
                                                         Status* status) {
  *status = okStatus();
  if (!dem || dem->content() != TileContent::kHeightF32) {
    *status = Status::error(ErrorCode::kInvalidArgument, "synthesized relief: the source is not a height source");
    return nullptr;
  }
  if (levels < 1 || levels > kMaxSynthesizedLevels) {
    *status = Status::error(ErrorCode::kInvalidArgument, "synthesized relief: " + std::to_string(levels) +
                                                             " levels: must be 1 to " +
                                                             std::to_string(kMaxSynthesizedLevels));
    return nullptr;
  }
  const PyramidGeometry& g = dem->geometry();
  const uint64_t w = ((g.width_px - 1) << levels) + 1, h = ((g.height_px - 1) << levels) + 1;
  PyramidGeometry geometry;
  if (!makePyramidGeometry(w, h, g.tile_px, PixelFormat::kF32, &geometry) ||
      geometry.levelCount() != g.levelCount() + levels) {
    *status = Status::error(ErrorCode::kInvalidArgument,
                            "synthesized relief: " + dem->describe() + " cannot take " + std::to_string(levels) +
                                " more levels (" + std::to_string(w) + "x" + std::to_string(h) + " samples)");
    return nullptr;
  }
  return std::make_shared<SynthesizedHeightSource>(std::move(dem), levels, geometry);
}

}  // namespace clipstream
