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
// context was current at create().
#pragma once

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/alignment.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/terrain_bounds.h>

#include <glm/glm.hpp>

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

namespace clipstream {

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
const char* terrainMethodName(TerrainMethod method);
// "clipmap", "quadtree", "flat", "full"; kInvalidArgument naming the choices otherwise.
Status terrainMethodFromName(const std::string& name, TerrainMethod* out);

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
  // Quadtree, for measuring only (eval's FewestTriangles): each node's
  // error from this function (height units; level, node x, node y) instead
  // of the bounds, and no restriction between neighbours (no stitching:
  // cracks may open). Null for display.
  std::function<double(uint32_t, int64_t, int64_t)> exact_node_error;
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
};

// A leaf of the quadtree drawn last (TerrainRenderer::lastNodes()): level-L
// node (x, y) covers level-L samples [x P, (x + 1) P] (P = patch_cells);
// coarse_sides: terrain_mesh's PatchSide bits of the sides that border a
// node one level coarser (drawn with their odd vertices left out).
struct TerrainNode {
  uint32_t level = 0;
  int64_t x = 0, y = 0;
  uint32_t coarse_sides = 0;
  bool drawn = false;  // false: outside the frustum or the image (culled)
};

class TerrainRenderer {
 public:
  // A quadtree node: level-L node (x, y) (TerrainNode's coordinates).
  struct NodeId {
    uint32_t level;
    int64_t x, y;
    bool operator==(const NodeId& o) const { return level == o.level && x == o.x && y == o.y; }
  };
  struct NodeIdHash {
    size_t operator()(const NodeId& k) const {
      return size_t((uint64_t(k.x) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(k.y) * 0xC2B2AE3D27D4EB4Full) ^ k.level);
    }
  };

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
  void setBounds(std::shared_ptr<const TerrainBounds> bounds) { m_bounds = std::move(bounds); }
  // Quadtree: a new TerrainConfig::error_px (within its range) for the next draws.
  void setErrorBound(double error_px) { m_config.error_px = error_px; }

  const TerrainFrame& lastFrame() const { return m_frame; }
  // Quadtree: every leaf of the last draw (culled ones included); empty
  // for the other methods.
  const std::vector<TerrainNode>& lastNodes() const { return m_nodes; }
  // Bytes of the height stack texture (video memory).
  uint64_t textureBytes() const { return m_texture_bytes; }
  const PyramidGeometry& geometry() const { return m_geometry; }
  const TerrainConfig& config() const { return m_config; }

  // The clip size (tiles a side) a streamer's height layer needs for rings
  // of `ring_cells`: the n + 3 samples a ring reads (one more each side for
  // normals) in whole tiles, plus room for the planner's window, which
  // lies a quarter of its width ahead of the camera and snaps to tiles.
  static uint32_t windowTiles(uint32_t ring_cells, uint32_t tile_px) {
    return (ring_cells + 3 + tile_px - 1) / tile_px + 3;
  }

  // Ring origin of `level` for this camera: the level's sample index of the
  // ring's vertex (0, 0), even, so every other vertex is a vertex of the
  // next coarser ring. Pure; exposed for tests.
  static glm::i64vec2 ringOrigin(const TerrainConfig& config, const Camera& camera, uint32_t level);

  // Test hook: runs ring `level`'s vertex shader for this camera (transform
  // feedback, nothing drawn) and returns, for each vertex of its
  // (n + 1)^2 grid in row order, the normal (xyz) and height (w) it outputs.
  // A complete framebuffer must be bound (e.g. an OffscreenTarget).
  std::vector<glm::vec4> ringVertices(const Camera& camera, const Viewport& viewport,
                                      uint32_t level);

 private:
  TerrainRenderer() = default;
  void setFrameUniforms(uint32_t program, const Camera& camera, const Viewport& viewport) const;
  // The coarsest ring level needed with the camera at `cam` (level-0
  // samples), and setting it (with the colour image's extent) for a frame.
  uint32_t coarsestFor(const glm::dvec2& cam) const;
  void updateCoarsest(const Camera& camera, const ClipmapRenderer& colour);
  double farDistance(const Camera& camera) const;
  // Draws the resident rings with `program` (its uniforms set by the caller
  // for the frame), culling blocks; fills m_frame.
  void drawRings(uint32_t program, const Camera& camera, const Viewport& viewport);
  // The nested rings of the geometry clipmap, finest (nearest) first.
  void drawClipmapRings(uint32_t program, const Camera& camera, const Viewport& viewport);
  // The full_resolution mesh: every patch over the height field and the
  // colour image (m_image_px), culled by blocks.
  void drawPatches(uint32_t program, const Camera& camera, const Viewport& viewport);
  // The quadtree (and the flat plane, its roots at height 0): selects the
  // leaves for this camera (selectNodes(), into m_nodes) and draws them.
  void drawQuadtree(uint32_t program, const Camera& camera, const Viewport& viewport);
  void selectNodes(const Camera& camera, const Viewport& viewport);
  // Quadtree helpers (terrain_quadtree.cpp).
  struct NodeBox {
    glm::dvec3 lo, hi;  // camera-relative world box
  };
  NodeBox nodeBox(const Camera& camera, uint32_t level, int64_t x, int64_t y) const;
  bool nodeVisible(const Camera& camera, const NodeBox& box) const;
  // The node's error bound (height units): the smaller of the index's bound
  // for its tiles (plus their twist) and, where the next finer level is
  // resident, the exact distance of that level's samples from the node's
  // surface plus the children's bounds. Cached until a tile under it changes.
  double nodeError(uint32_t level, int64_t x, int64_t y);
  double tileErrorBound(uint32_t level, int64_t x, int64_t y) const;
  // Height of level sample (i, j) from the resident tiles (clamped to the
  // level; levels past the pyramid decimate its last, as the shader does).
  bool cpuHeight(uint32_t level, int64_t i, int64_t j, float* h) const;
  bool samplesResident(uint32_t level, glm::i64vec2 s0, glm::i64vec2 s1) const;
  uint32_t rootLevel() const;
  // The flat method's plane: the terrain's lowest height (height units;
  // without bounds the lowest sample of the pyramid's last level), so that
  // a camera kept above the ground is above the plane too.
  double flatHeight() const;
  using Frustum = std::array<glm::dvec4, 6>;
  Frustum frustum(const Camera& camera, const Viewport& viewport) const;
  // Draws the blocks of index pattern `config` of the grid whose vertex
  // (0, 0) is `origin` (level samples) at `level` that meet the frustum;
  // counts them in m_frame.
  void drawGrid(uint32_t program, const Camera& camera, const Frustum& planes, uint32_t level,
                const glm::i64vec2& origin, int config);
  void setRingUniforms(uint32_t program, const Camera& camera, uint32_t level,
                       const glm::i64vec2& origin) const;
  bool levelResident(uint32_t level, const glm::i64vec2& origin) const;
  // Bounds of the heights a ring of `ring_level` reads in level samples
  // [s0, s1] (inclusive, clamped), from the resident tiles' bounds.
  glm::vec2 heightBounds(uint32_t ring_level, glm::i64vec2 s0, glm::i64vec2 s1) const;
  uint32_t slotOf(int64_t tile) const;

  PyramidGeometry m_geometry;
  TerrainConfig m_config;
  uint32_t m_slots = 0;        // tiles per stack layer side (toroidal period)
  // Outermost ring level: covers the whole height field and colour image
  // from the camera of the last draw (updateCoarsest()).
  uint32_t m_coarsest = 0;
  uint32_t m_program[2] = {0, 0};  // without / with the overlay
  uint32_t m_feedback_program = 0; // ringVertices()
  uint32_t m_position_program = 0; // readPositions()
  uint32_t m_position_fbo = 0, m_position_color = 0, m_position_depth = 0;
  Viewport m_position_size{0, 0};
  glm::dvec2 m_image_px{0.0};  // the colour image's size (world units) at the last draw
  uint32_t m_vao = 0, m_vertices = 0, m_indices = 0;
  uint32_t m_heights = 0;      // R32F array texture
  // Index buffer ranges: [0] no hole, [1 + hx + 2 hy] hole at (n/4 + hx, n/4 + hy).
  // Each pattern's triangles in kBlocks x kBlocks blocks (by the cell of
  // their centroid), culled one by one against the frustum.
  static constexpr uint32_t kBlocks = 4;
  uint32_t m_first_index[5][kBlocks * kBlocks] = {};
  uint32_t m_index_count[5][kBlocks * kBlocks] = {};
  // Height bounds of the tile in each slot (min, max), per level.
  std::vector<std::vector<glm::vec2>> m_slot_bounds;
  // Which tile each slot holds, per level (x | y << 32, or kNoTile).
  static constexpr uint64_t kNoTile = ~uint64_t(0);
  std::vector<std::vector<uint64_t>> m_slot_tile;
  // CPU copies of the same tiles, for groundHeight() (per level, per slot).
  std::vector<std::vector<std::vector<float>>> m_slot_heights;
  // Quadtree: the patch mesh (one (P + 1)^2 grid, 16 edge patterns), the
  // largest twist |a - b - c + d| / 4 of the cells of each resident tile's
  // node-sized blocks (the triangulated surface's distance from the
  // bilinear one the index's error bounds), per level and slot.
  uint32_t m_patch_vao = 0, m_patch_vertices = 0, m_patch_indices = 0;
  uint32_t m_patch_first[16] = {}, m_patch_count[16] = {};
  std::vector<std::vector<std::vector<float>>> m_slot_twist;
  std::shared_ptr<const TerrainBounds> m_bounds;
  std::vector<TerrainNode> m_nodes;
  std::unordered_map<NodeId, float, NodeIdHash> m_error_cache;
  // Entries kept at most (cleared beyond): a few frames' nodes, so that an
  // upload's scan stays cheap and the cache cannot grow over a long flight.
  static constexpr size_t kMaxCachedNodeErrors = 16384;
  Frustum m_frustum_cache{};
  uint64_t m_texture_bytes = 0;
  TerrainFrame m_frame;
};

}  // namespace clipstream
