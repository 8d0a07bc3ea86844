#include "gl_util.h"

#include "gl.h"
#include "shaders.h"

#include <clipstream/renderer/config.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace clipstream::gl_util {
namespace {

Status compile(GLenum kind, const std::string& source, GLuint* out) {
  GLuint shader = glCreateShader(kind);
  const char* text = source.c_str();
  glShaderSource(shader, 1, &text, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &len);
    std::string log(size_t(len > 0 ? len : 1), '\0');
    glGetShaderInfoLog(shader, len, nullptr, log.data());
    glDeleteShader(shader);
    return Status::error(ErrorCode::kUnavailable, "shader compile failed: " + log);
  }
  *out = shader;
  return okStatus();
}

}  // namespace

void clearErrors() {
  // Bounded: a lost context may keep returning an error.
  for (int i = 0; i < 32 && glGetError() != GL_NO_ERROR; ++i) {
  }
}

Status checkCreated(const std::string& what, const std::string& hint) {
  const GLenum first = glGetError();
  if (first == GL_NO_ERROR) return okStatus();
  clearErrors();
  char code[16];
  std::snprintf(code, sizeof code, "0x%04x", unsigned(first));
  if (first == GL_OUT_OF_MEMORY) {
    return Status::error(ErrorCode::kOutOfMemory,
                         "the GL driver cannot allocate " + what + " (GL_OUT_OF_MEMORY)" +
                             (hint.empty() ? "" : ": " + hint));
  }
  const char* name = first == GL_INVALID_VALUE       ? "GL_INVALID_VALUE"
                     : first == GL_INVALID_OPERATION ? "GL_INVALID_OPERATION"
                     : first == GL_INVALID_ENUM      ? "GL_INVALID_ENUM"
                                                     : code;
  return Status::error(ErrorCode::kUnavailable, "the GL driver refused to create " + what + " (" + name + ")" +
                                                   (hint.empty() ? "" : ": " + hint));
}

std::string shaderHeader(const std::string& extra_defines) {
  return "#version 450 core\n#define MAX_LEVELS " + std::to_string(renderer_config::kMaxLevels) +
         "\n#define AMBIENT " + std::to_string(renderer_config::kTerrainAmbient) +
         "\n#define DETAIL_FADE_LEVELS " + std::to_string(renderer_config::kDetailFadeLevels) +
         "\n#define SKY_RGB vec3(" + std::to_string(renderer_config::kSkyRgba[0] / 255.0) + ", " +
         std::to_string(renderer_config::kSkyRgba[1] / 255.0) + ", " +
         std::to_string(renderer_config::kSkyRgba[2] / 255.0) + ")\n" + extra_defines;
}

Status buildGroundProgram(const char* fragment_body, uint32_t* program,
                          const std::string& extra_defines) {
  return buildProgram(shaders::k_fullscreen_vert,
                      std::string(shaders::k_ground_ray_glsl) + "\n" + fragment_body, program,
                      extra_defines);
}

Status buildProgram(const std::string& vertex, const std::string& fragment, uint32_t* program,
                    const std::string& extra_defines, const std::vector<const char*>& feedback) {
  const std::string header = shaderHeader(extra_defines);
  GLuint vs = 0, fs = 0;
  Status s = compile(GL_VERTEX_SHADER, header + vertex, &vs);
  if (!s) return s;
  s = compile(GL_FRAGMENT_SHADER, header + fragment, &fs);
  if (!s) {
    glDeleteShader(vs);
    return s;
  }
  GLuint p = glCreateProgram();
  glAttachShader(p, vs);
  glAttachShader(p, fs);
  if (!feedback.empty()) {
    glTransformFeedbackVaryings(p, GLsizei(feedback.size()), feedback.data(), GL_INTERLEAVED_ATTRIBS);
  }
  glLinkProgram(p);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetProgramiv(p, GL_INFO_LOG_LENGTH, &len);
    std::string log(size_t(len > 0 ? len : 1), '\0');
    glGetProgramInfoLog(p, len, nullptr, log.data());
    glDeleteProgram(p);
    return Status::error(ErrorCode::kUnavailable, "shader link failed: " + log);
  }
  *program = p;
  return okStatus();
}

void setRayUniforms(uint32_t program, const Camera& camera, const Viewport& viewport,
                    double image_width_px, double image_height_px) {
  const glm::dvec3 f = camera.forward(), r = camera.right(), u = camera.up();
  const double tan_half = std::tan(camera.vfov_rad * 0.5);
  const double aspect = double(viewport.width_px) / double(std::max(viewport.height_px, 1u));
  glProgramUniform3f(program, glGetUniformLocation(program, "uForward"), float(f.x), float(f.y),
                     float(f.z));
  glProgramUniform3f(program, glGetUniformLocation(program, "uRight"), float(r.x), float(r.y),
                     float(r.z));
  glProgramUniform3f(program, glGetUniformLocation(program, "uUp"), float(u.x), float(u.y),
                     float(u.z));
  glProgramUniform2f(program, glGetUniformLocation(program, "uNdcScale"),
                     float(tan_half * aspect), float(tan_half));
  glProgramUniform2f(program, glGetUniformLocation(program, "uViewportPx"),
                     float(viewport.width_px), float(viewport.height_px));
  glProgramUniform1f(program, glGetUniformLocation(program, "uHeight"), float(camera.position.y));
  // Subtracted in double: the rectangle relative to the camera.
  glProgramUniform4f(program, glGetUniformLocation(program, "uImageRel"),
                     float(-camera.position.x), float(-camera.position.z),
                     float(image_width_px - camera.position.x),
                     float(image_height_px - camera.position.z));
}

}  // namespace clipstream::gl_util
