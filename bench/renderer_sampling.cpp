// What sampling a block-compressed colour stack costs on this GL: RGBA8, BC1
// (the stack's compressed format) and BC7 (BPTC, which the product cannot
// write: Debian 12 packages no BC7 encoder; docs/decisions.md D234).
//
// Each format fills a 2D array texture shaped like the colour clip stack
// (--layers layers of --side^2 texels, full mip chain, trilinear) with the
// same textured pattern; a full-screen pass then samples it through a tilted
// ground plane, each fragment picking the layer whose window holds its ground
// point (layer L spans side * 2^L level-0 texels around the camera), so many
// mips and several layers are read, as in a clipmap frame. Frames of the
// three formats are interleaved, so load from other processes hits all alike;
// a frame's time is draw + glFinish, wall clock (and the render thread's CPU
// time, which is the whole frame's work only with LP_NUM_THREADS=0).
// Sampling cost does not depend on block content, so BC7's blocks come from a
// minimal mode-6 writer (below), not from an encoder.
//
// Also: the upload time of one 128^2 tile into level 0 (glTextureSubImage3D,
// glCompressedTextureSubImage3D, each followed by glFinish, median of many)
// and the bytes of a tile.
//
// Checks that the draws are real: sampled pixels must not be the clear
// colour, and the BC1 and BC7 frames must stay close to the RGBA8 frame (a
// block the sampler rejected decodes to black). Exit 1 with a message if not.
//
//   bench_renderer_sampling [--sizes 1280x720,1920x1080] [--frames 60] [--side 2048] [--layers 8]
//                           [--upload-tiles 256] [--tsv FILE] [--upload-tsv FILE]
// Prints Markdown tables; --tsv FILE writes the frames' table into FILE and
// --upload-tsv FILE the uploads', tab-separated (docs/data/renderer_sampling_*.tsv).
#include <clipstream/cli/sizes.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/bc1.h>

#include "gl.h"
#include "gl_util.h"
#include "tsv_out.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

using namespace clipstream;

namespace {

constexpr uint32_t kTilePx = 128;  // the stack's tile size (uploads are timed per tile)

using Clock = std::chrono::steady_clock;

double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

double pct(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[size_t(p * double(v.size() - 1) + 0.5)];
}

// The textured pattern (bench_renderer_frame's, shifted per layer): smooth
// red and green waves and an 8-texel blue checker, never the clear colour.
void patternTexel(uint32_t x, uint32_t y, uint32_t layer, uint8_t* p) {
  const double fx = double(x + 517 * layer), fy = double(y + 331 * layer);
  p[0] = uint8_t(128 + 100 * std::sin(fx * 0.071) * std::cos(fy * 0.053));
  p[1] = uint8_t(128 + 90 * std::sin((fx + 2.0 * fy) * 0.019));
  p[2] = (((x / 8) + (y / 8) + layer) & 1) ? 200 : 60;
  p[3] = 255;
}

// RGBA8, w x h texels from (x0, y0) of level 0 of `layer`, top row first.
std::vector<uint8_t> patternImage(uint32_t x0, uint32_t y0, uint32_t w, uint32_t h, uint32_t layer) {
  std::vector<uint8_t> rgba(size_t(w) * h * 4);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) patternTexel(x0 + x, y0 + y, layer, &rgba[(size_t(y) * w + x) * 4]);
  return rgba;
}

// 2x2 box filter of a side^2 RGBA8 image (side even).
std::vector<uint8_t> halve(const std::vector<uint8_t>& rgba, uint32_t side) {
  const uint32_t h = side / 2;
  std::vector<uint8_t> out(size_t(h) * h * 4);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < h; ++x)
      for (uint32_t c = 0; c < 4; ++c) {
        auto at = [&](uint32_t xx, uint32_t yy) { return uint32_t(rgba[(size_t(yy) * side + xx) * 4 + c]); };
        out[(size_t(y) * h + x) * 4 + c] =
            uint8_t((at(2 * x, 2 * y) + at(2 * x + 1, 2 * y) + at(2 * x, 2 * y + 1) + at(2 * x + 1, 2 * y + 1) + 2) / 4);
      }
  return out;
}

// A side^2 image with side < 4 (the last mips) padded to one 4x4 block by
// repeating its edge texels.
std::vector<uint8_t> padToBlock(const std::vector<uint8_t>& rgba, uint32_t side) {
  std::vector<uint8_t> out(16 * 4);
  for (uint32_t y = 0; y < 4; ++y)
    for (uint32_t x = 0; x < 4; ++x)
      std::memcpy(&out[(y * 4 + x) * 4], &rgba[(size_t(std::min(y, side - 1)) * side + std::min(x, side - 1)) * 4], 4);
  return out;
}

// A minimal BPTC (BC7) mode-6 block writer, for measuring sampling only: it
// is not an encoder the product uses, and its picture quality is not a
// concern (docs/decisions.md D234). Mode 6 is one subset, RGBA
// end points of 7 bits plus one p-bit each, and 4-bit indices. The end points
// are the block's per-channel minimum (p-bit 0) and maximum (p-bit 1), so the
// decoded end points bracket every texel; each texel's index is its projection
// on the line between them. The layout (ARB_texture_compression_bptc): bits
// 0-6 the mode (bit 6 set), then R0 R1 G0 G1 B0 B1 A0 A1 (7 bits each), P0 P1,
// then the 16 indices in texel order (row-major), the first one (the anchor)
// with 3 bits: its top bit must be 0, so the end points are swapped and the
// indices inverted when it would be 1.
void writeBc7Mode6Block(const uint8_t texels[16 * 4], uint8_t out[16]) {
  uint32_t q[2][4], end[2][4];  // q: 7-bit end point values; end: decoded (q << 1 | p-bit)
  for (uint32_t c = 0; c < 4; ++c) {
    uint32_t lo = 255, hi = 0;
    for (uint32_t i = 0; i < 16; ++i) {
      lo = std::min<uint32_t>(lo, texels[i * 4 + c]);
      hi = std::max<uint32_t>(hi, texels[i * 4 + c]);
    }
    q[0][c] = lo >> 1;
    q[1][c] = hi >> 1;
    end[0][c] = q[0][c] << 1;
    end[1][c] = (q[1][c] << 1) | 1;
  }
  int32_t axis[3], axis_len2 = 0;
  for (uint32_t c = 0; c < 3; ++c) {
    axis[c] = int32_t(end[1][c]) - int32_t(end[0][c]);
    axis_len2 += axis[c] * axis[c];
  }
  uint32_t index[16];
  for (uint32_t i = 0; i < 16; ++i) {
    int32_t dot = 0;
    for (uint32_t c = 0; c < 3; ++c) dot += (int32_t(texels[i * 4 + c]) - int32_t(end[0][c])) * axis[c];
    index[i] = axis_len2 == 0 ? 0 : uint32_t(std::clamp(int32_t(std::lround(15.0 * dot / axis_len2)), 0, 15));
  }
  uint32_t p[2] = {0, 1};
  if (index[0] >= 8) {
    for (uint32_t c = 0; c < 4; ++c) std::swap(q[0][c], q[1][c]);
    std::swap(p[0], p[1]);
    for (uint32_t& i : index) i = 15 - i;
  }
  std::memset(out, 0, 16);
  uint32_t bit = 0;
  auto put = [&](uint32_t value, uint32_t bits) {
    for (uint32_t b = 0; b < bits; ++b, ++bit)
      if ((value >> b) & 1) out[bit / 8] |= uint8_t(1u << (bit % 8));
  };
  put(1u << 6, 7);
  for (uint32_t c = 0; c < 4; ++c) {
    put(q[0][c], 7);
    put(q[1][c], 7);
  }
  put(p[0], 1);
  put(p[1], 1);
  put(index[0], 3);
  for (uint32_t i = 1; i < 16; ++i) put(index[i], 4);
}

// BC7 blocks of a side^2 RGBA8 image (side a multiple of 4), row-major.
std::vector<uint8_t> encodeBc7Mode6(const std::vector<uint8_t>& rgba, uint32_t side) {
  const uint32_t n = side / 4;
  std::vector<uint8_t> blocks(size_t(n) * n * 16);
  uint8_t texels[16 * 4];
  for (uint32_t by = 0; by < n; ++by)
    for (uint32_t bx = 0; bx < n; ++bx) {
      for (uint32_t j = 0; j < 4; ++j)
        std::memcpy(texels + j * 16, &rgba[(size_t(by * 4 + j) * side + bx * 4) * 4], 16);
      writeBc7Mode6Block(texels, &blocks[(size_t(by) * n + bx) * 16]);
    }
  return blocks;
}

struct Format {
  const char* name;
  GLenum internal_format;
  bool compressed;
};
const Format kFormats[] = {{"RGBA8", GL_RGBA8, false},
                           {"BC1", GL_COMPRESSED_RGB_S3TC_DXT1_EXT, true},
                           {"BC7", GL_COMPRESSED_RGBA_BPTC_UNORM, true}};
constexpr size_t kFormatCount = std::size(kFormats);

// The bytes of a side^2 RGBA8 image in `f` (side < 4: one padded block).
std::vector<uint8_t> encodeImage(const Format& f, const std::vector<uint8_t>& rgba, uint32_t side) {
  if (!f.compressed) return rgba;
  const std::vector<uint8_t> padded = side < 4 ? padToBlock(rgba, side) : rgba;
  const uint32_t block_side = std::max<uint32_t>(side, 4);
  if (f.internal_format == GL_COMPRESSED_RGBA_BPTC_UNORM) return encodeBc7Mode6(padded, block_side);
  std::vector<uint8_t> blocks;
  if (Status s = encodeBc1Tile(padded, block_side, &blocks); !s) {
    std::fprintf(stderr, "BC1 encode: %s\n", s.toString().c_str());
    std::exit(1);
  }
  return blocks;
}

void uploadImage(const Format& f, GLuint tex, uint32_t level, uint32_t x, uint32_t y, uint32_t layer,
                 uint32_t w, uint32_t h, const std::vector<uint8_t>& bytes) {
  if (f.compressed)
    glCompressedTextureSubImage3D(tex, GLint(level), GLint(x), GLint(y), GLint(layer), GLsizei(w), GLsizei(h), 1,
                                  f.internal_format, GLsizei(bytes.size()), bytes.data());
  else
    glTextureSubImage3D(tex, GLint(level), GLint(x), GLint(y), GLint(layer), GLsizei(w), GLsizei(h), 1, GL_RGBA,
                        GL_UNSIGNED_BYTE, bytes.data());
}

// The stack-shaped array texture of `f`, every mip of every layer filled
// from the pattern. Exits with a message if GL reports an error or stores
// another format (e.g. no BPTC).
GLuint createStack(const Format& f, uint32_t side, uint32_t layers, uint32_t mips, uint64_t* bytes) {
  while (glGetError() != GL_NO_ERROR) {
  }
  GLuint tex = 0;
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &tex);
  glTextureStorage3D(tex, GLsizei(mips), f.internal_format, GLsizei(side), GLsizei(side), GLsizei(layers));
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  *bytes = 0;
  for (uint32_t layer = 0; layer < layers; ++layer) {
    std::vector<uint8_t> rgba = patternImage(0, 0, side, side, layer);
    for (uint32_t m = 0, s = side; m < mips; ++m, s /= 2) {
      const std::vector<uint8_t> data = encodeImage(f, rgba, s);
      uploadImage(f, tex, m, 0, 0, layer, s, s, data);
      *bytes += data.size();
      if (s > 1) rgba = halve(rgba, s);
    }
  }
  glTextureParameteri(tex, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTextureParameteri(tex, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(tex, GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTextureParameteri(tex, GL_TEXTURE_WRAP_T, GL_REPEAT);
  glFinish();
  const GLenum err = glGetError();
  GLint stored = 0, compressed = 0;
  glGetTextureLevelParameteriv(tex, 0, GL_TEXTURE_INTERNAL_FORMAT, &stored);
  glGetTextureLevelParameteriv(tex, 0, GL_TEXTURE_COMPRESSED, &compressed);
  if (err != GL_NO_ERROR || GLenum(stored) != f.internal_format || (compressed != 0) != f.compressed) {
    std::fprintf(stderr,
                 "creating the %s texture (internal format 0x%04x) failed: GL error 0x%04x, stored format 0x%04x, "
                 "compressed %d; %s\n",
                 f.name, f.internal_format, err, unsigned(stored), compressed,
                 f.internal_format == GL_COMPRESSED_RGBA_BPTC_UNORM
                     ? "is BPTC (ARB_texture_compression_bptc) supported by this GL?"
                     : "is the format supported by this GL?");
    std::exit(1);
  }
  return tex;
}

// Full-screen triangle; the fragment shader's inputs:
//   vNdc: the fragment's normalised device position (-1..1).
//   uAspect: width / height; uTanHalfFov: tan(vertical field of view / 2).
//   uPitch, uHeading: radians (pitch < 0 looks down; heading 0 looks to -z).
//   uHeight: the camera's height above the ground, in level-0 texels.
//   uSpan: level-0 texels across layer 0; layer L spans uSpan * 2^L.
//   uLayers: layers in uStack; uOffset: the camera's position in layer
//   units (so windows are not centred on a texel corner).
const char* kVertex = R"(
out vec2 vNdc;
void main() {
  vNdc = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
  gl_Position = vec4(vNdc, 0.0, 1.0);
}
)";
const char* kFragment = R"(
in vec2 vNdc;
out vec4 oColor;
uniform sampler2DArray uStack;
uniform float uAspect, uTanHalfFov, uPitch, uHeading, uHeight, uSpan;
uniform int uLayers;
uniform vec2 uOffset;
void main() {
  vec3 d = normalize(vec3(vNdc.x * uAspect * uTanHalfFov, vNdc.y * uTanHalfFov, -1.0));
  float cp = cos(uPitch), sp = sin(uPitch), ch = cos(uHeading), sh = sin(uHeading);
  d = vec3(d.x, cp * d.y - sp * d.z, sp * d.y + cp * d.z);
  d = vec3(ch * d.x + sh * d.z, d.y, -sh * d.x + ch * d.z);
  // Rows at or above the horizon see a far band of the ground instead of sky,
  // so every fragment samples.
  d.y = min(d.y, -0.01);
  vec2 g = d.xz * (uHeight / -d.y);  // ground point relative to the camera, texels
  float r = max(abs(g.x), abs(g.y));
  float layer = clamp(ceil(log2(max(r, 1.0) / (0.45 * uSpan))), 0.0, float(uLayers - 1));
  vec2 uv = g / (uSpan * exp2(layer)) + 0.5 + uOffset;
  oColor = vec4(texture(uStack, vec3(uv, layer)).rgb, 1.0);
}
)";

constexpr float kClear[4] = {1.0f, 0.0f, 1.0f, 1.0f};  // magenta: the pattern has no red 255

struct Pass {
  GLuint program = 0, vao = 0;
  void draw(GLuint tex, const Viewport& vp, uint32_t side, uint32_t layers) const {
    auto loc = [&](const char* n) { return glGetUniformLocation(program, n); };
    glProgramUniform1f(program, loc("uAspect"), float(vp.width_px) / float(vp.height_px));
    glProgramUniform1f(program, loc("uTanHalfFov"), float(std::tan(30.0 * M_PI / 180.0)));
    glProgramUniform1f(program, loc("uPitch"), -0.5f);
    glProgramUniform1f(program, loc("uHeading"), 0.35f);
    glProgramUniform1f(program, loc("uHeight"), 300.0f);
    glProgramUniform1f(program, loc("uSpan"), float(side));
    glProgramUniform1i(program, loc("uLayers"), GLint(layers));
    glProgramUniform2f(program, loc("uOffset"), 0.137f, 0.291f);
    glProgramUniform1i(program, loc("uStack"), 0);
    glBindTextureUnit(0, tex);
    glUseProgram(program);
    glBindVertexArray(vao);
    glDisable(GL_DEPTH_TEST);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glBindVertexArray(0);
    glUseProgram(0);
  }
};

void clearTarget(const OffscreenTarget& target) {
  target.bind();
  glClearColor(kClear[0], kClear[1], kClear[2], kClear[3]);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
}

bool isClear(const uint8_t* p) { return p[0] == 255 && p[1] == 0 && p[2] == 255; }

std::vector<std::string> splitComma(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    const size_t end = s.find(',', start);
    out.push_back(s.substr(start, end == std::string::npos ? std::string::npos : end - start));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return out;
}

struct Options {
  std::vector<Viewport> sizes;
  uint32_t frames = 60, side = 2048, layers = 8, upload_tiles = 256;
};

// Reads the command line (less the --tsv options) into *o; false after
// printing why it cannot.
bool parseOptions(int argc, char** argv, Options* o) {
  std::string sizes_text = "1280x720,1920x1080";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s needs a value\n", a.c_str());
      return false;
    }
    const char* v = argv[++i];
    if (a == "--sizes") sizes_text = v;
    else if (a == "--frames") o->frames = uint32_t(std::max(1, std::atoi(v)));
    else if (a == "--side") o->side = uint32_t(std::atoi(v));
    else if (a == "--layers") o->layers = uint32_t(std::max(1, std::atoi(v)));
    else if (a == "--upload-tiles") o->upload_tiles = uint32_t(std::max(1, std::atoi(v)));
    else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return false;
    }
  }
  if (o->side < kTilePx || (o->side & (o->side - 1)) != 0) {
    std::fprintf(stderr, "--side must be a power of two >= %u, got %u\n", kTilePx, o->side);
    return false;
  }
  for (const std::string& t : splitComma(sizes_text)) {
    Viewport vp;
    if (Status s = cli::parseSize(t, &vp.width_px, &vp.height_px); !s) {
      std::fprintf(stderr, "--sizes: %s\n", s.toString().c_str());
      return false;
    }
    o->sizes.push_back(vp);
  }
  return true;
}

// The draws are real: no sampled pixel is the clear colour, and the
// compressed frames stay near the RGBA8 one. Fills mad[f], the mean absolute
// difference of format f's frame to the RGBA8 frame; false after printing
// what is wrong.
bool checkFrames(const Pass& pass, const OffscreenTarget& target, const Viewport& vp, const GLuint tex[],
                 const Options& o, double mad[]) {
  std::vector<uint8_t> frame[kFormatCount];
  for (size_t f = 0; f < kFormatCount; ++f) {
    clearTarget(target);
    pass.draw(tex[f], vp, o.side, o.layers);
    target.readRgba(&frame[f]);
    for (uint32_t j = 0; j < 5; ++j)
      for (uint32_t i = 0; i < 5; ++i) {
        const uint32_t x = (vp.width_px - 1) * i / 4, y = (vp.height_px - 1) * j / 4;
        const uint8_t* p = &frame[f][(size_t(y) * vp.width_px + x) * 4];
        if (isClear(p)) {
          std::fprintf(stderr, "%s at %ux%u: pixel (%u, %u) is the clear colour: the draw did not happen\n",
                       kFormats[f].name, vp.width_px, vp.height_px, x, y);
          return false;
        }
      }
    uint64_t sum = 0;
    for (size_t k = 0; k < frame[f].size(); k += 4)
      for (size_t c = 0; c < 3; ++c) sum += uint64_t(std::abs(int(frame[f][k + c]) - int(frame[0][k + c])));
    mad[f] = double(sum) / double(frame[f].size() / 4 * 3);
    // BC1 of this pattern is within ~1 level; a rejected BPTC block would
    // read as black (about 100 levels off).
    if (mad[f] > 12.0) {
      std::fprintf(stderr, "%s at %ux%u: mean |difference| to the RGBA8 frame is %.1f levels (> 12): "
                   "the texture does not hold the pattern\n", kFormats[f].name, vp.width_px, vp.height_px, mad[f]);
      return false;
    }
  }
  return true;
}

// Times the frames of every format at one size, interleaved, and prints
// their rows.
void timeFrames(const Pass& pass, const OffscreenTarget& target, const Viewport& vp, const GLuint tex[],
                const uint64_t tex_bytes[], const double mad[], const Options& o, bench::TsvOut* frame_table) {
  std::vector<double> wall[kFormatCount], cpu[kFormatCount];
  const uint32_t warmup = 3;
  for (uint32_t round = 0; round < warmup + o.frames; ++round)
    for (size_t k = 0; k < kFormatCount; ++k) {
      const size_t f = (k + round) % kFormatCount;  // rotate the order too
      clearTarget(target);
      glFinish();
      const double c0 = threadCpuMs();
      const auto t0 = Clock::now();
      pass.draw(tex[f], vp, o.side, o.layers);
      glFinish();
      const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
      if (round >= warmup) {
        wall[f].push_back(ms);
        cpu[f].push_back(threadCpuMs() - c0);
      }
    }
  const double base = pct(wall[0], 0.5), cpu_base = pct(cpu[0], 0.5);
  for (size_t f = 0; f < kFormatCount; ++f) {
    std::printf("| %ux%u | %s | %.1f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f |\n", vp.width_px, vp.height_px,
                kFormats[f].name, double(tex_bytes[f]) / (1 << 20), pct(wall[f], 0.5), pct(wall[f], 0.9),
                pct(wall[f], 0.5) / base, pct(cpu[f], 0.5), pct(cpu[f], 0.5) / cpu_base, mad[f]);
    frame_table->fileOnly("%ux%u\t%s\t%.1f\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\n", vp.width_px, vp.height_px,
                          kFormats[f].name, double(tex_bytes[f]) / (1 << 20), pct(wall[f], 0.5), pct(wall[f], 0.9),
                          pct(wall[f], 0.5) / base, pct(cpu[f], 0.5), pct(cpu[f], 0.5) / cpu_base, mad[f]);
  }
}

// Uploads of 128^2 tiles into level 0, at tile positions over the layers,
// with the pattern that is there already (the picture does not change);
// prints the uploads' table. False after printing a GL error.
bool timeUploads(const GLuint tex[], const Options& o, bench::TsvOut* upload_table) {
  std::printf("\n| format | bytes_per_tile | upload_median_us | upload_p90_us | vs_RGBA8 |\n|---|---|---|---|---|\n");
  upload_table->fileOnly("format\tbytes_per_tile\tupload_median_us\tupload_p90_us\tvs_RGBA8\n");
  const uint32_t tiles_side = o.side / kTilePx;
  std::vector<double> upload_us[kFormatCount];
  size_t tile_bytes[kFormatCount] = {};
  for (uint32_t t = 0; t < o.upload_tiles; ++t) {
    const uint32_t tx = t % tiles_side, ty = (t / tiles_side) % tiles_side, layer = t % o.layers;
    const std::vector<uint8_t> rgba = patternImage(tx * kTilePx, ty * kTilePx, kTilePx, kTilePx, layer);
    for (size_t k = 0; k < kFormatCount; ++k) {
      const size_t f = (k + t) % kFormatCount;
      const std::vector<uint8_t> data = encodeImage(kFormats[f], rgba, kTilePx);
      tile_bytes[f] = data.size();
      glFinish();
      const auto t0 = Clock::now();
      uploadImage(kFormats[f], tex[f], 0, tx * kTilePx, ty * kTilePx, layer, kTilePx, kTilePx, data);
      glFinish();
      upload_us[f].push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    }
  }
  if (const GLenum err = glGetError(); err != GL_NO_ERROR) {
    std::fprintf(stderr, "GL error 0x%04x after the tile uploads\n", err);
    return false;
  }
  const double upload_base = pct(upload_us[0], 0.5);
  for (size_t f = 0; f < kFormatCount; ++f) {
    std::printf("| %s | %zu | %.1f | %.1f | %.2f |\n", kFormats[f].name, tile_bytes[f], pct(upload_us[f], 0.5),
                pct(upload_us[f], 0.9), pct(upload_us[f], 0.5) / upload_base);
    upload_table->fileOnly("%s\t%zu\t%.1f\t%.1f\t%.2f\n", kFormats[f].name, tile_bytes[f], pct(upload_us[f], 0.5),
                           pct(upload_us[f], 0.9), pct(upload_us[f], 0.5) / upload_base);
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut frame_table(bench::takeOption(&argc, argv, "--tsv"));
  bench::TsvOut upload_table(bench::takeOption(&argc, argv, "--upload-tsv"));
  if (!frame_table.ok() || !upload_table.ok()) return 1;
  Options o;
  if (!parseOptions(argc, argv, &o)) return 2;

  std::unique_ptr<HeadlessContext> ctx;
  if (Status s = HeadlessContext::create(&ctx); !s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  keepHeapForSoftwareGl();  // as every frame loop of the product does
  Pass pass;
  if (Status s = gl_util::buildProgram(kVertex, kFragment, &pass.program); !s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  glCreateVertexArrays(1, &pass.vao);

  uint32_t mips = 1;
  while ((o.side >> mips) > 0) ++mips;
  GLuint tex[kFormatCount];
  uint64_t tex_bytes[kFormatCount];
  for (size_t f = 0; f < kFormatCount; ++f) tex[f] = createStack(kFormats[f], o.side, o.layers, mips, &tex_bytes[f]);

  const char* threads = std::getenv("LP_NUM_THREADS");
  std::printf("%s, %u layers of %u^2 texels, %u mips, trilinear; %u frames per format and size, interleaved; "
              "LP_NUM_THREADS=%s\n\n",
              ctx->describe().c_str(), o.layers, o.side, mips, o.frames, threads ? threads : "(unset)");
  std::printf("| size | format | texture_MiB | frame_median_ms | frame_p90_ms | vs_RGBA8 | cpu_median_ms | "
              "cpu_vs_RGBA8 | mean_abs_diff_vs_RGBA8 |\n|---|---|---|---|---|---|---|---|---|\n");
  frame_table.fileOnly("size\tformat\ttexture_MiB\tframe_median_ms\tframe_p90_ms\tvs_RGBA8\tcpu_median_ms\t"
                       "cpu_vs_RGBA8\tmean_abs_diff_vs_RGBA8\n");
  for (const Viewport& vp : o.sizes) {
    std::unique_ptr<OffscreenTarget> target;
    if (Status s = OffscreenTarget::create(vp, &target); !s) {
      std::fprintf(stderr, "%s\n", s.toString().c_str());
      return 1;
    }
    double mad[kFormatCount] = {};
    if (!checkFrames(pass, *target, vp, tex, o, mad)) return 1;
    timeFrames(pass, *target, vp, tex, tex_bytes, mad, o, &frame_table);
  }

  if (!timeUploads(tex, o, &upload_table)) return 1;

  glDeleteTextures(GLsizei(kFormatCount), tex);
  glDeleteVertexArrays(1, &pass.vao);
  glDeleteProgram(pass.program);
  return frame_table.commit() && upload_table.commit() ? 0 : 1;
}
