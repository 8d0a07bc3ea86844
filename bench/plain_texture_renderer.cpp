// The plain-texture baseline. See plain_texture_renderer.h.
#include "plain_texture_renderer.h"

#include "gl.h"
#include "gl_util.h"
#include "plain_shaders.h"

#include <algorithm>

namespace clipstream {
namespace {

GLint loc(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

}  // namespace

Status PlainTextureRenderer::create(const uint8_t* rgba, uint32_t width_px, uint32_t height_px,
                                    std::unique_ptr<PlainTextureRenderer>* out) {
  out->reset();
  std::unique_ptr<PlainTextureRenderer> r(new PlainTextureRenderer());
  Status s = gl_util::buildGroundProgram(shaders::k_ground_plain_frag, &r->m_program);
  if (!s) return s;
  glCreateVertexArrays(1, &r->m_vao);
  uint32_t mips = 1;
  while ((std::max(width_px, height_px) >> mips) > 0) ++mips;
  glCreateTextures(GL_TEXTURE_2D, 1, &r->m_texture);
  glTextureStorage2D(r->m_texture, GLsizei(mips), GL_RGBA8, GLsizei(width_px), GLsizei(height_px));
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glTextureSubImage2D(r->m_texture, 0, 0, 0, GLsizei(width_px), GLsizei(height_px), GL_RGBA,
                      GL_UNSIGNED_BYTE, rgba);
  glGenerateTextureMipmap(r->m_texture);
  glTextureParameteri(r->m_texture, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTextureParameteri(r->m_texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  r->m_width_px = width_px;
  r->m_height_px = height_px;
  *out = std::move(r);
  return okStatus();
}

PlainTextureRenderer::~PlainTextureRenderer() {
  glDeleteProgram(m_program);
  glDeleteVertexArrays(1, &m_vao);
  glDeleteTextures(1, &m_texture);
}

void PlainTextureRenderer::draw(const Camera& camera, const Viewport& viewport) {
  const GLuint p = m_program;
  gl_util::setRayUniforms(p, camera, viewport, m_width_px, m_height_px);
  glProgramUniform2f(p, loc(p, "uCamUv"), float(camera.position.x / m_width_px),
                     float(camera.position.z / m_height_px));
  glProgramUniform2f(p, loc(p, "uInvSize"), float(1.0 / m_width_px), float(1.0 / m_height_px));
  glProgramUniform1i(p, loc(p, "uPlain"), 0);
  glBindTextureUnit(0, m_texture);
  glUseProgram(p);
  glBindVertexArray(m_vao);
  glDisable(GL_DEPTH_TEST);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glBindVertexArray(0);
  glUseProgram(0);
}

}  // namespace clipstream
