#include "terrain_detail.h"

#include <clipstream/renderer/config.h>

#include "gl.h"
#include "gl_util.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>

namespace clipstream {
namespace {

// A lattice value in [-1, 1] of noise `seed` at lattice point (x, y).
float latticeValue(uint32_t seed, uint32_t x, uint32_t y) {
  uint32_t h = seed * 0x9E3779B1u ^ x * 0x85EBCA77u ^ y * 0xC2B2AE3Du;
  h ^= h >> 15;
  h *= 0x2C1B3C6Du;
  h ^= h >> 12;
  h *= 0x297A2D39u;
  h ^= h >> 15;
  return float(h & 0xFFFFFFu) / float(0x7FFFFF) - 1.0f;
}

// Value noise of `cells` lattice cells across the tile at (u, v) in
// [0, 1): the lattice wraps, so the noise tiles.
float tileNoise(uint32_t seed, double u, double v, uint32_t cells) {
  const double x = u * cells, y = v * cells;
  const double fx = std::floor(x), fy = std::floor(y);
  const uint32_t x0 = uint32_t(fx) % cells, y0 = uint32_t(fy) % cells;
  const uint32_t x1 = (x0 + 1) % cells, y1 = (y0 + 1) % cells;
  auto smooth = [](double t) { return t * t * (3.0 - 2.0 * t); };
  const double tx = smooth(x - fx), ty = smooth(y - fy);
  const double a = latticeValue(seed, x0, y0), b = latticeValue(seed, x1, y0);
  const double c = latticeValue(seed, x0, y1), d = latticeValue(seed, x1, y1);
  return float((a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * ty);
}

// A material's noise: octaves of `cells` lattice cells and amplitudes;
// ridged takes 0.5 - |n| of each (crests and cracks, for rock).
struct Material {
  std::array<uint32_t, 4> cells;
  std::array<float, 4> amplitude;
  bool ridged;
};
// Grass: fine clumps and blades; soil: grain at every scale; rock: ridges
// and cracks; snow: faint, broad.
constexpr std::array<Material, 4> kMaterials = {{
    {{16, 32, 64, 128}, {0.05f, 0.10f, 0.09f, 0.07f}, false},
    {{8, 16, 32, 64}, {0.10f, 0.08f, 0.06f, 0.04f}, false},
    {{4, 8, 16, 32}, {0.30f, 0.18f, 0.12f, 0.07f}, true},
    {{4, 8, 16, 32}, {0.04f, 0.03f, 0.02f, 0.01f}, false},
}};

}  // namespace

std::vector<uint8_t> detailTextureTexels() {
  const uint32_t n = renderer_config::kDetailTexturePx;
  std::vector<uint8_t> texels(size_t(n) * n * 4);
  std::vector<double> values(size_t(n) * n);
  for (uint32_t m = 0; m < kMaterials.size(); ++m) {
    const Material& mat = kMaterials[m];
    double sum = 0.0;
    for (uint32_t y = 0; y < n; ++y)
      for (uint32_t x = 0; x < n; ++x) {
        double v = 0.0;
        for (size_t o = 0; o < mat.cells.size(); ++o) {
          const double noise = tileNoise(m * 16 + uint32_t(o) + 1, double(x) / n, double(y) / n, mat.cells[o]);
          v += mat.amplitude[o] * (mat.ridged ? 0.5 - std::abs(noise) : noise);
        }
        values[size_t(y) * n + x] = v;
        sum += v;
      }
    // Centred on 0.5 (a factor of 1 once doubled), then rounded.
    const double mean = sum / double(values.size());
    for (size_t i = 0; i < values.size(); ++i) {
      const double v = std::clamp(0.5 + values[i] - mean, 0.0, 1.0);
      texels[i * 4 + m] = uint8_t(std::lround(v * 255.0));
    }
  }
  return texels;
}

Status TerrainDetailTexture::create(std::unique_ptr<TerrainDetailTexture>* out) {
  out->reset();
  std::unique_ptr<TerrainDetailTexture> t(new TerrainDetailTexture());
  const uint32_t n = renderer_config::kDetailTexturePx;
  const std::vector<uint8_t> texels = detailTextureTexels();
  const int mips = std::bit_width(n);
  gl_util::clearErrors();
  glCreateTextures(GL_TEXTURE_2D, 1, &t->m_texture);
  glTextureStorage2D(t->m_texture, mips, GL_RGBA8, GLsizei(n), GLsizei(n));
  glTextureSubImage2D(t->m_texture, 0, 0, 0, GLsizei(n), GLsizei(n), GL_RGBA, GL_UNSIGNED_BYTE, texels.data());
  glGenerateTextureMipmap(t->m_texture);
  glTextureParameteri(t->m_texture, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTextureParameteri(t->m_texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(t->m_texture, GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTextureParameteri(t->m_texture, GL_TEXTURE_WRAP_T, GL_REPEAT);
  t->m_bytes = uint64_t(n) * n * 4 * 4 / 3;
  if (Status s = gl_util::checkCreated("the terrain's detail texture"); !s) return s;
  *out = std::move(t);
  return okStatus();
}

TerrainDetailTexture::~TerrainDetailTexture() { glDeleteTextures(1, &m_texture); }

}  // namespace clipstream
