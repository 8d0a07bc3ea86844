#include "terrain_gl.h"

#include "gl.h"
#include "gl_util.h"
#include "shaders.h"

#include <cstddef>

namespace clipstream {

Status TerrainMeshBuffers::create(const std::vector<int32_t>& vertices, const std::vector<uint32_t>& indices,
                                  bool instanced, const std::string& what,
                                  std::unique_ptr<TerrainMeshBuffers>* out) {
  out->reset();
  std::unique_ptr<TerrainMeshBuffers> m(new TerrainMeshBuffers());
  gl_util::clearErrors();
  glCreateBuffers(1, &m->m_vertices);
  glNamedBufferStorage(m->m_vertices, GLsizeiptr(vertices.size() * sizeof(int32_t)), vertices.data(), 0);
  glCreateBuffers(1, &m->m_indices);
  glNamedBufferStorage(m->m_indices, GLsizeiptr(indices.size() * sizeof(uint32_t)), indices.data(), 0);
  glCreateVertexArrays(1, &m->m_vao);
  glVertexArrayVertexBuffer(m->m_vao, 0, m->m_vertices, 0, 2 * sizeof(int32_t));
  glVertexArrayElementBuffer(m->m_vao, m->m_indices);
  glEnableVertexArrayAttrib(m->m_vao, 0);
  glVertexArrayAttribIFormat(m->m_vao, 0, 2, GL_INT, 0);
  glVertexArrayAttribBinding(m->m_vao, 0, 0);
  if (instanced) {
    glCreateBuffers(1, &m->m_instances);
    glVertexArrayVertexBuffer(m->m_vao, 1, m->m_instances, 0, sizeof(TerrainGridOrigin));
    glVertexArrayBindingDivisor(m->m_vao, 1, 1);
    glEnableVertexArrayAttrib(m->m_vao, 1);
    glVertexArrayAttribIFormat(m->m_vao, 1, 4, GL_INT, GLuint(offsetof(TerrainGridOrigin, origin_level)));
    glVertexArrayAttribBinding(m->m_vao, 1, 1);
    glEnableVertexArrayAttrib(m->m_vao, 2);
    glVertexArrayAttribIFormat(m->m_vao, 2, 1, GL_INT, GLuint(offsetof(TerrainGridOrigin, level)));
    glVertexArrayAttribBinding(m->m_vao, 2, 1);
  }
  if (Status s = gl_util::checkCreated(what); !s) return s;
  *out = std::move(m);
  return okStatus();
}

void TerrainMeshBuffers::setOrigin(const TerrainGridOrigin& o) {
  glVertexAttribI4i(1, o.origin_level[0], o.origin_level[1], o.origin_rel[0], o.origin_rel[1]);
  glVertexAttribI1i(2, o.level);
}

void TerrainMeshBuffers::setInstances(const std::vector<TerrainGridOrigin>& origins) {
  // A new store each time (the draws of the last call may still read the
  // old one).
  glNamedBufferData(m_instances, GLsizeiptr(origins.size() * sizeof(TerrainGridOrigin)), origins.data(),
                    GL_STREAM_DRAW);
}

TerrainMeshBuffers::~TerrainMeshBuffers() {
  glDeleteBuffers(1, &m_instances);
  glDeleteVertexArrays(1, &m_vao);
  glDeleteBuffers(1, &m_vertices);
  glDeleteBuffers(1, &m_indices);
}

Status TerrainPrograms::create(bool whole_level0, std::unique_ptr<TerrainPrograms>* out) {
  out->reset();
  std::unique_ptr<TerrainPrograms> p(new TerrainPrograms());
  const std::string vertex = std::string(shaders::k_terrain_heights_glsl) + "\n" + shaders::k_terrain_vert;
  const std::string fragment = std::string(shaders::k_terrain_ground_glsl) + "\n" +
                               shaders::k_ground_clipmap_frag;
  for (int i = 0; i < 8; ++i) {
    const bool overlay = (i & 1) != 0, pixel = (i & 2) != 0, detail = (i & 4) != 0;
    // Lit by vertex, the fragment shader reads no heights.
    Status s = gl_util::buildProgram(
        vertex, pixel ? std::string(shaders::k_terrain_heights_glsl) + "\n" + fragment : fragment, &p->m_ground[i],
        std::string("#define TERRAIN 1\n") + (overlay ? "#define OVERLAY 1\n" : "") +
            (pixel ? "#define PIXEL_LIGHTING 1\n" : "") + (detail ? "#define DETAIL 1\n" : "") +
            (whole_level0 ? "#define WHOLE_LEVEL0 1\n" : ""));
    if (!s) return s;
  }
  Status s = gl_util::buildProgram(vertex, shaders::k_terrain_position_frag, &p->m_position,
                                   whole_level0 ? "#define WHOLE_LEVEL0 1\n" : "");
  if (!s) return s;
  *out = std::move(p);
  return okStatus();
}

TerrainPrograms::~TerrainPrograms() {
  for (uint32_t program : m_ground) glDeleteProgram(program);
  glDeleteProgram(m_position);
}

Status TerrainPositionTarget::fit(const Viewport& viewport) {
  if (m_size.width_px == viewport.width_px && m_size.height_px == viewport.height_px) return okStatus();
  gl_util::clearErrors();
  release();
  glCreateRenderbuffers(1, &m_color);
  glNamedRenderbufferStorage(m_color, GL_RGBA32F, GLsizei(viewport.width_px), GLsizei(viewport.height_px));
  glCreateRenderbuffers(1, &m_depth);
  glNamedRenderbufferStorage(m_depth, GL_DEPTH_COMPONENT24, GLsizei(viewport.width_px),
                             GLsizei(viewport.height_px));
  glCreateFramebuffers(1, &m_fbo);
  glNamedFramebufferRenderbuffer(m_fbo, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, m_color);
  glNamedFramebufferRenderbuffer(m_fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, m_depth);
  if (Status s = gl_util::checkCreated("the terrain's position target (" + std::to_string(viewport.width_px) +
                                       "x" + std::to_string(viewport.height_px) + " RGBA32F)");
      !s) {
    m_size = Viewport{0, 0};  // made again on the next call
    return s;
  }
  m_size = viewport;
  return okStatus();
}

void TerrainPositionTarget::release() {
  glDeleteFramebuffers(1, &m_fbo);
  glDeleteRenderbuffers(1, &m_color);
  glDeleteRenderbuffers(1, &m_depth);
  m_fbo = m_color = m_depth = 0;
}

TerrainPositionTarget::~TerrainPositionTarget() { release(); }

}  // namespace clipstream
