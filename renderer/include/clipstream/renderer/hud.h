// A head-up display over the frame in a window: lines of ASCII text (the
// stb_easy_font glyphs) and filled boxes in window pixels, drawn blended on
// top of whatever the frame drew. clipstream-view shows its statistics, key
// help and the overlay's legend with it. And the window's pixels read back,
// for a screenshot.
//
// Render thread only: create, add, draw and destroy with the context that
// draws the frame current.
#pragma once

#include <clipstream/store/types.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

namespace clipstream {

using HudColour = std::array<uint8_t, 4>;  // RGBA, A = opacity

class Hud {
 public:
  // kUnavailable with the compiler's log if the shaders do not build.
  static Status create(std::unique_ptr<Hud>* out);
  ~Hud();
  Hud(const Hud&) = delete;
  Hud& operator=(const Hud&) = delete;

  // Glyph size at scale 1 (stb_easy_font): a line is 12 pixels high, a
  // character about 6 wide.
  static constexpr float kLinePx = 12.0f;
  // Width in pixels of the widest line of `text` at `scale`.
  static float textWidth(std::string_view text, float scale);

  // Starts a new frame's HUD: forgets what was added.
  void clear();
  // Text with its top-left corner at (x, y), '\n' starting a new line.
  void text(float x_px, float y_px, std::string_view text, HudColour colour, float scale);
  // A filled box.
  void box(float x_px, float y_px, float width_px, float height_px, HudColour colour);
  // Draws what was added since clear() over the bound framebuffer of this
  // size, blended, without depth; GL state it changes is restored.
  void draw(uint32_t width_px, uint32_t height_px);

 private:
  Hud() = default;
  struct Vertex {
    float x, y;
    HudColour colour;
  };
  std::vector<Vertex> m_vertices;  // triangles
  uint32_t m_program = 0, m_vao = 0, m_vbo = 0;
  int32_t m_window_px_uniform = -1;
};

// Reads the bound read framebuffer's colour (the window's back buffer
// before the swap) as RGBA8, top row first. Render thread only.
void readWindowPixels(uint32_t width_px, uint32_t height_px, std::vector<uint8_t>* rgba);

}  // namespace clipstream
