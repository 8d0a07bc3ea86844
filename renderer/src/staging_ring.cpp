#include "staging_ring.h"

#include "gl.h"
#include "gl_util.h"

#include <cstring>
#include <string>

namespace clipstream {

StagingRing::~StagingRing() {
  for (void* fence : m_fence)
    if (fence != nullptr) glDeleteSync(static_cast<GLsync>(fence));
  if (m_buffer != 0) {
    glUnmapNamedBuffer(m_buffer);
    glDeleteBuffers(1, &m_buffer);
  }
}

Status StagingRing::create(size_t region_bytes) {
  m_region_bytes = region_bytes;
  const size_t bytes = m_region_bytes * renderer_config::kStagingFrames;
  const GLbitfield flags = GL_MAP_WRITE_BIT | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT;
  glCreateBuffers(1, &m_buffer);
  glNamedBufferStorage(m_buffer, GLsizeiptr(bytes), nullptr, flags);
  if (Status s = gl_util::checkCreated("the staging buffer (" + std::to_string(bytes >> 20) + " MiB)"); !s)
    return s;
  m_map = static_cast<uint8_t*>(glMapNamedBufferRange(m_buffer, 0, GLsizeiptr(bytes), flags));
  if (m_map == nullptr) return Status::error(ErrorCode::kUnavailable, "renderer: cannot map the staging buffer");
  return okStatus();
}

void StagingRing::beginFrame() {
  m_region = (m_region + 1) % renderer_config::kStagingFrames;
  m_used = 0;
  if (void*& fence = m_fence[m_region]; fence != nullptr) {
    glClientWaitSync(static_cast<GLsync>(fence), GL_SYNC_FLUSH_COMMANDS_BIT, uint64_t(10) * 1000000000);
    glDeleteSync(static_cast<GLsync>(fence));
    fence = nullptr;
  }
}

int64_t StagingRing::stage(const uint8_t* pixels, size_t bytes) {
  if (m_used + bytes > m_region_bytes) return -1;
  const size_t offset = size_t(m_region) * m_region_bytes + m_used;
  std::memcpy(m_map + offset, pixels, bytes);
  m_used += bytes;
  return int64_t(offset);
}

void StagingRing::fenceFrame() {
  if (m_used > 0 && m_fence[m_region] == nullptr) m_fence[m_region] = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
}

}  // namespace clipstream
