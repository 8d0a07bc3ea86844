// Private: the terrain's height clip stack (TerrainRenderer, terrain.h).
// One R32F array texture, a layer per height level, each layer holding
// slots x slots tiles placed toroidally as in the colour stack: tile (x, y)
// of a level lives in slot (x mod slots, y mod slots), replacing whatever
// tile had that slot. Beside the texture, for the CPU: which tile each slot
// holds, a copy of its heights (the ground under the camera), its height
// bounds (culling) and, for the quadtree, the twist of its cells.
//
// Owned by the GL thread: create(), upload() and the destructor call GL;
// the const queries read only the CPU copies, and are called on that thread.
#pragma once

#include <clipstream/renderer/terrain.h>

#include <glm/glm.hpp>

#include <cstdint>
#include <memory>
#include <vector>

namespace clipstream {

class TerrainHeightStack {
 public:
  // Tiles per layer side for `config` over `heights` (pure). A ring spans
  // n + 1 samples plus one on each side for normals, which touches at most
  // ceil((n + 3) / tile) + 1 tiles a side; one more slot keeps a tile that
  // just left from sharing a slot with one needed. At least the streamer's
  // window plus two (as the colour stack), so no two tiles it hands over
  // share a slot. The full-resolution mesh keeps level 0 whole: one slot
  // per tile, so the toroidal period never wraps.
  static uint32_t slotsFor(const PyramidGeometry& heights, const TerrainConfig& config);

  // Allocates `layers` layers of slots x slots tiles of `heights`' tile
  // size, cleared to height 0, and the CPU bookkeeping for every level of
  // `heights`; with `gradients` (per-pixel lighting) also the gradients
  // texture. kUnavailable when the layer side exceeds
  // GL_MAX_TEXTURE_SIZE; kOutOfMemory / kUnavailable when GL cannot make it.
  static Status create(const PyramidGeometry& heights, uint32_t slots, uint32_t layers, bool gradients,
                       std::unique_ptr<TerrainHeightStack>* out);
  ~TerrainHeightStack();
  TerrainHeightStack(const TerrainHeightStack&) = delete;
  TerrainHeightStack& operator=(const TerrainHeightStack&) = delete;

  // Uploads tile `key` (tile_px^2 heights in store units; the caller checks
  // that the key is in the pyramid and its level has a layer) into its slot
  // and records it there: its heights and their bounds; with gradients,
  // also its samples' gradients and those of the samples beside it in the
  // neighbouring slots.
  void upload(const TileKey& key, const float* heights);
  // Records, for the tile just uploaded with `key`, the largest twist
  // |a - b - c + d| / 4 of its cells in each block of `block_cells` cells a
  // side (cells inside the tile only): the triangulated surface's distance
  // from the bilinear one the store's error bounds measure.
  void storeTwist(const TileKey& key, const float* heights, uint32_t block_cells);

  uint32_t slots() const { return m_slots; }
  uint32_t texture() const { return m_texture; }  // the R32F array texture's GL name
  // With gradients (else 0): an RG32F array texture laid out as
  // texture(), each sample's height differences across it in x and z
  // (clamped to the level), or kNoGradient where the tiles holding them are
  // not all in their slots. Kept true as slots change: an upload rewrites
  // its tile and the facing samples of the four slots beside it, so a
  // sample that is not kNoGradient has its right neighbours' heights.
  // Makes it (filled from the tiles held) unless it exists; kOutOfMemory /
  // kUnavailable when GL cannot.
  Status enableGradients();
  uint32_t gradientsTexture() const { return m_gradients_texture; }
  // A gradient whose heights are not all resident (or were not, when its
  // sample was written): far above any real one, so that a bilinear blend
  // with any weight on it stays above terrain_heights.glsl's
  // kNoGradientAbove, and finite, so that no blend overflows.
  static constexpr float kNoGradient = 1e30f;
  uint64_t textureBytes() const { return m_texture_bytes; }  // both textures

  // Whether level `level`'s slot of tile (tx, ty) holds that tile.
  bool holds(uint32_t level, int64_t tx, int64_t ty) const {
    return m_slot_tile[level][slotIndex(tx, ty)] == tileId(tx, ty);
  }
  // The held tile's (min, max) height, and its twist blocks (empty unless
  // storeTwist() ran for it). Only for a tile holds() says is there.
  glm::vec2 tileBounds(uint32_t level, int64_t tx, int64_t ty) const {
    return m_slot_bounds[level][slotIndex(tx, ty)];
  }
  const std::vector<float>& tileTwist(uint32_t level, int64_t tx, int64_t ty) const {
    return m_slot_twist[level][slotIndex(tx, ty)];
  }
  // The held tile's tile_px^2 heights, row-major; null when the slot does
  // not hold that tile.
  const float* tileHeights(uint32_t level, int64_t tx, int64_t ty) const {
    return holds(level, tx, ty) ? m_slot_heights[level][slotIndex(tx, ty)].data() : nullptr;
  }

  // Height of stored level `level`'s sample (i, j), clamped to the level,
  // from the resident tile; false when that tile is not resident.
  bool sample(uint32_t level, int64_t i, int64_t j, float* h) const;

  // Bounds (min, max) of the heights a ring of `ring_level` reads in its
  // level's samples [s0, s1] (inclusive, clamped to the level; a ring past
  // the pyramid's last level reads that level's samples 2^k apart), from the
  // resident tiles' bounds; (-inf, inf) when one of them is not resident.
  glm::vec2 heightBounds(uint32_t ring_level, glm::i64vec2 s0, glm::i64vec2 s1) const;

  // The samples of `level` (first x, first y, last x, last y) whose tiles
  // are all held: the largest block of held tiles grown from the one under
  // level-0 sample `camera` (clamped to the level), a row or column at a
  // time; a side on the level's edge reaches far beyond it (samples there
  // clamp to the edge). Empty (first > last) when that tile is not held.
  glm::i64vec4 residentSamples(uint32_t level, const glm::i64vec2& camera) const;

  // Whether every tile the ring of `ring_cells` at `ring_level` with vertex
  // (0, 0) at `ring_origin` reads is resident: its (n + 1)^2 vertices and
  // one more sample on each side (normals), clamped to the level.
  bool ringResident(uint32_t ring_level, const glm::i64vec2& ring_origin, uint32_t ring_cells) const;

 private:
  TerrainHeightStack() = default;
  static uint64_t tileId(int64_t tx, int64_t ty) { return uint64_t(tx) | (uint64_t(ty) << 32); }
  uint32_t slotOf(int64_t tile) const {
    const int64_t s = tile % int64_t(m_slots);
    return uint32_t(s < 0 ? s + m_slots : s);
  }
  size_t slotIndex(int64_t tx, int64_t ty) const { return size_t(slotOf(ty)) * m_slots + slotOf(tx); }
  // Computes and uploads the gradients of held tile (tx, ty)'s samples
  // [x0, x1] x [y0, y1] (within the tile).
  void writeGradients(uint32_t level, int64_t tx, int64_t ty, uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1);

  PyramidGeometry m_geometry;
  uint32_t m_slots = 0;    // tiles per layer side (the toroidal period in tiles)
  uint32_t m_layers = 0;   // levels with a layer (from level 0)
  uint32_t m_texture = 0;  // R32F array texture, a layer per level held
  uint32_t m_gradients_texture = 0;  // gradientsTexture()
  uint64_t m_texture_bytes = 0;
  // Per level, per slot: which tile it holds (tileId(), or kNoTile), a CPU
  // copy of its heights, their bounds (min, max) and its twist blocks.
  static constexpr uint64_t kNoTile = ~uint64_t(0);
  std::vector<std::vector<uint64_t>> m_slot_tile;
  std::vector<std::vector<std::vector<float>>> m_slot_heights;
  std::vector<std::vector<glm::vec2>> m_slot_bounds;
  std::vector<std::vector<std::vector<float>>> m_slot_twist;
};

}  // namespace clipstream
