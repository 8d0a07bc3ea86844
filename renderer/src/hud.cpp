#include <clipstream/renderer/hud.h>

#include "gl.h"
#include "gl_util.h"
#include "shaders.h"

#include <algorithm>
#include <cstddef>
#include <utility>
#include <string>

// Header-only: every function is static to this file (two unused here).
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wshadow"
#endif
#include <stb/stb_easy_font.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

namespace clipstream {

Status Hud::create(std::unique_ptr<Hud>* out) {
  std::unique_ptr<Hud> hud(new Hud());
  if (Status s = gl_util::buildProgram(shaders::k_hud_vert, shaders::k_hud_frag, &hud->m_program); !s)
    return s;
  hud->m_window_px_uniform = glGetUniformLocation(hud->m_program, "uWindowPx");
  gl_util::clearErrors();
  glCreateVertexArrays(1, &hud->m_vao);
  glCreateBuffers(1, &hud->m_vbo);
  glVertexArrayVertexBuffer(hud->m_vao, 0, hud->m_vbo, 0, sizeof(Vertex));
  glEnableVertexArrayAttrib(hud->m_vao, 0);
  glVertexArrayAttribFormat(hud->m_vao, 0, 2, GL_FLOAT, GL_FALSE, offsetof(Vertex, x));
  glVertexArrayAttribBinding(hud->m_vao, 0, 0);
  glEnableVertexArrayAttrib(hud->m_vao, 1);
  glVertexArrayAttribFormat(hud->m_vao, 1, 4, GL_UNSIGNED_BYTE, GL_TRUE, offsetof(Vertex, colour));
  glVertexArrayAttribBinding(hud->m_vao, 1, 0);
  if (Status s = gl_util::checkCreated("the HUD's vertex buffer"); !s) return s;
  *out = std::move(hud);
  return okStatus();
}

Hud::~Hud() {
  glDeleteBuffers(1, &m_vbo);
  glDeleteVertexArrays(1, &m_vao);
  glDeleteProgram(m_program);
}

float Hud::textWidth(std::string_view text, float scale) {
  std::string copy(text);
  return float(stb_easy_font_width(copy.data())) * scale;
}

void Hud::clear() { m_vertices.clear(); }

void Hud::text(float x_px, float y_px, std::string_view text, HudColour colour, float scale) {
  // stb_easy_font writes quads of four 16-byte vertices (x, y, z, RGBA);
  // about 270 bytes a character is its documented worst case.
  struct EasyVertex {
    float x, y, z;
    uint8_t rgba[4];
  };
  static_assert(sizeof(EasyVertex) == 16);
  std::string copy(text);
  std::vector<EasyVertex> quads(copy.size() * 18 + 64);
  const int count = stb_easy_font_print(0.0f, 0.0f, copy.data(), colour.data(), quads.data(),
                                        int(quads.size() * sizeof(EasyVertex)));
  for (int q = 0; q < count; ++q) {
    const EasyVertex* v = &quads[size_t(q) * 4];
    for (int corner : {0, 1, 2, 0, 2, 3}) {
      m_vertices.push_back({x_px + v[corner].x * scale, y_px + v[corner].y * scale, colour});
    }
  }
}

void Hud::box(float x_px, float y_px, float width_px, float height_px, HudColour colour) {
  const float x1 = x_px + width_px, y1 = y_px + height_px;
  for (const auto& [x, y] : {std::pair{x_px, y_px}, {x1, y_px}, {x1, y1}, {x_px, y_px}, {x1, y1}, {x_px, y1}})
    m_vertices.push_back({x, y, colour});
}

void Hud::draw(uint32_t width_px, uint32_t height_px) {
  if (m_vertices.empty()) return;
  glNamedBufferData(m_vbo, GLsizeiptr(m_vertices.size() * sizeof(Vertex)), m_vertices.data(), GL_STREAM_DRAW);
  const GLboolean blend = glIsEnabled(GL_BLEND), depth = glIsEnabled(GL_DEPTH_TEST),
                  cull = glIsEnabled(GL_CULL_FACE);
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_CULL_FACE);
  glViewport(0, 0, GLsizei(width_px), GLsizei(height_px));
  glUseProgram(m_program);
  glUniform2f(m_window_px_uniform, float(width_px), float(height_px));
  glBindVertexArray(m_vao);
  glDrawArrays(GL_TRIANGLES, 0, GLsizei(m_vertices.size()));
  glBindVertexArray(0);
  glUseProgram(0);
  if (!blend) glDisable(GL_BLEND);
  if (depth) glEnable(GL_DEPTH_TEST);
  if (cull) glEnable(GL_CULL_FACE);
}

void readWindowPixels(uint32_t width_px, uint32_t height_px, std::vector<uint8_t>* rgba) {
  const size_t row = size_t(width_px) * 4;
  std::vector<uint8_t> bottom_up(row * height_px);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, GLsizei(width_px), GLsizei(height_px), GL_RGBA, GL_UNSIGNED_BYTE, bottom_up.data());
  rgba->resize(bottom_up.size());
  for (uint32_t y = 0; y < height_px; ++y)
    std::copy_n(&bottom_up[(height_px - 1 - y) * row], row, &(*rgba)[y * row]);
}

}  // namespace clipstream
