// Terrain geometry over a height clip stack, textured by the colour
// clipmap, by one of two methods (TerrainMethod): a GPU geometry clipmap
// (Losasso & Hoppe 2004; GPU Gems 2 ch. 2), or a restricted quadtree of
// patches refined by their projected geometric error. Clipmap: rings of
// n x n cells, each level twice the spacing of the one inside it, centred
// on the viewer; every vertex's height is fetched in the vertex shader from
// the height stack (R32F, one array layer per height level, tiles placed
// toroidally as in the colour stack); the outer band of each ring blends
// towards the coarser ring's surface so rings meet without cracks,
// T-junctions or popping. Quadtree: nodes of kTerrainPatchCells cells over
// the same height levels, split while the store's per-tile error bound,
// projected at the node's nearest point, exceeds TerrainConfig::error_px;
// neighbours differ by at most one level, and a node's side towards a
// coarser one skips its odd vertices (no crack). docs/terrain.md explains
// both methods and when to choose which.
//
// Owned by the GL thread: every method must be called on the thread whose
// context was current at create(). The implementation and its GL objects
// are private (renderer/src/terrain_impl.h).
#pragma once

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/alignment.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/terrain_bounds.h>

#include <glm/glm.hpp>

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace clipstream {

class TerrainRendererImpl;

// How heights map to the world (the colour layer's level-0 texels, y up):
// the scene's alignment of the elevation layer (alignElevation()); the
// renderer reads world_per_sample, sample0_world and world_per_height.
using TerrainMapping = LayerAlignment;

// How the terrain's geometry is modelled (--terrain): the geometry clipmap,
// the restricted quadtree, or the flat plane at the terrain's lowest height
// drawn through the same pipeline (an end point of the accuracy charts: what
// no geometry costs; cameras still fly above the real ground).
// kFull: the full-resolution mesh (TerrainConfig::full_resolution), the
// other end point; it needs level 0 whole in the stack.
enum class TerrainMethod : uint8_t { kClipmap, kQuadtree, kFlat, kFull };
// "clipmap", "quadtree", "flat", "full", in reports; programs parse
// --terrain with cli::parseTerrainMethod().
const char* terrainMethodName(TerrainMethod method);

// How the terrain is lit (--terrain-lighting): by the vertices' normals,
// interpolated across each triangle (the normals of the level the
// geometry is drawn at), or per pixel: the normal of the heights under
// each pixel, from the level its footprint asks for (as the colour's
// level) or the finest resident one above it, blended across levels. The
// same Lambert and ambient light either way; kVertex draws the frames it
// drew before per-pixel lighting existed, bit for bit.
enum class TerrainLighting : uint8_t { kVertex, kPixel };
// "vertex", "pixel"; programs parse --terrain-lighting with
// cli::parseTerrainLighting().
const char* terrainLightingName(TerrainLighting lighting);

// Range of TerrainConfig::error_px (--terrain-error): below a hundredth of
// a pixel every node in view splits to level 0; above 1000 none does.
inline constexpr double kMinTerrainErrorPx = 0.01;
inline constexpr double kMaxTerrainErrorPx = 1000.0;

struct TerrainConfig {
  uint32_t ring_cells = renderer_config::kTerrainRingCells;  // n: power of two, 16..1024
  TerrainMapping mapping;
  // The streamer's clip size for the height layer (tiles a side), so that
  // every tile of a window it hands over has a slot of its own; 0: only
  // what the rings read.
  uint32_t clip_tiles = 0;
  // The full-resolution mesh instead of rings: one vertex per level-0
  // sample over the whole height field (and the colour image beyond it),
  // drawn as patches of ring_cells x ring_cells cells with the rings'
  // vertex shader, so wherever the finest ring lies its vertices are
  // bit-identical. The stack then holds level 0 whole (uploadTile ignores
  // other levels). The accuracy reference of terrain flights
  // (eval/terrain_accuracy.h); for measuring, not for display.
  bool full_resolution = false;
  // How the geometry is modelled (kFull sets full_resolution).
  TerrainMethod method = TerrainMethod::kClipmap;
  // Quadtree: the screen-space error bound (pixels) a node is split above.
  double error_px = renderer_config::kTerrainErrorPx;
  // Quadtree: cells per node side (a power of two, 4..256).
  uint32_t patch_cells = renderer_config::kTerrainPatchCells;
  // Quadtree: the most triangles a frame draws (0: no budget). Nodes split
  // in order of their projected error, largest first, and the splitting
  // stops before the budget would be passed, so the bound the frame meets
  // (TerrainFrame::achieved_error_px) is the lowest the budget allows:
  // error_px, or higher where the ground asks for more triangles. Each
  // drawn node counts as a whole patch (2 P^2 triangles; stitched sides
  // draw up to P / 2 fewer each), the restriction's forced splits
  // included. The only excess: the roots in view (at most 9 nodes) are
  // drawn whatever the budget.
  uint64_t triangle_budget = renderer_config::kTerrainTriangleBudget;
  TerrainLighting lighting = TerrainLighting::kVertex;
  // Detail textures where the colour is magnified (a texel larger than a
  // pixel): tiling textures of four materials, chosen by rules on the
  // slope and the height, modulating the colour, faded in over
  // renderer_config::kDetailFadeLevels of magnification (docs/terrain.md,
  // "Detail textures"). Off draws the frames drawn before they existed.
  bool detail_textures = false;
};

// What the last draw() drew.
struct TerrainFrame {
  uint32_t rings = 0;          // 0: the height stack could not draw even its coarsest ring
  uint32_t finest_level = 0;   // height level of the innermost ring drawn
  uint32_t coarsest_level = 0; // height level of the outermost ring
  uint64_t triangles = 0;
  uint32_t blocks = 0;         // ring blocks drawn
  uint32_t culled_blocks = 0;  // ring blocks outside the frustum (not drawn)
  // Quadtree: leaves drawn, leaves that wanted to split but whose children's
  // height tiles were not resident (drawn coarser), and splits made only to
  // keep neighbours within one level.
  uint32_t nodes = 0;
  uint32_t fallback_nodes = 0;
  uint32_t forced_splits = 0;
  // Quadtree: leaves the restriction drew coarser because a neighbour could
  // not be split (its children's heights not resident).
  uint32_t coarsened_nodes = 0;
  // Quadtree: the screen-space error bound the selection met (pixels):
  // TerrainConfig::error_px, or more where the triangle budget stopped the
  // splits (the projected error of the first node left whole, capped at
  // kMaxTerrainErrorPx, beyond which nothing splits). 0 for the other methods.
  double achieved_error_px = 0.0;
  double select_ms = 0.0;  // quadtree: the node selection's time on this thread
};

// A leaf of the quadtree drawn last (TerrainRenderer::lastNodes()): level-L
// node (x, y) covers level-L samples [x P, (x + 1) P] (P = patch_cells);
// coarse_sides: bits of the sides that border a node one level coarser
// (drawn with their odd vertices left out): 1 the side along sample row
// y P, 2 along column (x + 1) P, 4 along row (y + 1) P, 8 along column x P.
struct TerrainNode {
  uint32_t level = 0;
  int64_t x = 0, y = 0;
  uint32_t coarse_sides = 0;
  bool drawn = false;  // false: outside the frustum or the image (culled)
};

class TerrainRenderer {
 public:
  // Allocates the height stack for `heights` (an elevation store's
  // geometry) and builds the ring meshes. kInvalidArgument for a ring size
  // that is not a power of two in 16..1024 or a non-positive mapping;
  // kUnavailable when GL fails (with the shader log).
  static Status create(const PyramidGeometry& heights, const TerrainConfig& config,
                       std::unique_ptr<TerrainRenderer>* out);
  ~TerrainRenderer();
  TerrainRenderer(const TerrainRenderer&) = delete;
  TerrainRenderer& operator=(const TerrainRenderer&) = delete;

  // Uploads one height tile (tile_px^2 floats, heights in the store's units;
  // other sizes and keys outside the pyramid are ignored) into its level's
  // toroidal slot, replacing whatever tile had the slot.
  void uploadTile(const TileKey& key, const float* heights);

  // Uploads every tile of every level small enough to stay whole in the
  // stack (its tile grid fits the slots), asking `tile` for each (null: the
  // tile cannot be had). These levels are the outer rings' and the
  // fallback of every finer one; loading them before the first frame means
  // the terrain is drawn from the first frame on. Returns the tiles `tile`
  // could not give (their rings are not drawn until they arrive).
  using HeightTileFn = std::function<std::shared_ptr<const std::vector<uint8_t>>(const TileKey&)>;
  uint32_t preloadCoarseLevels(const HeightTileFn& tile);

  // Draws the terrain seen by `camera`, textured and lit, into the bound
  // framebuffer (depth test on; the caller clears colour and depth, e.g.
  // ClipmapRenderer::clearSky()). Rings whose height tiles are not all in
  // the stack are not drawn: the innermost ring drawn is the finest level
  // whose tiles, and those of every coarser ring, are resident, so a
  // missing height tile coarsens the geometry, never opens a hole.
  void draw(const Camera& camera, const Viewport& viewport, const ClipmapRenderer& colour);

  // The ground height (world units) at world point (x, z) on the surface
  // the rings draw there (cells cut along the same diagonal), from the
  // resident tiles: the highest of the surfaces of the finest level whose
  // tile there is resident and of every level up to the innermost ring
  // drawn last, so that a camera kept above it is above the ground whichever
  // of those rings the next frame draws (a coarser ring bridging a valley
  // lies above the finer surface). False when no level holds the point.
  // `level` (optional) receives the finest level resident there.
  bool groundHeight(const glm::dvec2& world_xz, double* height, uint32_t* level = nullptr) const;

  // The camera-relative world position (x, y, z) each pixel shows, 4
  // floats a pixel (w = 1 + the transition weight on terrain, so 1 outside
  // the transition bands; 0 elsewhere), top row first, drawn
  // with the same rings, culling and residency as draw() into the
  // renderer's own float target. For measuring the geometric error; it
  // replaces lastFrame(). GL thread.
  // `colour` gives the image's extent (ground outside it is left out, as
  // draw() leaves it).
  // kOutOfMemory / kUnavailable if its float target cannot be made.
  [[nodiscard]] Status readPositions(const Camera& camera, const Viewport& viewport,
                                     const ClipmapRenderer& colour, std::vector<float>* xyzw);

  // The ground the frame just drawn showed (Streamer::setGroundSeen()): at
  // the points of groundSeenGrid(viewport), the world point each pixel
  // shows, unprojected from the depth the draw left; NaN where it shows no
  // ground. Call right after draw() with the camera and viewport it drew
  // with, while its framebuffer (`framebuffer` pixels, the viewport's unless
  // the window's is larger) is still bound: it reads one row of depth per
  // grid row (55 rows of 1280 at 1280x720), so it waits for the draw as
  // glFinish would. GL thread.
  void readGroundSeen(const Camera& camera, const Viewport& viewport, const Viewport& framebuffer,
                      GroundSeen* out) const;

  // The lowest and highest ground (world units) around the camera: the
  // bounds of the resident tiles under the ring `kReliefRings` levels
  // coarser than the finest ring drawn last (or, where that is not all
  // resident, a coarser ring's). False when no ring is resident. The
  // streamer's planner takes them as the relief in view.
  static constexpr uint32_t kReliefRings = 3;
  bool groundRange(const Camera& camera, double* lowest, double* highest) const;

  // The per-tile geometric errors the quadtree refines by (the elevation
  // store's index, loadTerrainBounds()). Without them a node has no bound
  // but the exact one from its resident finer level (it splits wherever
  // its children are resident).
  void setBounds(std::shared_ptr<const TerrainBounds> bounds);
  // Quadtree: a new TerrainConfig::error_px (within its range) for the next draws.
  void setErrorBound(double error_px);
  // A new TerrainConfig::lighting for the next draws. The first switch to
  // kPixel makes the height gradients from the tiles held (video memory:
  // twice the height stack's); kOutOfMemory / kUnavailable, the lighting
  // unchanged, when GL cannot.
  [[nodiscard]] Status setLighting(TerrainLighting lighting);
  // A new TerrainConfig::detail_textures for the next draws; the first
  // switch on makes the texture (kOutOfMemory / kUnavailable, unchanged,
  // when GL cannot).
  [[nodiscard]] Status setDetailTextures(bool on);

  const TerrainFrame& lastFrame() const;
  // Quadtree: every leaf of the last draw (culled ones included); empty
  // for the other methods.
  const std::vector<TerrainNode>& lastNodes() const;
  // The height tiles the last draw's vertices read, each once: the stored
  // pyramid's (rings coarser than it read its last level), under every
  // ring block or quadtree leaf drawn, with the samples its normals and
  // its transition band towards the coarser ring reach. For measuring what
  // the geometry samples against what the streamer loads (the height
  // over-fetch); readPositions() draws, so it sets them too.
  const std::vector<TileKey>& lastHeightTiles() const;
  // The height samples the last draw read, and those it would have read
  // had their tiles been resident, for the streamer's plans of the height
  // layer (Streamer::setHeightReads()): the clipmap's every ring square
  // from level 0 out (a ring is drawn only when its square is resident),
  // one snap of the ring wider. None for the quadtree and the other
  // methods (their windows stay whole): its node errors read the finer
  // levels under every node it evaluates (docs/decisions.md D297).
  const HeightReads& heightReads() const;
  // Bytes of the height stack texture (video memory), with its gradients
  // when lit per pixel.
  uint64_t textureBytes() const;
  const PyramidGeometry& geometry() const;
  const TerrainConfig& config() const;

  // The clip size (tiles a side) a streamer's height layer needs for rings
  // of `ring_cells`: the n + 3 samples a ring reads (one more each side for
  // normals) in whole tiles, plus room for the planner's window, which
  // lies a quarter of its width ahead of the camera and snaps to tiles.
  static uint32_t windowTiles(uint32_t ring_cells, uint32_t tile_px) {
    return (ring_cells + 3 + tile_px - 1) / tile_px + 3;
  }

  // The implementation, for the library's own use: its definition is not
  // installed.
  TerrainRendererImpl& impl() { return *m_impl; }
  const TerrainRendererImpl& impl() const { return *m_impl; }

 private:
  explicit TerrainRenderer(std::unique_ptr<TerrainRendererImpl> impl);
  std::unique_ptr<TerrainRendererImpl> m_impl;
};

}  // namespace clipstream
