// Private: the terrain's detail textures (TerrainConfig::detail_textures,
// docs/terrain.md "Detail textures"): one tiling RGBA8 texture, a material a
// channel (grass, soil, rock, snow), each a luminance around 0.5 that the
// shader doubles into a factor around 1 on the colour, made from tileable
// value noise: the same bytes on every run and machine.
//
// detailTextureTexels() is pure (any thread); TerrainDetailTexture is owned
// by the GL thread (its constructor and destructor call GL).
#pragma once

#include <clipstream/store/types.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace clipstream {

// The texture's renderer_config::kDetailTexturePx^2 texels, RGBA, row by
// row: every channel tiles (its last column and row meet its first) and
// averages 127.5 to within half a step, so its coarsest mip leaves the
// colour as it is.
std::vector<uint8_t> detailTextureTexels();

class TerrainDetailTexture {
 public:
  // Uploads detailTextureTexels() with its mip chain (repeat, trilinear);
  // kOutOfMemory / kUnavailable when GL cannot.
  static Status create(std::unique_ptr<TerrainDetailTexture>* out);
  ~TerrainDetailTexture();
  TerrainDetailTexture(const TerrainDetailTexture&) = delete;
  TerrainDetailTexture& operator=(const TerrainDetailTexture&) = delete;

  uint32_t texture() const { return m_texture; }
  uint64_t bytes() const { return m_bytes; }  // video memory, mips included

 private:
  TerrainDetailTexture() = default;
  uint32_t m_texture = 0;
  uint64_t m_bytes = 0;
};

}  // namespace clipstream
