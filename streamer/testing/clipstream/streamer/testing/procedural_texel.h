// The procedural source's texels one at a time, for CPU references in tests
// and benchmarks (makeProceduralSource(), tile_source.h). Part of the
// streamer library but not installed: a host streams the source, it does
// not recompute it. Thread-safe (a pure function).
#pragma once

#include <clipstream/streamer/tile_source.h>

#include <cstdint>

namespace clipstream {

// The RGBA8 value the procedural source gives texel (tx, ty) of `level`.
// Definition: six layers of hashed colours over aligned square cells of
// 8, 16, 32, 64, 128 and 256 texels of this level, weights 2,2,3,3,4,4
// (so every 8x8 block differs from its neighbours). A cell is identified by its size and
// position in level-0 texels, so a cell of level l+1 is the same cell (same
// colour) as the one covering the same ground at level l: levels agree on
// structure, and a coarser level looks like a smoothed finer one (it drops
// the finest layer). Texels on a tile boundary of their level (x or y a
// multiple of tile_px) are darkened to half, drawing the tile grid.
// Alpha is always 255.
void proceduralTexel(const ProceduralSpec& spec, uint32_t level, uint64_t tx, uint64_t ty,
                     uint8_t rgba[4]);

}  // namespace clipstream
