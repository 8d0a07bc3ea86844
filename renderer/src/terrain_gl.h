// Private: the GL objects of the terrain renderer (terrain.h) other than
// its height stack (terrain_height_stack.h), one owner with a destructor
// each: a mesh's buffers, the terrain's programs, the float target of
// readPositions().
//
// Owned by the GL thread: every method, constructor and destructor calls GL.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace clipstream {

// Where terrain.vert puts a grid: its aOrigin (attribute 1, ivec4) and
// aLevel (attribute 2, int).
struct TerrainGridOrigin {
  int32_t origin_level[2];  // vertex (0, 0)'s sample of `level`
  int32_t origin_rel[2];    // the same in level-0 samples, minus the camera's integer sample
  int32_t level;
};

// A vertex buffer of (i, j) grid coordinates (two int32 a vertex, attribute
// 0 as ivec2), an index buffer of uint32 triangles, and the vertex array
// that binds both. The grid's origin (attributes 1 and 2) is either one
// value for a whole draw (setOrigin(), the rings) or, for an instanced
// mesh, one TerrainGridOrigin an instance from setInstances() (the
// quadtree's nodes: one draw call per edge pattern instead of per node).
class TerrainMeshBuffers {
 public:
  // Uploads `vertices` ((i, j) pairs) and `indices`; kOutOfMemory /
  // kUnavailable naming `what` when GL cannot make them.
  static Status create(const std::vector<int32_t>& vertices, const std::vector<uint32_t>& indices,
                       bool instanced, const std::string& what, std::unique_ptr<TerrainMeshBuffers>* out);
  ~TerrainMeshBuffers();
  TerrainMeshBuffers(const TerrainMeshBuffers&) = delete;
  TerrainMeshBuffers& operator=(const TerrainMeshBuffers&) = delete;

  uint32_t vao() const { return m_vao; }
  // Not instanced: the origin of the next draws (the attributes' current
  // values, read by every vertex).
  static void setOrigin(const TerrainGridOrigin& origin);
  // Instanced: replaces the instances' origins (instance k of a draw with
  // base instance b reads origins[b + k]).
  void setInstances(const std::vector<TerrainGridOrigin>& origins);

 private:
  TerrainMeshBuffers() = default;
  uint32_t m_vao = 0, m_vertices = 0, m_indices = 0, m_instances = 0;
};

// terrain.vert linked with the ground's fragment shader, without and with
// the level overlay, lit by vertex or by pixel, without and with the detail
// textures (draw()), and with terrain_position.frag (readPositions()).
class TerrainPrograms {
 public:
  // kUnavailable with the compiler log when a program does not build.
  // `whole_level0`: for the full-resolution mesh, whose stack holds level 0
  // alone (terrain_heights.glsl's WHOLE_LEVEL0).
  static Status create(bool whole_level0, std::unique_ptr<TerrainPrograms>* out);
  ~TerrainPrograms();
  TerrainPrograms(const TerrainPrograms&) = delete;
  TerrainPrograms& operator=(const TerrainPrograms&) = delete;

  uint32_t ground(bool overlay, bool pixel_lighting, bool detail) const {
    return m_ground[(overlay ? 1 : 0) + (pixel_lighting ? 2 : 0) + (detail ? 4 : 0)];
  }
  uint32_t position() const { return m_position; }

 private:
  TerrainPrograms() = default;
  uint32_t m_ground[8] = {};  // overlay + 2 pixel_lighting + 4 detail
  uint32_t m_position = 0;
};

// readPositions()'s target: an RGBA32F colour and a 24-bit depth
// renderbuffer in a framebuffer, made on first use and again when the
// viewport's size changes.
class TerrainPositionTarget {
 public:
  TerrainPositionTarget() = default;
  ~TerrainPositionTarget();
  TerrainPositionTarget(const TerrainPositionTarget&) = delete;
  TerrainPositionTarget& operator=(const TerrainPositionTarget&) = delete;

  // Makes the target `viewport`'s size unless it is already; kOutOfMemory /
  // kUnavailable when GL cannot (made again on the next call).
  Status fit(const Viewport& viewport);
  uint32_t framebuffer() const { return m_fbo; }

 private:
  void release();
  uint32_t m_fbo = 0, m_color = 0, m_depth = 0;
  Viewport m_size{0, 0};
};

}  // namespace clipstream
