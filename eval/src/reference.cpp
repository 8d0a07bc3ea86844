// The CPU reference renderer. See reference.h.
#include <clipstream/eval/reference.h>

#include <clipstream/renderer/config.h>
#include <clipstream/streamer/bc1.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <tuple>

namespace clipstream {
namespace {

struct Ray {
  glm::dvec3 forward, right, up;
  double sx = 0, sy = 0;  // ndc scale
  double w = 1, h = 1;
};

// Camera-relative ground point of pixel centre (px, py); false if the ray
// does not go down. Mirrors groundRel() in ground_ray.glsl.
bool rel(const Ray& r, const Camera& cam, double px, double py, glm::dvec2* out) {
  const double nx = 2.0 * px / r.w - 1.0, ny = 1.0 - 2.0 * py / r.h;
  const glm::dvec3 dir = r.forward + r.right * (nx * r.sx) + r.up * (ny * r.sy);
  if (-dir.y <= 1e-12 || cam.position.y <= 0.0) return false;
  const double t = cam.position.y / -dir.y;
  *out = {dir.x * t, dir.z * t};
  return true;
}

void bilinear(const PyramidGeometry& g, const TexelFunction& texel, uint32_t level, double u0,
              double v0, double out[4]) {
  const double scale = std::ldexp(1.0, -int(level));
  const double cx = u0 * scale - 0.5, cy = v0 * scale - 0.5;
  const double fx = std::floor(cx), fy = std::floor(cy);
  const double wx = cx - fx, wy = cy - fy;
  const int64_t max_x = int64_t(g.levels[level].tiles_x) * g.tile_px - 1;
  const int64_t max_y = int64_t(g.levels[level].tiles_y) * g.tile_px - 1;
  double acc[4] = {0, 0, 0, 0};
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const int64_t x = std::clamp<int64_t>(int64_t(fx) + i, 0, max_x);
      const int64_t y = std::clamp<int64_t>(int64_t(fy) + j, 0, max_y);
      uint8_t px[4];
      texel(level, uint64_t(x), uint64_t(y), px);
      const double w = (i ? wx : 1.0 - wx) * (j ? wy : 1.0 - wy);
      for (int c = 0; c < 4; ++c) acc[c] += w * px[c];
    }
  }
  for (int c = 0; c < 4; ++c) out[c] = acc[c];
}

}  // namespace

void renderReference(const PyramidGeometry& geometry, const TexelFunction& texel,
                     const Camera& camera, const Viewport& viewport,
                     const ReferenceOptions& options, std::vector<uint8_t>* rgba) {
  const uint32_t W = viewport.width_px, H = viewport.height_px;
  rgba->assign(size_t(W) * H * 4, 0);
  Ray r;
  r.forward = camera.forward();
  r.right = camera.right();
  r.up = camera.up();
  r.sy = std::tan(camera.vfov_rad * 0.5);
  r.sx = r.sy * double(W) / double(std::max(H, 1u));
  r.w = W;
  r.h = H;
  const double max_lod = double(geometry.levelCount() - 1);
  const double min_lod = std::min(double(options.min_level), max_lod);
  for (uint32_t py = 0; py < H; ++py) {
    for (uint32_t px = 0; px < W; ++px) {
      uint8_t* out = rgba->data() + (size_t(py) * W + px) * 4;
      std::copy_n(renderer_config::kSkyRgba, 4, out);
      glm::dvec2 p;
      if (!rel(r, camera, px + 0.5, py + 0.5, &p)) continue;
      const double u0 = camera.position.x + p.x, v0 = camera.position.z + p.y;
      if (u0 < 0 || v0 < 0 || u0 >= double(geometry.width_px) || v0 >= double(geometry.height_px))
        continue;
      // Derivatives as a GPU quad forms them: GL rows count from the
      // bottom, quads pair rows (0,1), (2,3)... of that count.
      const uint32_t gl_row = H - 1 - py;
      const uint32_t qx = px & ~1u, q_gl_row = gl_row & ~1u;
      const double top_py = double(H - 1 - q_gl_row) + 0.5;  // quad's first GL row, top-left coords
      glm::dvec2 a, b, c, d;
      double lambda = std::numeric_limits<double>::infinity();
      if (rel(r, camera, qx + 0.5, py + 0.5, &a) && rel(r, camera, qx + 1.5, py + 0.5, &b) &&
          rel(r, camera, px + 0.5, top_py, &c) && rel(r, camera, px + 0.5, top_py - 1.0, &d)) {
        const double rho = std::max(glm::length(b - a), glm::length(d - c));
        lambda = std::log2(std::max(rho, 1e-30));
      }
      const double lod = std::clamp(lambda, min_lod, max_lod);
      const uint32_t level = uint32_t(std::floor(lod));
      const double f = lod - level;
      double ca[4], cb[4] = {0, 0, 0, 0};
      bilinear(geometry, texel, level, u0, v0, ca);
      if (f > 0.0 && level + 1 < geometry.levelCount())
        bilinear(geometry, texel, level + 1, u0, v0, cb);
      // Premultiplied alpha over the sky colour, as the ground shader
      // composites it (a no-data texel is black under alpha 0).
      const double cover = (ca[3] * (1.0 - f) + cb[3] * f) / 255.0;
      for (int k = 0; k < 3; ++k) {
        const double v = ca[k] * (1.0 - f) + cb[k] * f + (1.0 - cover) * renderer_config::kSkyRgba[k];
        out[k] = uint8_t(std::clamp(std::lround(v), 0l, 255l));
      }
      out[3] = 255;
    }
  }
}

TexelFunction texelsFromSource(std::shared_ptr<TileSource> source) {
  struct Cache {
    std::mutex mutex;
    std::map<std::tuple<uint32_t, uint32_t, uint32_t>, std::vector<uint8_t>> tiles;
  };
  auto cache = std::make_shared<Cache>();
  return [source, cache](uint32_t level, uint64_t x, uint64_t y, uint8_t rgba[4]) {
    const uint32_t tp = source->geometry().tile_px;
    const TileKey key{level, uint32_t(x / tp), uint32_t(y / tp)};
    std::lock_guard<std::mutex> lock(cache->mutex);
    auto it = cache->tiles.find({key.level, key.x, key.y});
    if (it == cache->tiles.end()) {
      std::vector<uint8_t> px;
      if (!source->fetch(key, &px)) px.clear();
      // BC1 tiles are decoded here: the texels are what the GPU samples.
      if (!px.empty() && source->content() == TileContent::kBc1) {
        std::vector<uint8_t> blocks = std::move(px);
        if (!decodeBc1Tile(blocks, tp, &px)) px.clear();
      }
      it = cache->tiles.emplace(std::make_tuple(key.level, key.x, key.y), std::move(px)).first;
    }
    if (it->second.empty()) {
      rgba[0] = 255, rgba[1] = 0, rgba[2] = 255, rgba[3] = 255;
      return;
    }
    const uint8_t* p = it->second.data() + ((y % tp) * tp + (x % tp)) * 4;
    std::copy_n(p, 4, rgba);
  };
}

}  // namespace clipstream
