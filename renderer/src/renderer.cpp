// The clipmap on the GPU. Slot rule, usable map: clipmap.cpp. Shader:
// shaders/ground_clipmap.frag. Why double-buffering: see docs/renderer.md.
#include <clipstream/renderer/renderer.h>

#include "gl.h"
#include "gl_util.h"
#include "shaders.h"
#include "tile_fill.h"

#include <clipstream/renderer/config.h>
#include <clipstream/streamer/bc1.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <utility>

namespace clipstream {
namespace {

using Clock = std::chrono::steady_clock;

using gl_util::msSince;

GLint loc(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

// Bytes of one size_px^2 image of `content` (BC1: whole 4x4 blocks).
uint64_t imageBytes(uint64_t size_px, TileContent content) {
  if (content == TileContent::kBc1) {
    const uint64_t blocks = (size_px + kBc1BlockPx - 1) / kBc1BlockPx;
    return blocks * blocks * kBc1BlockBytes;
  }
  return size_px * size_px * 4;
}

bool hasExtension(const char* name) {
  GLint n = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &n);
  for (GLint i = 0; i < n; ++i) {
    const char* e = reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, GLuint(i)));
    if (e != nullptr && std::strcmp(e, name) == 0) return true;
  }
  return false;
}

}  // namespace

const char* bufferingName(Buffering buffering) {
  switch (buffering) {
    case Buffering::kSingle: return "single";
    case Buffering::kDoubleUploadTwice: return "double-upload";
    case Buffering::kDoubleCopy: return "double-copy";
    case Buffering::kStaged: return "staged";
  }
  return "?";
}

const char* textureMemoryName(TextureMemory memory) {
  return memory == TextureMemory::kPaged ? "paged" : "stack";
}

Status textureMemoryFromName(const std::string& name, TextureMemory* out) {
  if (name == "stack") *out = TextureMemory::kStack;
  else if (name == "paged") *out = TextureMemory::kPaged;
  else
    return Status::error(ErrorCode::kInvalidArgument,
                         "texture memory '" + name + "' is not one of: stack, paged");
  return okStatus();
}

TextureMemory automaticTextureMemory(bool terrain, Buffering buffering) {
  const bool doubled = buffering == Buffering::kDoubleUploadTwice || buffering == Buffering::kDoubleCopy;
  return terrain || doubled ? TextureMemory::kStack : TextureMemory::kPaged;
}

Status textureMemoryFromChoice(const std::string& name, bool terrain, Buffering buffering, bool pool_given,
                               TextureMemory* out) {
  const bool automatic = name == "auto";
  if (automatic) *out = automaticTextureMemory(terrain, buffering);
  else if (!textureMemoryFromName(name, out))
    return Status::error(ErrorCode::kInvalidArgument,
                         "--texture-memory " + name + " is not one of: auto, stack, paged");
  if (!pool_given || *out == TextureMemory::kPaged) return okStatus();
  if (!automatic)
    return Status::error(ErrorCode::kInvalidArgument, "--pool-mb sizes the pool of --texture-memory paged");
  return Status::error(ErrorCode::kInvalidArgument,
                       std::string("--pool-mb sizes the page pool, and auto chose the stack (the pool does not draw ") +
                           (terrain ? "--elevation" : "double buffering") + " yet)");
}

PlannerConfig plannerFor(TextureMemory memory, PlannerConfig planner) {
  if (memory == TextureMemory::kPaged && planner.pyramid_tiles == 0)
    planner.pyramid_tiles = renderer_config::kPagedPyramidTiles;
  return planner;
}

uint64_t defaultPoolBytes(const Viewport& viewport, uint32_t tile_px, TileContent content) {
  if (tile_px == 0) return 0;
  const double screen_tiles =
      double(viewport.width_px) * double(viewport.height_px) / (double(tile_px) * double(tile_px));
  const uint64_t pages =
      std::max<uint64_t>(renderer_config::kPoolMinPages,
                         uint64_t(std::ceil(renderer_config::kDefaultPoolPagesPerScreenTile * screen_tiles)));
  return pages * pageBytes(tile_px, content);
}

Status bufferingFromName(const std::string& name, Buffering* out) {
  for (Buffering b : {Buffering::kSingle, Buffering::kDoubleUploadTwice, Buffering::kDoubleCopy,
                      Buffering::kStaged})
    if (name == bufferingName(b)) {
      *out = b;
      return okStatus();
    }
  return Status::error(ErrorCode::kInvalidArgument,
                       "buffering \"" + printableText(name, 40) + "\" is not single, double-upload, double-copy or staged");
}

namespace {
// The clip stack named in an allocation failure.
std::string stackDescription(uint64_t set_bytes, bool bc1, uint32_t sets) {
  char text[160];
  std::snprintf(text, sizeof text, "the clip stack (%u set%s of %.1f MiB of %s)", unsigned(sets),
                sets == 1 ? "" : "s", double(set_bytes) / 1048576.0, bc1 ? "BC1" : "RGBA8");
  return text;
}
}  // namespace

Status ClipmapRenderer::create(const PyramidGeometry& geometry, const RendererConfig& config,
                               std::unique_ptr<ClipmapRenderer>* out) {
  out->reset();
  if (config.clip_tiles == 0 || geometry.tile_px == 0)
    return Status::error(ErrorCode::kInvalidArgument, "renderer: clip_tiles and tile_px must be > 0");
  if (config.pyramid_level >= geometry.levelCount() ||
      geometry.levelCount() > renderer_config::kMaxLevels)
    return Status::error(ErrorCode::kInvalidArgument,
                         "renderer: pyramid level " + std::to_string(config.pyramid_level) +
                             " outside a pyramid of " + std::to_string(geometry.levelCount()) +
                             " levels (at most " + std::to_string(renderer_config::kMaxLevels) + ")");
  const LevelInfo& top = geometry.levels[config.pyramid_level];
  if (top.tiles_x > config.clip_tiles || top.tiles_y > config.clip_tiles)
    return Status::error(ErrorCode::kInvalidArgument,
                         "renderer: pyramid level does not fit in one clip");
  if (config.tile_content != TileContent::kRgba8 && config.tile_content != TileContent::kBc1)
    return Status::error(ErrorCode::kInvalidArgument, "renderer: the colour stack holds rgba8 or bc1 tiles, not " +
                                                          std::string(tileContentName(config.tile_content)));
  if (config.tile_content == TileContent::kBc1) {
    if (geometry.tile_px % kBc1BlockPx != 0)
      return Status::error(ErrorCode::kInvalidArgument,
                           "renderer: BC1 needs a tile size that is a multiple of 4, not " +
                               std::to_string(geometry.tile_px));
    if (!hasExtension("GL_EXT_texture_compression_s3tc"))
      return Status::error(ErrorCode::kUnavailable,
                           "renderer: BC1 tiles need GL_EXT_texture_compression_s3tc, which this GL lacks");
  }
  if (config.texture_memory == TextureMemory::kPaged &&
      (config.buffering == Buffering::kDoubleUploadTwice || config.buffering == Buffering::kDoubleCopy))
    return Status::error(ErrorCode::kInvalidArgument,
                         std::string("renderer: paged texture memory takes staged or single buffering, not ") +
                             bufferingName(config.buffering));
  std::unique_ptr<ClipmapRenderer> r(new ClipmapRenderer());
  r->m_geometry = geometry;
  r->m_config = config;
  if (r->paged()) {
    r->m_page_border = config.tile_content == TileContent::kBc1 ? renderer_config::kPageBorderBc1
                                                                : renderer_config::kPageBorderRgba8;
    r->m_page_px = geometry.tile_px + 2 * r->m_page_border;
  }
  // Slot period: even, so a coarser tile covers whole slot pairs in mip 1,
  // and 2 more than the window, so the parents of a window that starts on an
  // odd tile (clip/2 + 1 of them) never share a mip-1 slot.
  r->m_slots = (config.clip_tiles / 2) * 2 + 2;
  const uint64_t slots_px = uint64_t(r->m_slots) * geometry.tile_px;
  GLint max_size = 0, max_layers = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
  // The stack is slots x tile_px texels a side, a layer per stack level;
  // paged, only the indirection maps are as wide (a texel per slot, a
  // layer per level) and the pool is checked when it is created.
  const uint64_t widest = r->paged() ? r->m_slots : slots_px;
  const uint32_t map_layers = r->paged() ? geometry.levelCount() : config.pyramid_level + 1;
  if (widest > uint64_t(max_size) || map_layers > uint32_t(max_layers))
    return Status::error(ErrorCode::kUnavailable,
                         std::string(r->paged() ? "renderer: indirection maps of " : "renderer: clip of ") +
                             std::to_string(widest) + (r->paged() ? " slots exceed" : " px exceeds") +
                             " GL_MAX_TEXTURE_SIZE " + std::to_string(max_size) + " or " +
                             std::to_string(map_layers) + " layers GL_MAX_ARRAY_TEXTURE_LAYERS " +
                             std::to_string(max_layers));
  // Mips: enough for the pyramid layer's chain, at least 2 (level L + 1),
  // and only while each mip halves exactly (REPEAT must wrap at the same
  // ground distance on every mip).
  r->m_mips = std::max(2u, geometry.levelCount() - config.pyramid_level);
  while (r->m_mips > 2 && (slots_px % (uint64_t(1) << (r->m_mips - 1))) != 0) --r->m_mips;

  for (int overlay = 0; overlay < 2; ++overlay) {
    Status s = gl_util::buildGroundProgram(shaders::k_ground_clipmap_frag, &r->m_program[overlay],
                                           r->shaderDefines() + (overlay ? "#define OVERLAY 1\n" : ""));
    if (!s) return s;
  }
  glCreateVertexArrays(1, &r->m_vao);
  if (r->paged()) {
    if (Status s = r->createPaged(); !s) return s;
    *out = std::move(r);
    return okStatus();
  }

  const GLsizei layers = GLsizei(config.pyramid_level + 1);
  const GLsizei usable_layers = GLsizei(std::max(config.pyramid_level, 1u));
  const uint32_t c = r->m_slots;
  const bool bc1 = config.tile_content == TileContent::kBc1;
  gl_util::clearErrors();
  for (uint32_t set = 0; set < r->stackSets(); ++set) {
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &r->m_stack[set]);
    glTextureStorage3D(r->m_stack[set], GLsizei(r->m_mips), bc1 ? kBc1Format : GL_RGBA8,
                       GLsizei(slots_px), GLsizei(slots_px), layers);
    glTextureParameteri(r->m_stack[set], GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
    glTextureParameteri(r->m_stack[set], GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    // REPEAT is the toroidal wrap: a bilinear footprint crossing the slot
    // edge reads the neighbouring tile from the other side, where it lives.
    glTextureParameteri(r->m_stack[set], GL_TEXTURE_WRAP_S, GL_REPEAT);
    glTextureParameteri(r->m_stack[set], GL_TEXTURE_WRAP_T, GL_REPEAT);
    const uint8_t zero[4] = {0, 0, 0, 0};
    for (uint32_t m = 0; m < r->m_mips; ++m) {
      const uint64_t size = slots_px >> m;
      if (bc1) {
        // Compressed images cannot be cleared: zero blocks (black) are
        // uploaded, a layer at a time.
        const std::vector<uint8_t> zeros(imageBytes(size, TileContent::kBc1), 0);
        for (GLsizei layer = 0; layer < layers; ++layer)
          glCompressedTextureSubImage3D(r->m_stack[set], GLint(m), 0, 0, layer, GLsizei(size), GLsizei(size), 1,
                                        kBc1Format, GLsizei(zeros.size()), zeros.data());
      } else {
        glClearTexImage(r->m_stack[set], GLint(m), GL_RGBA, GL_UNSIGNED_BYTE, zero);
      }
      r->m_texture_bytes.stack += imageBytes(size, config.tile_content) * uint64_t(layers);
    }
    if (Status s = gl_util::checkCreated(stackDescription(r->m_texture_bytes.stack / (set + 1), bc1, r->stackSets()),
                                         bc1 ? "a smaller viewport needs less"
                                             : "BC1 tiles (--tile-format bc1) need 1/8 of it, a smaller viewport less");
        !s)
      return s;
    r->m_mip0_tile[set].assign(config.pyramid_level, std::vector<uint64_t>(size_t(c) * c, kNoTile));
    r->m_mip1_tile[set].assign(config.pyramid_level,
                               std::vector<uint64_t>(size_t(c / 2) * (c / 2), kNoTile));
  }

  for (uint32_t set = 0; set < r->usableSets(); ++set) {
    const uint8_t zero[4] = {0, 0, 0, 0};
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &r->m_usable_tex[set]);
    glTextureStorage3D(r->m_usable_tex[set], 1, GL_R16UI, GLsizei(c), GLsizei(c), usable_layers);
    // Integer textures are incomplete (read as 0) with a mipmap filter.
    glTextureParameteri(r->m_usable_tex[set], GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(r->m_usable_tex[set], GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glClearTexImage(r->m_usable_tex[set], 0, GL_RED_INTEGER, GL_UNSIGNED_SHORT, zero);
    r->m_texture_bytes.usable += uint64_t(c) * c * uint64_t(usable_layers) * 2;
    if (Status s = gl_util::checkCreated("the clip stack's usable-tile map"); !s) return s;
  }
  if (r->staged())
    if (Status s = r->createStaging(); !s) return s;

  for (uint32_t l = config.pyramid_level; l < geometry.levelCount(); ++l) {
    r->m_pyramid_first.push_back(r->m_pyramid_have.size());
    r->m_pyramid_have.resize(r->m_pyramid_have.size() +
                             size_t(geometry.levels[l].tiles_x) * geometry.levels[l].tiles_y, 0);
  }
  r->m_pyramid_missing = uint32_t(r->m_pyramid_have.size());
  r->m_front_map = computeUsableMap(geometry, c, config.pyramid_level, {});
  *out = std::move(r);
  return okStatus();
}

ClipmapRenderer::~ClipmapRenderer() {
  glDeleteProgram(m_program[0]);
  glDeleteProgram(m_program[1]);
  glDeleteVertexArrays(1, &m_vao);
  glDeleteTextures(2, m_stack);
  glDeleteTextures(2, m_usable_tex);
  for (void* fence : m_staging_fence)
    if (fence != nullptr) glDeleteSync(static_cast<GLsync>(fence));
  if (m_staging != 0) {
    glUnmapNamedBuffer(m_staging);
    glDeleteBuffers(1, &m_staging);
  }
}

namespace {
uint64_t packTile(int64_t x, int64_t y) { return uint64_t(uint32_t(x)) | (uint64_t(uint32_t(y)) << 32); }
}  // namespace

void ClipmapRenderer::beginFrame() {
  m_stats = {};
  m_issue_ms = 0.0;
  if (staged()) {
    // The next region; the frame that wrote it kStagingFrames frames ago
    // must have had its copies run (normally long done: no wait).
    m_staging_region = (m_staging_region + 1) % renderer_config::kStagingFrames;
    m_staging_used = 0;
    if (void*& fence = m_staging_fence[m_staging_region]; fence != nullptr) {
      glClientWaitSync(static_cast<GLsync>(fence), GL_SYNC_FLUSH_COMMANDS_BIT, uint64_t(10) * 1000000000);
      glDeleteSync(static_cast<GLsync>(fence));
      fence = nullptr;
    }
  }
  if (stackSets() == 1 || m_pending.empty()) return;
  const auto start = Clock::now();
  const uint32_t back = 1 - m_front;
  const GLsizei tp = GLsizei(m_geometry.tile_px);
  for (const Pending& p : m_pending) {
    if (m_config.buffering == Buffering::kDoubleCopy) {
      const uint32_t sx = slot(p.key.x, m_slots), sy = slot(p.key.y, m_slots);
      glCopyImageSubData(m_stack[m_front], GL_TEXTURE_2D_ARRAY, 0, GLint(sx) * tp, GLint(sy) * tp,
                         GLint(p.key.level), m_stack[back], GL_TEXTURE_2D_ARRAY, 0,
                         GLint(sx) * tp, GLint(sy) * tp, GLint(p.key.level), tp, tp, 1);
      m_mip0_tile[back][p.key.level][size_t(sy) * m_slots + sx] = packTile(p.key.x, p.key.y);
    } else {
      uploadStack(back, p.key, p.rgba->data());
    }
    ++m_stats.second_copies;
  }
  m_pending.clear();
  m_changed = true;
  m_issue_ms += msSince(start);
}

size_t ClipmapRenderer::tileBytes() const {
  return size_t(tileContentBytes(m_config.tile_content, m_geometry.tile_px));
}

const uint8_t* ClipmapRenderer::beginTileUpload(const uint8_t* pixels) {
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  if (!staged()) return pixels;
  // From the frame's staging region: `pixels` becomes an offset into the
  // bound pixel-unpack buffer.
  const int64_t offset = stage(pixels, tileBytes());
  if (offset < 0) {
    ++m_stats.unstaged;
    return pixels;
  }
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, m_staging);
  return reinterpret_cast<const uint8_t*>(uintptr_t(offset));
}

Status ClipmapRenderer::createStaging() {
  m_staging_region_bytes = size_t(std::max(m_config.staging_tiles, 1u)) * tileBytes();
  const size_t bytes = m_staging_region_bytes * renderer_config::kStagingFrames;
  const GLbitfield flags = GL_MAP_WRITE_BIT | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT;
  glCreateBuffers(1, &m_staging);
  glNamedBufferStorage(m_staging, GLsizeiptr(bytes), nullptr, flags);
  if (Status s = gl_util::checkCreated("the staging buffer (" + std::to_string(bytes >> 20) + " MiB)"); !s)
    return s;
  m_staging_map = static_cast<uint8_t*>(glMapNamedBufferRange(m_staging, 0, GLsizeiptr(bytes), flags));
  if (m_staging_map == nullptr)
    return Status::error(ErrorCode::kUnavailable, "renderer: cannot map the staging buffer");
  m_texture_bytes.staging = bytes;
  return okStatus();
}

int64_t ClipmapRenderer::stage(const uint8_t* pixels, size_t bytes) {
  if (m_staging_used + bytes > m_staging_region_bytes) return -1;
  const size_t offset = size_t(m_staging_region) * m_staging_region_bytes + m_staging_used;
  std::memcpy(m_staging_map + offset, pixels, bytes);
  m_staging_used += bytes;
  return int64_t(offset);
}

void ClipmapRenderer::uploadStack(uint32_t set, const TileKey& key, const uint8_t* pixels) {
  const GLsizei tp = GLsizei(m_geometry.tile_px);
  const uint32_t sx = slot(key.x, m_slots), sy = slot(key.y, m_slots);
  pixels = beginTileUpload(pixels);
  if (compressed())
    glCompressedTextureSubImage3D(m_stack[set], 0, GLint(sx) * tp, GLint(sy) * tp, GLint(key.level), tp, tp,
                                  1, kBc1Format, GLsizei(tileBytes()), pixels);
  else
    glTextureSubImage3D(m_stack[set], 0, GLint(sx) * tp, GLint(sy) * tp, GLint(key.level), tp, tp, 1,
                        GL_RGBA, GL_UNSIGNED_BYTE, pixels);
  if (staged()) glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
  if (key.level < m_config.pyramid_level)
    m_mip0_tile[set][key.level][size_t(sy) * m_slots + sx] = packTile(key.x, key.y);
}

void ClipmapRenderer::uploadPyramid(const TileKey& key, const uint8_t* pixels) {
  // Level pyramid_level + k is mip k of the pyramid layer. It has fewer
  // tiles than the slot period, so slot == tile position (unless a test
  // bias shifts it), and its tiles may overhang the smaller mips: only the
  // part inside the mip is uploaded (the rest is padding).
  const uint32_t tp = m_geometry.tile_px;
  const uint32_t mip = key.level - m_config.pyramid_level;
  if (mip >= m_mips) return;
  const uint64_t size = (uint64_t(m_slots) * tp) >> mip;
  const uint64_t x = uint64_t(slot(key.x, m_slots)) * tp, y = uint64_t(slot(key.y, m_slots)) * tp;
  if (x >= size || y >= size) return;
  const uint32_t w = uint32_t(std::min<uint64_t>(tp, size - x));
  const uint32_t h = uint32_t(std::min<uint64_t>(tp, size - y));
  if (compressed()) {
    // The blocks covering w x h (a partial width or height reaches the
    // mip's edge, where GL takes a partial block), packed row by row.
    const uint32_t row_blocks = tp / kBc1BlockPx;
    const uint32_t bw = (w + kBc1BlockPx - 1) / kBc1BlockPx, bh = (h + kBc1BlockPx - 1) / kBc1BlockPx;
    std::vector<uint8_t> packed;
    const uint8_t* data = pixels;
    if (bw != row_blocks || bh != row_blocks) {
      packed.resize(size_t(bw) * bh * kBc1BlockBytes);
      for (uint32_t by = 0; by < bh; ++by)
        std::memcpy(packed.data() + size_t(by) * bw * kBc1BlockBytes,
                    pixels + size_t(by) * row_blocks * kBc1BlockBytes, size_t(bw) * kBc1BlockBytes);
      data = packed.data();
    }
    for (uint32_t set = 0; set < stackSets(); ++set)
      glCompressedTextureSubImage3D(m_stack[set], GLint(mip), GLint(x), GLint(y), GLint(m_config.pyramid_level),
                                    GLsizei(w), GLsizei(h), 1, kBc1Format,
                                    GLsizei(size_t(bw) * bh * kBc1BlockBytes), data);
    return;
  }
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, GLint(tp));
  for (uint32_t set = 0; set < stackSets(); ++set)
    glTextureSubImage3D(m_stack[set], GLint(mip), GLint(x), GLint(y), GLint(m_config.pyramid_level),
                        GLsizei(w), GLsizei(h), 1, GL_RGBA, GL_UNSIGNED_BYTE, pixels);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
}

uint32_t ClipmapRenderer::loadPyramid(const PyramidTileFn& tile) {
  uint32_t failed = 0;
  for (uint32_t l = m_config.pyramid_level; l < m_geometry.levelCount(); ++l)
    for (uint32_t y = 0; y < m_geometry.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < m_geometry.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        if (auto px = tile(key)) uploadTile(key, std::move(px));
        else ++failed;
      }
  if (paged()) fillMissingPyramidPages();
  else fillMissingPyramidTiles();
  return failed;
}

uint32_t ClipmapRenderer::fillMissingPyramidTiles() {
  if (m_pyramid_missing == 0) return 0;
  const uint32_t pyramid = m_config.pyramid_level;
  const uint64_t tp = m_geometry.tile_px;
  // Levels past the stored mips are never sampled (draw() clamps to them).
  const uint32_t levels = std::min(m_geometry.levelCount() - pyramid, m_mips);
  auto have = [&](uint32_t mip, int64_t x, int64_t y) -> uint8_t* {
    const LevelInfo& info = m_geometry.levels[pyramid + mip];
    if (x < 0 || y < 0 || x >= int64_t(info.tiles_x) || y >= int64_t(info.tiles_y)) return nullptr;
    return &m_pyramid_have[m_pyramid_first[mip] + size_t(y) * info.tiles_x + size_t(x)];
  };
  GLuint fbo[2] = {0, 0};
  glCreateFramebuffers(2, fbo);
  glNamedFramebufferReadBuffer(fbo[0], GL_COLOR_ATTACHMENT0);
  const GLint layer = GLint(pyramid);
  auto blit = [&](uint32_t src_mip, const GLint src[4], uint32_t dst_mip, const GLint dst[4]) {
    for (uint32_t set = 0; set < stackSets(); ++set) {
      glNamedFramebufferTextureLayer(fbo[0], GL_COLOR_ATTACHMENT0, m_stack[set], GLint(src_mip),
                                     layer);
      glNamedFramebufferTextureLayer(fbo[1], GL_COLOR_ATTACHMENT0, m_stack[set], GLint(dst_mip),
                                     layer);
      glBlitNamedFramebuffer(fbo[0], fbo[1], src[0], src[1], src[2], src[3], dst[0], dst[1], dst[2],
                             dst[3], GL_COLOR_BUFFER_BIT, GL_LINEAR);
    }
  };
  uint32_t filled = 0;
  for (uint32_t mip = levels; mip-- > 0;) {
    const LevelInfo& info = m_geometry.levels[pyramid + mip];
    const uint64_t size = (uint64_t(m_slots) * tp) >> mip;
    for (uint32_t y = 0; y < info.tiles_y; ++y) {
      for (uint32_t x = 0; x < info.tiles_x; ++x) {
        uint8_t* mine = have(mip, x, y);
        if (*mine) continue;
        *mine = 1;
        --m_pyramid_missing;
        const uint64_t x0 = uint64_t(slot(x, m_slots)) * tp, y0 = uint64_t(slot(y, m_slots)) * tp;
        if (x0 >= size || y0 >= size) continue;  // beyond the mip: padding only
        const GLint dst[4] = {GLint(x0), GLint(y0), GLint(std::min(x0 + tp, size)),
                              GLint(std::min(y0 + tp, size))};
        ++filled;
        const uint8_t* parent = mip + 1 < levels ? have(mip + 1, x / 2, y / 2) : nullptr;
        bool children = mip > 0;
        for (int64_t j = 0; j < 2 && children; ++j)
          for (int64_t i = 0; i < 2 && children; ++i) {
            const uint8_t* c = have(mip - 1, 2 * int64_t(x) + i, 2 * int64_t(y) + j);
            children = c == nullptr || *c != 0;
          }
        if (compressed()) {
          const Fill fill = parent != nullptr && *parent ? Fill::kFromParent
                            : children                   ? Fill::kFromChildren
                                                         : Fill::kGrey;
          fillPyramidTileBc1({pyramid + mip, x, y}, fill);
        } else if (parent != nullptr && *parent) {
          const GLint src[4] = {dst[0] / 2, dst[1] / 2, dst[2] / 2, dst[3] / 2};
          blit(mip + 1, src, mip, dst);
        } else if (children) {
          // The coarsest stored level has no parent: average its children.
          const uint64_t below = size * 2;
          auto twice = [below](uint64_t v) { return GLint(std::min<uint64_t>(2 * v, below)); };
          const GLint src[4] = {twice(x0), twice(y0), twice(uint64_t(dst[2])),
                                twice(uint64_t(dst[3]))};
          blit(mip - 1, src, mip, dst);
        } else {
          const uint8_t grey[4] = {128, 128, 128, 255};
          for (uint32_t set = 0; set < stackSets(); ++set)
            glClearTexSubImage(m_stack[set], GLint(mip), dst[0], dst[1], layer, dst[2] - dst[0],
                               dst[3] - dst[1], 1, GL_RGBA, GL_UNSIGNED_BYTE, grey);
        }
      }
    }
  }
  glDeleteFramebuffers(2, fbo);
  m_changed = true;
  return filled;
}

std::vector<uint8_t> ClipmapRenderer::readPyramidRegion(uint32_t mip, uint32_t x, uint32_t y, uint32_t w,
                                                         uint32_t h) const {
  const uint32_t bw = (w + kBc1BlockPx - 1) / kBc1BlockPx, bh = (h + kBc1BlockPx - 1) / kBc1BlockPx;
  std::vector<uint8_t> blocks(size_t(bw) * bh * kBc1BlockBytes);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glGetCompressedTextureSubImage(m_stack[0], GLint(mip), GLint(x), GLint(y), GLint(m_config.pyramid_level),
                                 GLsizei(w), GLsizei(h), 1, GLsizei(blocks.size()), blocks.data());
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  std::vector<uint8_t> rgba(size_t(w) * h * 4);
  uint8_t texels[16 * 4];
  for (uint32_t by = 0; by < bh; ++by)
    for (uint32_t bx = 0; bx < bw; ++bx) {
      decodeBc1Block(blocks.data() + (size_t(by) * bw + bx) * kBc1BlockBytes, texels);
      for (uint32_t j = 0; j < kBc1BlockPx && by * 4 + j < h; ++j)
        for (uint32_t i = 0; i < kBc1BlockPx && bx * 4 + i < w; ++i)
          std::memcpy(&rgba[(size_t(by * 4 + j) * w + bx * 4 + i) * 4], &texels[(j * 4 + i) * 4], 4);
    }
  return rgba;
}

void ClipmapRenderer::fillPyramidTileBc1(const TileKey& key, Fill fill) {
  // The RGBA8 fallbacks of fillMissingPyramidTiles() (a linear blit of the
  // parent's quarter, a blit of the children's 2x2 average, mid grey) done
  // on the CPU over decoded blocks, then encoded and uploaded as a tile.
  const uint32_t tp = m_geometry.tile_px;
  const uint32_t mip = key.level - m_config.pyramid_level;
  const uint64_t size = (uint64_t(m_slots) * tp) >> mip;
  const uint64_t x0 = uint64_t(slot(key.x, m_slots)) * tp, y0 = uint64_t(slot(key.y, m_slots)) * tp;
  std::vector<uint8_t> tile(size_t(tp) * tp * 4, 128);
  for (size_t i = 3; i < tile.size(); i += 4) tile[i] = 255;
  if (fill == Fill::kFromParent) {
    // The parent's quarter over this tile, clamped to the parent mip.
    const uint64_t psize = size / 2;
    const uint32_t px = uint32_t(x0 / 2), py = uint32_t(y0 / 2);
    const uint32_t pw = uint32_t(std::min<uint64_t>(tp / 2, psize - px));
    const uint32_t ph = uint32_t(std::min<uint64_t>(tp / 2, psize - py));
    const std::vector<uint8_t> src = readPyramidRegion(mip + 1, px, py, pw, ph);
    magnifyQuarter(src.data(), pw, 0, 0, pw, ph, tp, tile.data());
  } else if (fill == Fill::kFromChildren) {
    // The four children's texels, 2x2 averaged, clamped to the finer mip.
    const uint64_t csize = size * 2;
    const uint32_t cx = uint32_t(std::min(x0 * 2, csize)), cy = uint32_t(std::min(y0 * 2, csize));
    const uint32_t cw = uint32_t(std::min<uint64_t>(2 * uint64_t(tp), csize - cx));
    const uint32_t ch = uint32_t(std::min<uint64_t>(2 * uint64_t(tp), csize - cy));
    if (cw >= 2 && ch >= 2) {
      const std::vector<uint8_t> src = readPyramidRegion(mip - 1, cx, cy, cw, ch);
      for (uint32_t j = 0; j < tp && 2 * j + 1 < ch; ++j)
        for (uint32_t i = 0; i < tp && 2 * i + 1 < cw; ++i)
          for (int c = 0; c < 3; ++c) {
            auto at = [&](uint32_t u, uint32_t v) { return uint32_t(src[(size_t(v) * cw + u) * 4 + size_t(c)]); };
            tile[(size_t(j) * tp + i) * 4 + size_t(c)] =
                uint8_t((at(2 * i, 2 * j) + at(2 * i + 1, 2 * j) + at(2 * i, 2 * j + 1) + at(2 * i + 1, 2 * j + 1) + 2) / 4);
          }
    }
  }
  std::vector<uint8_t> blocks;
  if (encodeBc1Tile(tile, tp, &blocks)) uploadPyramid(key, blocks.data());
}

void ClipmapRenderer::fillCoarserMips(uint32_t set) {
  // Mip 1 of layer L holds level L + 1 over level L's window, so a single
  // trilinear fetch blends L and L + 1. It is copied on the GPU from where
  // level L + 1 already lives (layer L + 1, mip 0), whenever a parent of
  // the window is there and the mip-1 slot holds something else.
  const GLsizei tp = GLsizei(m_geometry.tile_px);
  const uint32_t half = m_slots / 2;
  const uint32_t pyramid = m_config.pyramid_level;
  for (const LevelResidency& r : m_residency) {
    const uint32_t l = r.level;
    if (l >= pyramid || r.window.empty()) continue;
    const int64_t px0 = r.window.x0 / 2, px1 = (r.window.x1 - 1) / 2 + 1;
    const int64_t py0 = r.window.y0 / 2, py1 = (r.window.y1 - 1) / 2 + 1;
    for (int64_t py = py0; py < py1; ++py) {
      for (int64_t px = px0; px < px1; ++px) {
        const uint32_t dx = slot(px, half), dy = slot(py, half);
        uint64_t& have = m_mip1_tile[set][l][size_t(dy) * half + dx];
        if (have == packTile(px, py)) continue;
        const uint32_t sx = slot(px, m_slots), sy = slot(py, m_slots);
        bool present = false;
        if (l + 1 == pyramid) {
          const LevelInfo& info = m_geometry.levels[pyramid];
          present = px < int64_t(info.tiles_x) && py < int64_t(info.tiles_y) &&
                    m_pyramid_have[m_pyramid_first[0] + size_t(py) * info.tiles_x + size_t(px)];
        } else {
          present = m_mip0_tile[set][l + 1][size_t(sy) * m_slots + sx] == packTile(px, py);
        }
        if (!present) continue;
        glCopyImageSubData(m_stack[set], GL_TEXTURE_2D_ARRAY, 0, GLint(sx) * tp, GLint(sy) * tp,
                           GLint(l + 1), m_stack[set], GL_TEXTURE_2D_ARRAY, 1, GLint(dx) * tp,
                           GLint(dy) * tp, GLint(l), tp, tp, 1);
        have = packTile(px, py);
      }
    }
  }
}

void ClipmapRenderer::uploadTile(const TileKey& key,
                                 std::shared_ptr<const std::vector<uint8_t>> rgba) {
  if (!rgba || rgba->size() != tileBytes() || !m_geometry.contains(key)) return;
  const auto start = Clock::now();
  if (paged()) {
    uploadTilePaged(key, std::move(rgba));
  } else if (key.level >= m_config.pyramid_level) {
    const size_t index = m_pyramid_first[key.level - m_config.pyramid_level] +
                         size_t(key.y) * m_geometry.levels[key.level].tiles_x + key.x;
    // The pyramid never changes once loaded: a tile handed over again (the
    // streamer does not know it was preloaded) is not uploaded again.
    if (m_pyramid_have[index]) return;
    m_pyramid_have[index] = 1;
    --m_pyramid_missing;
    ++m_stats.tiles;
    m_changed = true;
    uploadPyramid(key, rgba->data());
  } else if (stackSets() == 1) {
    ++m_stats.tiles;
    m_changed = true;
    uploadStack(0, key, rgba->data());
  } else {
    ++m_stats.tiles;
    m_changed = true;
    uploadStack(1 - m_front, key, rgba->data());
    m_pending.push_back({key, std::move(rgba)});
  }
  m_issue_ms += msSince(start);
}

void ClipmapRenderer::setResidency(const std::vector<LevelResidency>& residency) {
  m_residency = residency;
  m_changed = true;
}

void ClipmapRenderer::endUploads() {
  if (!m_changed) {
    m_stats.upload_ms = m_issue_ms;
    return;
  }
  const auto start = Clock::now();
  if (paged()) {
    // Pages are written here (the tiles the frame samples), so the fence
    // over the staging region follows them.
    endUploadsPaged(usableSets() == 1 ? 0 : 1 - m_front);
    if (staged() && m_staging_used > 0 && m_staging_fence[m_staging_region] == nullptr)
      m_staging_fence[m_staging_region] = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    if (usableSets() == 2) m_front = 1 - m_front;
    m_changed = false;
    m_issue_ms += msSince(start);
    m_stats.upload_ms = m_issue_ms;
    return;
  }
  if (staged() && m_staging_used > 0 && m_staging_fence[m_staging_region] == nullptr)
    m_staging_fence[m_staging_region] = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  const uint32_t target = stackSets() == 1 ? 0 : 1 - m_front;
  const uint32_t usable_target = usableSets() == 1 ? 0 : 1 - m_front;
  fillCoarserMips(target);
  const auto mips_done = Clock::now();
  m_stats.coarser_mips_ms = std::chrono::duration<double, std::milli>(mips_done - start).count();
  UsableMap map = computeUsableMap(m_geometry, m_slots, m_config.pyramid_level, m_residency);
  const uint32_t c = m_slots;
  const bool same = map.windows == m_front_map.windows && map.finest == m_front_map.finest;
  if (!same || usableSets() == 2) {
    // Per slot: usableCode() of the window tile in the low byte and how
    // many levels coarser its finest usable ancestor is in the high byte
    // (up to the pyramid level). Written for every window tile, usable or
    // not; 0 elsewhere (no code matches it).
    std::vector<uint16_t> flat(size_t(c) * c * std::max<size_t>(map.usable.size(), 1), 0);
    for (size_t l = 0; l < map.usable.size(); ++l) {
      const uint8_t* finest = map.finest[l].data();
      uint16_t* out = flat.data() + l * c * c;
      forEachWindowSlot(map.windows[l], c, [&](int64_t, int64_t, size_t i, uint8_t code) {
        out[i] = uint16_t(code | ((finest[i] - uint32_t(l)) << 8));
      });
    }
    if (!map.usable.empty()) {
      glPixelStorei(GL_UNPACK_ALIGNMENT, 2);
      glTextureSubImage3D(m_usable_tex[usable_target], 0, 0, 0, 0, GLsizei(c), GLsizei(c),
                          GLsizei(map.usable.size()), GL_RED_INTEGER, GL_UNSIGNED_SHORT, flat.data());
      glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    }
  }
  m_front_map = std::move(map);
  m_stats.usable_ms = msSince(mips_done);
  if (usableSets() == 2) m_front = 1 - m_front;
  m_changed = false;
  m_issue_ms += msSince(start);
  m_stats.upload_ms = m_issue_ms;
}

void ClipmapRenderer::applyHandoff(const FrameHandoff& handoff) {
  beginFrame();
  for (const ReadyTile& t : handoff.tiles) uploadTile(t.key, t.rgba);
  setResidency(handoff.residency);
  setMaxTextureLod(handoff.max_texture_lod);
  endUploads();
}

void ClipmapRenderer::clearSky() {
  const uint8_t* s = renderer_config::kSkyRgba;
  glClearColor(s[0] / 255.0f, s[1] / 255.0f, s[2] / 255.0f, s[3] / 255.0f);
  glClearDepth(1.0);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
}

void ClipmapRenderer::draw(const Camera& camera, const Viewport& viewport) {
  const GLuint p = m_program[m_overlay == Overlay::kOff ? 0 : 1];
  bindColour(p, camera, viewport);
  glUseProgram(p);
  glBindVertexArray(m_vao);
  glDisable(GL_DEPTH_TEST);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glBindVertexArray(0);
  glUseProgram(0);
}

std::string ClipmapRenderer::shaderDefines() const {
  if (!paged()) return "";
  return "#define PAGED 1\n#define PAGE_BORDER " + std::to_string(m_page_border) + "\n";
}

void ClipmapRenderer::bindColour(uint32_t p, const Camera& camera, const Viewport& viewport) const {
  const uint32_t pyramid = m_config.pyramid_level;
  const double tp = m_geometry.tile_px;
  const double clip = m_slots;
  gl_util::setRayUniforms(p, camera, viewport, double(m_geometry.width_px),
                          double(m_geometry.height_px));
  // Per level, in double: the camera in tiles relative to the slot cell it
  // lies in, and that cell's index mod 4 (see slotPosition() in the shader).
  float cam_cell[renderer_config::kMaxLevels * 4] = {};
  float inv_tile[renderer_config::kMaxLevels] = {};
  // Paged: every level has an indirection map, the pyramid's levels too.
  const uint32_t top = paged() ? m_geometry.levelCount() - 1 : pyramid;
  for (uint32_t l = 0; l <= top; ++l) {
    const double tile_texels = tp * std::ldexp(1.0, int(l));
    const double tx = camera.position.x / tile_texels, ty = camera.position.z / tile_texels;
    const double cell_x = std::floor(tx / clip), cell_y = std::floor(ty / clip);
    cam_cell[4 * l + 0] = float(tx - cell_x * clip);
    cam_cell[4 * l + 1] = float(ty - cell_y * clip);
    cam_cell[4 * l + 2] = float(cell_x - 4.0 * std::floor(cell_x / 4.0));
    cam_cell[4 * l + 3] = float(cell_y - 4.0 * std::floor(cell_y / 4.0));
    inv_tile[l] = float(1.0 / tile_texels);
  }
  const GLsizei n = GLsizei(top + 1);
  glProgramUniform4fv(p, loc(p, "uCamCell"), n, cam_cell);
  glProgramUniform1fv(p, loc(p, "uInvTileTexels"), n, inv_tile);
  glProgramUniform1i(p, loc(p, "uSlots"), GLint(clip));
  const uint32_t max_level =
      paged() ? top : std::min(m_geometry.levelCount() - 1, pyramid + m_mips - 1);
  if (paged()) {
    glProgramUniform1i(p, loc(p, "uTopLevel"), GLint(top));
    // The pyramid level's grid and its cell's origin, for the fallback.
    const LevelInfo& info = m_geometry.levels[pyramid];
    glProgramUniform2i(p, loc(p, "uPyramidTiles"), GLint(info.tiles_x), GLint(info.tiles_y));
    glProgramUniform1i(p, loc(p, "uPyramidLayersX"), GLint(m_pyramid_layers_x));
    const double tile_texels = tp * std::ldexp(1.0, int(pyramid));
    glProgramUniform2f(p, loc(p, "uPyramidOrigin"),
                       float(std::floor(camera.position.x / tile_texels / clip) * clip),
                       float(std::floor(camera.position.z / tile_texels / clip) * clip));
  }
  glProgramUniform1i(p, loc(p, "uPyramidLevel"), GLint(pyramid));
  glProgramUniform1f(p, loc(p, "uMinLod"), float(std::min(m_max_texture_lod, max_level)));
  glProgramUniform1f(p, loc(p, "uMaxLod"), float(max_level));
  glProgramUniform1f(p, loc(p, "uTilePx"), float(tp));
  glProgramUniform1i(p, loc(p, "uStack"), 0);
  glProgramUniform1i(p, loc(p, "uUsable"), 1);
  glBindTextureUnit(0, m_stack[stackSets() == 1 ? 0 : m_front]);
  glBindTextureUnit(1, m_usable_tex[usableSets() == 1 ? 0 : m_front]);
}

// ---------------------------------------------------------------------------

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

void magnifyQuarter(const uint8_t* src, uint32_t src_stride, uint32_t x0, uint32_t y0, uint32_t w,
                    uint32_t h, uint32_t tile_px, uint8_t* tile) {
  for (uint32_t j = 0; j < tile_px; ++j)
    for (uint32_t i = 0; i < tile_px; ++i) {
      // Texel centres of the magnified tile in the region's texels.
      const double sx = std::clamp((i + 0.5) * 0.5 - 0.5, 0.0, double(w - 1));
      const double sy = std::clamp((j + 0.5) * 0.5 - 0.5, 0.0, double(h - 1));
      const uint32_t ix = uint32_t(sx), iy = uint32_t(sy);
      const uint32_t ix1 = std::min(ix + 1, w - 1), iy1 = std::min(iy + 1, h - 1);
      const double fx = sx - ix, fy = sy - iy;
      for (int c = 0; c < 3; ++c) {
        auto at = [&](uint32_t u, uint32_t v) {
          return double(src[(size_t(y0 + v) * src_stride + x0 + u) * 4 + size_t(c)]);
        };
        const double v = (at(ix, iy) * (1 - fx) + at(ix1, iy) * fx) * (1 - fy) +
                         (at(ix, iy1) * (1 - fx) + at(ix1, iy1) * fx) * fy;
        tile[(size_t(j) * tile_px + i) * 4 + size_t(c)] = uint8_t(std::lround(v));
      }
    }
}

}  // namespace clipstream
