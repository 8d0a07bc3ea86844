// CPU side of the GPU clipmap: the toroidal slot rule and the per-tile
// "usable" map the shader consults. Pure functions over plain data (no GL),
// so they are unit-tested directly.
//
// Thread-safe: pure functions only.
#pragma once

#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/streamer.h>

#include <cstdint>
#include <vector>

namespace clipstream {

// THE toroidal slot rule: tile column (or row) `tile` of a stack level lives
// in slot tile mod clip_tiles (always in [0, clip_tiles), also for negative
// tiles). A window of clip_tiles consecutive tiles therefore maps one-to-one
// onto the slots, and moving it by k tiles rewrites only k columns/rows. The
// ground shader mirrors this rule (imod in ground.frag); the GPU tests check
// that both agree.
inline uint32_t toroidalSlot(int64_t tile, uint32_t clip_tiles) {
  const int64_t c = int64_t(clip_tiles);
  const int64_t r = tile % c;
  return uint32_t(r < 0 ? r + c : r);
}

// What the GPU's usable map holds for a window tile: 1 + px + 4 py, where
// px and py are (tile / slots) mod 4 on each axis, so 1..kUsableCodeMax.
// The shader recomputes it from the fragment's tile, so a tile outside the
// window that shares the slot of a usable one (1 to 3 slot periods away)
// does not match. 0 = no window tile there.
inline constexpr uint8_t kUsableCodeMax = 16;
inline uint8_t usableCode(int64_t tile_x, int64_t tile_y, uint32_t slots) {
  const int64_t s = int64_t(slots);
  const int64_t px = (tile_x >= 0 ? tile_x / s : (tile_x - s + 1) / s) & 3;
  const int64_t py = (tile_y >= 0 ? tile_y / s : (tile_y - s + 1) / s) & 3;
  return uint8_t(1 + px + 4 * py);
}

// Calls fn(x, y, slot, code) for every tile of `window`, row by row: slot =
// toroidalSlot(y) * slots + toroidalSlot(x), code = usableCode(x, y). Each
// row's and column's divisions are done once, not once a tile (the
// usable and indirection maps are rebuilt from every window tile whenever
// they change, most frames of a moving flight).
template <typename Fn>
void forEachWindowSlot(const TileRect& window, uint32_t slots, Fn&& fn) {
  const int64_t w = window.width();
  if (w == 0 || window.height() == 0) return;
  std::vector<uint32_t> column(size_t(w), 0);
  std::vector<uint8_t> column_code(size_t(w), 0);
  for (int64_t x = window.x0; x < window.x1; ++x) {
    column[size_t(x - window.x0)] = toroidalSlot(x, slots);
    column_code[size_t(x - window.x0)] = uint8_t(usableCode(x, 0, slots) - 1);  // px
  }
  for (int64_t y = window.y0; y < window.y1; ++y) {
    const size_t row = size_t(toroidalSlot(y, slots)) * slots;
    const uint8_t row_code = usableCode(0, y, slots);  // 1 + 4 py
    for (int64_t x = window.x0; x < window.x1; ++x) {
      const size_t j = size_t(x - window.x0);
      fn(x, y, row + column[j], uint8_t(row_code + column_code[j]));
    }
  }
}

// Which slot of every stack level may be sampled, as the shader sees it:
// usable[level][slot_y * clip_tiles + slot_x] != 0. A tile is usable when
//  - it lies in the level's window and is resident,
//  - each of its 8 neighbours inside the level's tile grid is also in the
//    window and resident (the bilinear footprint of any point of the tile
//    stays on valid texels, so no seam can show a stale slot), and
//  - its parent tile on the next coarser stack level is usable (so the
//    trilinear blend towards the coarser level is valid too; the level at
//    pyramid_level is always complete).
// `residency` lists stack levels (any order, missing levels = nothing
// resident); levels >= pyramid_level are ignored.
// `finest` answers the shader's fallback question in one lookup: for the
// window tile in each slot, the finest level >= this one whose ancestor of
// that tile is usable (walking up through the coarser windows), or
// pyramid_level when none is.
struct UsableMap {
  uint32_t clip_tiles = 0;
  uint32_t pyramid_level = 0;
  std::vector<TileRect> windows;            // per stack level (empty rect = none)
  std::vector<std::vector<uint8_t>> usable; // per stack level, clip_tiles^2 slots
  std::vector<std::vector<uint8_t>> finest; // per stack level, clip_tiles^2 slots
};
UsableMap computeUsableMap(const PyramidGeometry& geometry, uint32_t clip_tiles,
                           uint32_t pyramid_level, const std::vector<LevelResidency>& residency);

}  // namespace clipstream
