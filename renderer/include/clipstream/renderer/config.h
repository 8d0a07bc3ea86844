// Renderer tunables in one place, each with the reason for its value. The
// shaders receive the ones they need as #defines (gl_util.cpp, buildGroundProgram), so the
// C++ and GLSL sides can never disagree.
//
// Thread-safe: constants only.
#pragma once

#include <cstdint>

namespace clipstream::renderer_config {

// Uniform arrays in the ground shader are sized for this many pyramid
// levels; 2^31 texels a side at 128-px tiles needs 25, so 32 leaves room.
inline constexpr uint32_t kMaxLevels = 32;

// Tiles uploaded per frame when the caller does not say: 16 tiles of 128^2
// RGBA8 are 1 MiB, about 1.5 ms of glTexSubImage3D on llvmpipe.
inline constexpr uint32_t kDefaultUploadTilesPerFrame = 16;

// Buffering::kStaged: regions in the staging ring. A frame's region is
// written again kStagingFrames frames later: by then the frame that
// uploaded from it was drawn and, with one frame queued behind the one
// being filled, its copies ran (the wait before reuse is a fence, never a
// guess).
inline constexpr uint32_t kStagingFrames = 3;

// TextureMemory::kPaged: the pool's size when the caller does not say, in
// pages per tile-sized area of the screen (defaultPoolBytes()). The most
// pages a frame of the sweep's line and turn flights needed (no frame
// short of a page) was 4.4, 3.0, 4.7 and 5.4 per screen tile at 1280x720,
// 1920x1080, 2560x1440 and 3840x2160 (docs/benchmarks.md, "Paged texture
// memory"); 5.5 covers every one, and at 1920x1080 comes to 59 MiB of
// RGBA8 pages.
inline constexpr double kDefaultPoolPagesPerScreenTile = 5.5;
// ... and never fewer than this many pages: what a frame needs does not
// shrink with the screen below a point (the pinned pyramid's 21 pages, a
// tile ahead and the ancestors on every level, the neighbours filtering
// reads). Small views needed 50 to 146 (160x96 to 640x360, the pass at
// x100 and the line at x1); 256 pages are 21 MiB of RGBA8.
inline constexpr uint32_t kPoolMinPages = 256;
// kPaged: the pyramid (levels pinned in the pool, the fallback of every
// other level) is every level at most this many tiles a side: 4 pins 21
// pages of a square image (16 + 4 + 1), where the clip-sized pyramid of
// the stack would pin a clip's worth (1,365 pages at 1920x1080).
inline constexpr uint32_t kPagedPyramidTiles = 4;
// kPaged: texels of border around a tile in its page. Bilinear filtering
// reads one texel past the tile at mip 0 and one past it at mip 1, which
// has half the border: RGBA8 needs 2. BC1 copies whole 4x4 blocks, and
// mip 1's border must be a block too: 8.
inline constexpr uint32_t kPageBorderRgba8 = 2;
inline constexpr uint32_t kPageBorderBc1 = 8;

// The simulated clock of a Flight (flight.h): every step advances the
// streamer's clock, and a scripted path's time, by this much whatever the
// real render time, so runs are deterministic.
inline constexpr double kSimulatedFrameSeconds = 1.0 / 60.0;

// Geometry clipmap (terrain.h): cells per ring side. 128 cells of 2^L
// samples put the ring's outer edge about 64 cells away, where a cell
// spans about 10 px at 1280x720 and 60 degrees: fine enough for the
// 1-px geometric error target on real DEMs, while 10 rings stay under
// 250,000 triangles (docs/terrain.md has the measurements).
inline constexpr uint32_t kTerrainRingCells = 128;
// A ring's transition band is its cells / this (Losasso & Hoppe's w = n / 10).
inline constexpr uint32_t kTerrainTransitionDivisor = 10;
// Quadtree terrain (terrain.h, TerrainMethod::kQuadtree): cells per node
// side. A node is 128 triangles, drawn as an instance (one draw call per
// edge pattern). 8 cells follow rough ground closer than 16: on the terrain
// sweep's St Helens orbit (1280x720) 14.6k / 17.2k triangles at 10 / 8 px
// gave p95 1.06 / 0.94 px where 16-cell nodes drew 27.3k for 0.82 px, 1.2x the
// fewest triangles at the frame's error instead of 1.6x; on Rainier 1.6x
// instead of 1.7x (docs/decisions.md D296; D255 chose 16 when each node
// was its own draw call).
inline constexpr uint32_t kTerrainPatchCells = 8;
// Quadtree terrain: a node is split while its geometric error bound (the
// tile's error from the store's index, tightened by the exact distance of
// the resident finer level), projected at the node's nearest point,
// exceeds this many pixels. The bound is a worst case at the nearest
// point, far above the error the frame shows: with 8-cell nodes 6 px keeps
// the measured p95 under 1 px on both real DEMs of the terrain sweep
// (0.72 px on St Helens, 0.81 on Rainier; 7 px: 0.86 and 1.01; docs/
// terrain.md, "The two methods side by side"; D296).
inline constexpr double kTerrainErrorPx = 6.0;
// Quadtree terrain: the most triangles a frame draws (TerrainConfig::
// triangle_budget, --terrain-triangle-budget; 0: none). Twice a full ring
// of the clipmap at its default kTerrainRingCells (2 x 2 x 128^2), which
// is about what the clipmap draws at 1280x720 (28k-57k on the terrain
// sweep's scenes), so on rough ground the quadtree costs about what the
// clipmap does instead of 5-8x (435k triangles, 138 ms a frame on the
// rough DEM at 10 px), while at the default bound the real DEMs stay
// under it (25k on St Helens, 61k on Rainier on the sweep's orbits).
inline constexpr uint64_t kTerrainTriangleBudget = 65536;
// Quadtree terrain: when the restriction's forced splits take a budgeted
// frame over, the selection searches for the most splits that fit with at
// most this many restrictions more (false position, every other step
// halving: ~1,000 splits are narrowed to one in 8-10).
inline constexpr uint32_t kTerrainBudgetSearchSteps = 10;
// Share of the light that does not depend on the sun (Lambert + ambient).
inline constexpr float kTerrainAmbient = 0.35f;

// Detail textures (TerrainConfig::detail_textures, --terrain-detail): one
// tiling RGBA8 texture of this side, a material a channel, generated at
// start-up (docs/terrain.md, "Detail textures").
inline constexpr uint32_t kDetailTexturePx = 256;
// Its texels per level-0 colour texel: 8 makes the detail as sharp as the
// colour at 8x magnification (a texel of the colour 8 px on screen), the
// low passes' range over the demo's 1 m orthophoto; one repeat spans 32
// colour texels.
inline constexpr uint32_t kDetailTexelsPerTexel = 8;
// The detail fades in over this many levels of the colour's magnification
// (log2 of a texel's size in pixels, above the level it is drawn from):
// none where a texel is at most a pixel, all where it spans 2^this pixels.
inline constexpr float kDetailFadeLevels = 2.0f;

// Least height above the ground a camera keeps over terrain (world units):
// flights lift a path that asks for less, and clipstream-view stops there,
// so the near plane never cuts into the slope in front.
inline constexpr double kTerrainClearance = 2.0;

// Colour written where the view ray misses the textured ground (sky, or
// outside the texture), and shown through ground whose colour is not
// opaque (a no-data pixel: alpha 0). Tests compare against the same constant.
inline constexpr uint8_t kSkyRgba[4] = {46, 51, 64, 255};

}  // namespace clipstream::renderer_config
