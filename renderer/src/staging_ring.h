// Buffering::kStaged's ring: one pixel-unpack buffer, persistently mapped,
// cut into renderer_config::kStagingFrames regions of a frame's tiles each.
// A frame copies its tiles into its own region and the textures take them
// from there by copies the GPU runs after the frames already queued; a
// region is written again only kStagingFrames frames later, after the fence
// of the frame that last wrote it (normally long signalled: no wait).
//
// GL thread only (the renderer's).
#pragma once

#include <clipstream/renderer/config.h>
#include <clipstream/store/types.h>

#include <cstddef>
#include <cstdint>

namespace clipstream {

class StagingRing {
 public:
  StagingRing() = default;
  ~StagingRing();
  StagingRing(const StagingRing&) = delete;
  StagingRing& operator=(const StagingRing&) = delete;

  // The buffer for regions of `region_bytes` each, mapped. kUnavailable
  // (naming its size) when GL cannot make or map it.
  Status create(size_t region_bytes);
  bool created() const { return m_buffer != 0; }
  // Bytes of the whole ring (every region).
  uint64_t bytes() const { return uint64_t(m_region_bytes) * renderer_config::kStagingFrames; }

  // The next frame's region, after the fence of the frame that wrote it.
  void beginFrame();
  // Copies `bytes` of `pixels` into this frame's region and returns its
  // offset in the buffer; -1 when the region is full.
  int64_t stage(const uint8_t* pixels, size_t bytes);
  // Something was staged this frame.
  bool used() const { return m_used > 0; }
  // After the frame's copies out of the region are issued: its fence (once).
  void fenceFrame();
  // The buffer, to bind as GL_PIXEL_UNPACK_BUFFER.
  uint32_t buffer() const { return m_buffer; }

 private:
  uint32_t m_buffer = 0;
  uint8_t* m_map = nullptr;
  size_t m_region_bytes = 0;
  uint32_t m_region = 0;
  size_t m_used = 0;
  void* m_fence[renderer_config::kStagingFrames] = {};
};

}  // namespace clipstream
