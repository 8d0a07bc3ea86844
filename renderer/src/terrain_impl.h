// Private: the terrain renderer behind TerrainRenderer (terrain.h), which
// forwards every call here. Its parts, one file each:
//  - terrain.cpp: create() and the height uploads, the ground queries, the
//    position pass;
//  - terrain_draw.cpp: the per-frame uniforms, the frustum, the clipmap's
//    rings and the full-resolution mesh's patches;
//  - terrain_quadtree.cpp: the quadtree's node selection and draws;
//  - terrain_node_error.cpp: the quadtree's node error bounds;
//  - terrain_seen.cpp: the ground a frame showed, read from its depth;
//  - terrain_height_stack.h: the height clip stack (texture and CPU copies);
//  - terrain_mesh.h: the ring and patch meshes, built on the CPU;
//  - terrain_gl.h: the meshes' buffers, the programs, the position target.
// Tests include this header to run terrain.vert over a ring's vertices
// with the renderer's own uniforms, origin and mesh (setFrameUniforms(),
// gridOrigin(), ringMesh()).
//
// Owned by the GL thread: every method must be called on the thread whose
// context was current at create() (the const queries touch no GL, and are
// called on that thread too).
#pragma once

#include <clipstream/renderer/terrain.h>

#include "terrain_detail.h"
#include "terrain_gl.h"
#include "terrain_height_stack.h"
#include "terrain_mesh.h"

#include <glm/glm.hpp>

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <unordered_map>
#include <vector>

namespace clipstream {

// The camera in level-0 sample coordinates (sample i at i).
inline glm::dvec2 cameraSamples(const TerrainMapping& m, const Camera& camera) {
  return {(camera.position.x - m.sample0_world.x) / m.world_per_sample.x,
          (camera.position.z - m.sample0_world.y) / m.world_per_sample.y};
}

// Ring origin of `level` for this camera (terrain_mesh::ringOrigin()).
inline glm::i64vec2 ringOrigin(const TerrainConfig& config, const Camera& camera, uint32_t level) {
  return terrain_mesh::ringOrigin(cameraSamples(config.mapping, camera), config.ring_cells, level);
}

class TerrainRendererImpl {
 public:
  // TerrainRenderer::create(): checks `config` (checkConfig()), then makes
  // the programs, the meshes and the height stack.
  static Status create(const PyramidGeometry& heights, const TerrainConfig& config,
                       std::unique_ptr<TerrainRendererImpl>* out);
  ~TerrainRendererImpl();
  TerrainRendererImpl(const TerrainRendererImpl&) = delete;
  TerrainRendererImpl& operator=(const TerrainRendererImpl&) = delete;

  // TerrainRenderer's methods of the same names (terrain.h says what each does).
  void uploadTile(const TileKey& key, const float* heights);
  uint32_t preloadCoarseLevels(const TerrainRenderer::HeightTileFn& tile);
  void draw(const Camera& camera, const Viewport& viewport, const ClipmapRenderer& colour);
  bool groundHeight(const glm::dvec2& world_xz, double* height, uint32_t* level) const;
  Status readPositions(const Camera& camera, const Viewport& viewport, const ClipmapRenderer& colour,
                       std::vector<float>* xyzw);
  bool groundRange(const Camera& camera, double* lowest, double* highest) const;
  void setBounds(std::shared_ptr<const TerrainBounds> bounds) { m_bounds = std::move(bounds); }
  void setErrorBound(double error_px) { m_config.error_px = error_px; }
  Status setLighting(TerrainLighting lighting) {
    // The full-resolution mesh computes its gradients from level 0.
    if (lighting == TerrainLighting::kPixel && !m_config.full_resolution)
      if (Status s = m_stack->enableGradients(); !s) return s;
    m_config.lighting = lighting;
    return okStatus();
  }
  Status setDetailTextures(bool on) {
    if (on && !m_detail)
      if (Status s = TerrainDetailTexture::create(&m_detail); !s) return s;
    m_config.detail_textures = on;
    return okStatus();
  }
  const TerrainFrame& lastFrame() const { return m_frame; }
  const std::vector<TerrainNode>& lastNodes() const { return m_nodes; }
  const std::vector<TileKey>& lastHeightTiles() const { return m_height_tiles; }
  const HeightReads& heightReads() const { return m_reads; }
  uint64_t textureBytes() const { return m_stack->textureBytes(); }
  const PyramidGeometry& geometry() const { return m_geometry; }
  const TerrainConfig& config() const { return m_config; }
  // Quadtree, for measuring only (setExactNodeError()): each node's error
  // from `error` instead of the bounds, and no restriction between
  // neighbours. Null for display.
  void setExactNodeError(std::function<double(uint32_t, int64_t, int64_t)> error) {
    m_exact_node_error = std::move(error);
  }
  // Quadtree, for tests and the selection benchmark only: the selection as
  // it was before the triangle budget and the restriction's worklist (issue
  // #33), their reference: split depth first, no budget, the restriction by
  // a full scan of the leaves after each mend, no cached visibility.
  void setReferenceSelection(bool reference) { m_reference_selection = reference; }
  // The per-tile bounds of setBounds() (null: none).
  const std::shared_ptr<const TerrainBounds>& bounds() const { return m_bounds; }

  // Sets terrain.vert's per-frame uniforms on `program` for this camera
  // (and binds the height stack to texture unit 2), as draw() does.
  void setFrameUniforms(uint32_t program, const Camera& camera, const Viewport& viewport) const;
  // Where terrain.vert puts one grid: level `level` with vertex (0, 0) at
  // level sample `origin` (TerrainMeshBuffers::setOrigin() or an instance).
  TerrainGridOrigin gridOrigin(const Camera& camera, uint32_t level, const glm::i64vec2& origin) const;
  // The ring mesh: the plain (n + 1)^2 grid first (vertex j (n + 1) + i is
  // (i, j)), then the blocks' copies (terrain_mesh::RingMesh).
  const TerrainMeshBuffers& ringMesh() const { return *m_ring_mesh; }
  // The far plane of every draw for this camera (setFrameUniforms()).
  double farDistance(const Camera& camera) const;

 private:
  TerrainRendererImpl() = default;
  // create()'s steps. kInvalidArgument naming what is wrong with `config`.
  static Status checkConfig(const PyramidGeometry& heights, const TerrainConfig& config);
  Status buildMeshes();

  // The coarsest ring level needed with the camera at `cam` (level-0
  // samples), and setting it (with the colour image's extent) for a frame.
  uint32_t coarsestFor(const glm::dvec2& cam) const;
  void updateCoarsest(const Camera& camera, const ClipmapRenderer& colour);
  using Frustum = std::array<glm::dvec4, 6>;
  Frustum frustum(const Camera& camera, const Viewport& viewport) const;

  // Draws the resident rings with `program` (its uniforms set by the caller
  // for the frame), culling blocks; fills m_frame.
  void drawRings(uint32_t program, const Camera& camera, const Viewport& viewport);
  // The nested rings of the geometry clipmap, finest (nearest) first.
  void drawClipmapRings(uint32_t program, const Camera& camera, const Viewport& viewport);
  // The full_resolution mesh: every patch over the height field and the
  // colour image (m_image_px), culled by blocks.
  void drawPatches(uint32_t program, const Camera& camera, const Viewport& viewport);
  // Draws, with the program in use, the blocks of index pattern `pattern`
  // of the grid whose vertex (0, 0) is `origin` (level samples) at `level`
  // that meet the frustum, nearest first; counts them in m_frame.
  void drawGrid(const Camera& camera, const Frustum& planes, uint32_t level, const glm::i64vec2& origin,
                int pattern);
  // Notes in m_height_tiles the tiles holding samples [s0, s1] (inclusive)
  // of `level` as terrain.vert's heightAt() reads them (clamped to the
  // level; levels past the pyramid decimate its last).
  void noteHeightReads(uint32_t level, glm::i64vec2 s0, glm::i64vec2 s1);

  // ---- The quadtree (terrain_quadtree.cpp) ----
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
  // One frame's leaf selection (selectNodes()'s steps).
  class NodeSelection;
  // The quadtree (and the flat plane, its roots at height 0): selects the
  // leaves for this camera (selectNodes(), into m_nodes) and draws them.
  void drawQuadtree(uint32_t program, const Camera& camera, const Viewport& viewport);
  void selectNodes(const Camera& camera, const Viewport& viewport);
  struct NodeBox {
    glm::dvec3 lo, hi;  // camera-relative world box
    // The camera's (the origin's) distance to the box: 0 inside it.
    double distance() const { return glm::length(glm::max(glm::max(lo, -hi), glm::dvec3(0.0))); }
  };
  NodeBox nodeBox(const Camera& camera, uint32_t level, int64_t x, int64_t y) const;
  bool nodeVisible(const Camera& camera, const NodeBox& box) const;
  // The node's error bound (height units): the smaller of the index's bound
  // for its tiles (plus their twist) and, where the next finer level is
  // resident, the exact distance of that level's samples from the node's
  // surface plus the children's bounds. Cached until a tile under it changes.
  double nodeError(uint32_t level, int64_t x, int64_t y);
  double tileErrorBound(uint32_t level, int64_t x, int64_t y) const;
  // Forgets the cached errors of the nodes that read tile `key` (it changed).
  void forgetNodeErrors(const TileKey& key);
  // Height of level sample (i, j) from the resident tiles (clamped to the
  // level; levels past the pyramid decimate its last, as the shader does).
  bool cpuHeight(uint32_t level, int64_t i, int64_t j, float* h) const;
  // The size x size samples of `level` from sample s0 on into `out`
  // (row-major), as cpuHeight() reads them; false when one is not resident.
  bool readSamples(uint32_t level, const glm::i64vec2& s0, int64_t size, float* out) const;
  bool samplesResident(uint32_t level, glm::i64vec2 s0, glm::i64vec2 s1) const;
  uint32_t rootLevel() const;
  // The flat method's plane: the terrain's lowest height (height units;
  // without bounds the lowest sample of the pyramid's last level), so that
  // a camera kept above the ground is above the plane too.
  double flatHeight() const;

  PyramidGeometry m_geometry;
  TerrainConfig m_config;
  // Quadtree, for measuring only (clipstream/renderer/testing/
  // terrain_measure.h); null for display.
  std::function<double(uint32_t, int64_t, int64_t)> m_exact_node_error;
  bool m_reference_selection = false;  // setReferenceSelection()
  // Outermost ring level: covers the whole height field and colour image
  // from the camera of the last draw (updateCoarsest()).
  uint32_t m_coarsest = 0;
  glm::dvec2 m_image_px{0.0};  // the colour image's size (world units) at the last draw
  std::unique_ptr<TerrainPrograms> m_programs;
  std::unique_ptr<TerrainHeightStack> m_stack;
  std::unique_ptr<TerrainDetailTexture> m_detail;  // made when the detail textures are first on
  // The ring mesh and where each pattern's blocks lie in its index buffer.
  std::unique_ptr<TerrainMeshBuffers> m_ring_mesh;
  terrain_mesh::RingMesh::Blocks m_ring_blocks{};
  // Quadtree: the patch mesh and where each edge pattern lies.
  std::unique_ptr<TerrainMeshBuffers> m_patch_mesh;
  terrain_mesh::PatchMesh::Masks m_patch_masks{};
  TerrainPositionTarget m_position_target;  // readPositions()
  std::shared_ptr<const TerrainBounds> m_bounds;
  std::vector<TerrainNode> m_nodes;
  // The height tiles the last drawRings() read, each once (lastHeightTiles()).
  std::vector<TileKey> m_height_tiles;
  // What the last drawRings() read and wanted to read (heightReads()).
  HeightReads m_reads;
  std::unordered_map<NodeId, float, NodeIdHash> m_error_cache;
  // Entries kept at most (cleared beyond): a few frames' nodes, so that an
  // upload's scan stays cheap and the cache cannot grow over a long flight.
  static constexpr size_t kMaxCachedNodeErrors = 16384;
  Frustum m_frustum_cache{};
  TerrainFrame m_frame;
};

}  // namespace clipstream
