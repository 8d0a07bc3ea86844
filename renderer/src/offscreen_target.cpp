// OffscreenTarget, the headless frames' framebuffer, and the window's.
#include <clipstream/renderer/renderer.h>

#include "gl.h"
#include "gl_util.h"

#include <algorithm>
#include <string>

namespace clipstream {

Status OffscreenTarget::create(const Viewport& viewport, std::unique_ptr<OffscreenTarget>* out) {
  out->reset();
  if (viewport.width_px == 0 || viewport.height_px == 0)
    return Status::error(ErrorCode::kInvalidArgument, "offscreen target: empty viewport");
  std::unique_ptr<OffscreenTarget> t(new OffscreenTarget());
  t->m_viewport = viewport;
  gl_util::clearErrors();
  glCreateRenderbuffers(1, &t->m_color);
  glNamedRenderbufferStorage(t->m_color, GL_RGBA8, GLsizei(viewport.width_px),
                             GLsizei(viewport.height_px));
  glCreateRenderbuffers(1, &t->m_depth);
  glNamedRenderbufferStorage(t->m_depth, GL_DEPTH_COMPONENT24, GLsizei(viewport.width_px),
                             GLsizei(viewport.height_px));
  glCreateFramebuffers(1, &t->m_fbo);
  glNamedFramebufferRenderbuffer(t->m_fbo, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, t->m_color);
  glNamedFramebufferRenderbuffer(t->m_fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, t->m_depth);
  if (Status s = gl_util::checkCreated("the offscreen target (" + std::to_string(viewport.width_px) + "x" +
                                       std::to_string(viewport.height_px) + ")");
      !s)
    return s;
  if (glCheckNamedFramebufferStatus(t->m_fbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    return Status::error(ErrorCode::kUnavailable, "offscreen framebuffer incomplete");
  *out = std::move(t);
  return okStatus();
}

OffscreenTarget::~OffscreenTarget() {
  glDeleteFramebuffers(1, &m_fbo);
  glDeleteRenderbuffers(1, &m_color);
  glDeleteRenderbuffers(1, &m_depth);
}

void OffscreenTarget::bind() const {
  glBindFramebuffer(GL_FRAMEBUFFER, m_fbo);
  glViewport(0, 0, GLsizei(m_viewport.width_px), GLsizei(m_viewport.height_px));
}

void bindWindowFramebuffer(const Viewport& framebuffer) {
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glViewport(0, 0, GLsizei(framebuffer.width_px), GLsizei(framebuffer.height_px));
}

void OffscreenTarget::readRgba(std::vector<uint8_t>* rgba) const {
  const size_t row = size_t(m_viewport.width_px) * 4;
  std::vector<uint8_t> bottom_up(row * m_viewport.height_px);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, m_fbo);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadPixels(0, 0, GLsizei(m_viewport.width_px), GLsizei(m_viewport.height_px), GL_RGBA,
               GL_UNSIGNED_BYTE, bottom_up.data());
  rgba->resize(bottom_up.size());
  for (uint32_t y = 0; y < m_viewport.height_px; ++y)
    std::copy_n(bottom_up.data() + size_t(m_viewport.height_px - 1 - y) * row, row,
                rgba->data() + size_t(y) * row);
}

}  // namespace clipstream
