// Baseline for the frame benchmark: the same ground as the clipmap renderer
// (the same ray set-up, renderer/shaders/ground_ray.glsl) from one ordinary
// mipmapped 2D texture with hardware trilinear filtering. A benchmark's
// comparison method, not part of the library.
//
// Owned by the GL thread: create it and call draw() on the thread whose
// context is current.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
#include <memory>

namespace clipstream {

class PlainTextureRenderer {
 public:
  // `rgba` holds width*height*4 bytes, top row first.
  static Status create(const uint8_t* rgba, uint32_t width_px, uint32_t height_px,
                       std::unique_ptr<PlainTextureRenderer>* out);
  ~PlainTextureRenderer();
  PlainTextureRenderer(const PlainTextureRenderer&) = delete;
  PlainTextureRenderer& operator=(const PlainTextureRenderer&) = delete;
  // Draws into the bound framebuffer (cleared by the caller).
  void draw(const Camera& camera, const Viewport& viewport);

 private:
  PlainTextureRenderer() = default;
  uint32_t m_program = 0, m_vao = 0, m_texture = 0;
  uint32_t m_width_px = 0, m_height_px = 0;
};

}  // namespace clipstream
