// The clipmap on the GPU: ClipmapRenderer and its implementation's
// creation, frame protocol and drawing. The coarse pyramid and its
// fallbacks: pyramid_fill.cpp; paged texture memory: paged.cpp; the staged
// ring: staging_ring.cpp; the slot rule and usable map: clipmap.cpp; the
// shader: shaders/ground_clipmap.frag. Why double-buffering: see
// docs/renderer.md.
#include "clipmap_renderer_impl.h"

#include "gl.h"
#include "gl_util.h"
#include "shaders.h"

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

namespace {
// The clip stack named in an allocation failure.
std::string stackDescription(uint64_t set_bytes, bool bc1, uint32_t sets) {
  char text[160];
  std::snprintf(text, sizeof text, "the clip stack (%u set%s of %.1f MiB of %s)", unsigned(sets),
                sets == 1 ? "" : "s", double(set_bytes) / 1048576.0, bc1 ? "BC1" : "RGBA8");
  return text;
}
}  // namespace

ClipmapRenderer::ClipmapRenderer() : m_impl(std::make_unique<Impl>()) {}
ClipmapRenderer::~ClipmapRenderer() = default;

Status ClipmapRenderer::create(const PyramidGeometry& geometry, const RendererConfig& config,
                               std::unique_ptr<ClipmapRenderer>* out) {
  out->reset();
  std::unique_ptr<ClipmapRenderer> r(new ClipmapRenderer());
  if (Status s = r->m_impl->init(geometry, config); !s) return s;
  *out = std::move(r);
  return okStatus();
}

void ClipmapRenderer::beginFrame() { m_impl->beginFrame(); }
void ClipmapRenderer::uploadTile(const TileKey& key, std::shared_ptr<const std::vector<uint8_t>> rgba) {
  m_impl->uploadTile(key, std::move(rgba));
}
void ClipmapRenderer::setResidency(const std::vector<LevelResidency>& residency) { m_impl->setResidency(residency); }
void ClipmapRenderer::setMaxTextureLod(uint32_t level) { m_impl->m_max_texture_lod = level; }
void ClipmapRenderer::endUploads() { m_impl->endUploads(); }
void ClipmapRenderer::draw(const Camera& camera, const Viewport& viewport) { m_impl->draw(camera, viewport); }
void ClipmapRenderer::setOverlay(Overlay overlay) { m_impl->m_overlay = overlay; }
Overlay ClipmapRenderer::overlay() const { return m_impl->m_overlay; }
uint32_t ClipmapRenderer::loadPyramid(const PyramidTileFn& tile) { return m_impl->loadPyramid(tile); }
const UsableMap& ClipmapRenderer::usableMap() const { return m_impl->m_front_map; }
const UploadStats& ClipmapRenderer::lastUploads() const { return m_impl->m_stats; }
const PyramidGeometry& ClipmapRenderer::geometry() const { return m_impl->m_geometry; }
const TextureBytes& ClipmapRenderer::textureBytes() const { return m_impl->m_texture_bytes; }
TileContent ClipmapRenderer::tileContent() const { return m_impl->m_config.tile_content; }
TextureMemory ClipmapRenderer::textureMemory() const { return m_impl->m_config.texture_memory; }
uint32_t ClipmapRenderer::poolPages() const { return m_impl->m_pages ? m_impl->m_pages->pages() : 0; }
uint32_t ClipmapRenderer::poolPagesUsed() const { return m_impl->m_pages ? m_impl->m_pages->used() : 0; }

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

Status ClipmapRenderer::Impl::init(const PyramidGeometry& geometry, const RendererConfig& config) {
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
  m_geometry = geometry;
  m_config = config;
  if (paged()) {
    m_page_border = config.tile_content == TileContent::kBc1 ? renderer_config::kPageBorderBc1
                                                                : renderer_config::kPageBorderRgba8;
    m_page_px = geometry.tile_px + 2 * m_page_border;
  }
  // Slot period: even, so a coarser tile covers whole slot pairs in mip 1,
  // and 2 more than the window, so the parents of a window that starts on an
  // odd tile (clip/2 + 1 of them) never share a mip-1 slot.
  m_slots = (config.clip_tiles / 2) * 2 + 2;
  const uint64_t slots_px = uint64_t(m_slots) * geometry.tile_px;
  GLint max_size = 0, max_layers = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
  // The stack is slots x tile_px texels a side, a layer per stack level;
  // paged, only the indirection maps are as wide (a texel per slot, a
  // layer per level) and the pool is checked when it is created.
  const uint64_t widest = paged() ? m_slots : slots_px;
  const uint32_t map_layers = paged() ? geometry.levelCount() : config.pyramid_level + 1;
  if (widest > uint64_t(max_size) || map_layers > uint32_t(max_layers))
    return Status::error(ErrorCode::kUnavailable,
                         std::string(paged() ? "renderer: indirection maps of " : "renderer: clip of ") +
                             std::to_string(widest) + (paged() ? " slots exceed" : " px exceeds") +
                             " GL_MAX_TEXTURE_SIZE " + std::to_string(max_size) + " or " +
                             std::to_string(map_layers) + " layers GL_MAX_ARRAY_TEXTURE_LAYERS " +
                             std::to_string(max_layers));
  // Mips: enough for the pyramid layer's chain, at least 2 (level L + 1),
  // and only while each mip halves exactly (REPEAT must wrap at the same
  // ground distance on every mip).
  m_mips = std::max(2u, geometry.levelCount() - config.pyramid_level);
  while (m_mips > 2 && (slots_px % (uint64_t(1) << (m_mips - 1))) != 0) --m_mips;

  for (int overlay = 0; overlay < 2; ++overlay) {
    Status s = gl_util::buildGroundProgram(shaders::k_ground_clipmap_frag, &m_program[overlay],
                                           shaderDefines() + (overlay ? "#define OVERLAY 1\n" : ""));
    if (!s) return s;
  }
  glCreateVertexArrays(1, &m_vao);
  if (paged()) {
    return createPaged();
  }
  return createStack();
}

// The stack array(s), the usable map(s), the staging ring and the pyramid's
// bookkeeping (kStack).
Status ClipmapRenderer::Impl::createStack() {
  const PyramidGeometry& geometry = m_geometry;
  const RendererConfig& config = m_config;
  const uint64_t slots_px = uint64_t(m_slots) * geometry.tile_px;

  const GLsizei layers = GLsizei(config.pyramid_level + 1);
  const GLsizei usable_layers = GLsizei(std::max(config.pyramid_level, 1u));
  const uint32_t c = m_slots;
  const bool bc1 = config.tile_content == TileContent::kBc1;
  gl_util::clearErrors();
  for (uint32_t set = 0; set < stackSets(); ++set) {
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &m_stack[set]);
    glTextureStorage3D(m_stack[set], GLsizei(m_mips), bc1 ? kBc1Format : GL_RGBA8,
                       GLsizei(slots_px), GLsizei(slots_px), layers);
    glTextureParameteri(m_stack[set], GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
    glTextureParameteri(m_stack[set], GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    // REPEAT is the toroidal wrap: a bilinear footprint crossing the slot
    // edge reads the neighbouring tile from the other side, where it lives.
    glTextureParameteri(m_stack[set], GL_TEXTURE_WRAP_S, GL_REPEAT);
    glTextureParameteri(m_stack[set], GL_TEXTURE_WRAP_T, GL_REPEAT);
    const uint8_t zero[4] = {0, 0, 0, 0};
    for (uint32_t m = 0; m < m_mips; ++m) {
      const uint64_t size = slots_px >> m;
      if (bc1) {
        // Compressed images cannot be cleared: zero blocks (black) are
        // uploaded, a layer at a time.
        const std::vector<uint8_t> zeros(imageBytes(size, TileContent::kBc1), 0);
        for (GLsizei layer = 0; layer < layers; ++layer)
          glCompressedTextureSubImage3D(m_stack[set], GLint(m), 0, 0, layer, GLsizei(size), GLsizei(size), 1,
                                        kBc1Format, GLsizei(zeros.size()), zeros.data());
      } else {
        glClearTexImage(m_stack[set], GLint(m), GL_RGBA, GL_UNSIGNED_BYTE, zero);
      }
      m_texture_bytes.stack += imageBytes(size, config.tile_content) * uint64_t(layers);
    }
    if (Status s = gl_util::checkCreated(stackDescription(m_texture_bytes.stack / (set + 1), bc1, stackSets()),
                                         bc1 ? "a smaller viewport needs less"
                                             : "BC1 tiles (--tile-format bc1) need 1/8 of it, a smaller viewport less");
        !s)
      return s;
    m_mip0_tile[set].assign(config.pyramid_level, std::vector<uint64_t>(size_t(c) * c, kNoTile));
    m_mip1_tile[set].assign(config.pyramid_level,
                               std::vector<uint64_t>(size_t(c / 2) * (c / 2), kNoTile));
  }

  for (uint32_t set = 0; set < usableSets(); ++set) {
    const uint8_t zero[4] = {0, 0, 0, 0};
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &m_usable_tex[set]);
    glTextureStorage3D(m_usable_tex[set], 1, GL_R16UI, GLsizei(c), GLsizei(c), usable_layers);
    // Integer textures are incomplete (read as 0) with a mipmap filter.
    glTextureParameteri(m_usable_tex[set], GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(m_usable_tex[set], GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glClearTexImage(m_usable_tex[set], 0, GL_RED_INTEGER, GL_UNSIGNED_SHORT, zero);
    m_texture_bytes.usable += uint64_t(c) * c * uint64_t(usable_layers) * 2;
    if (Status s = gl_util::checkCreated("the clip stack's usable-tile map"); !s) return s;
  }
  if (staged()) {
    if (Status s = m_staging.create(size_t(std::max(m_config.staging_tiles, 1u)) * tileBytes()); !s) return s;
    m_texture_bytes.staging = m_staging.bytes();
  }

  for (uint32_t l = config.pyramid_level; l < geometry.levelCount(); ++l) {
    m_pyramid_first.push_back(m_pyramid_have.size());
    m_pyramid_have.resize(m_pyramid_have.size() +
                             size_t(geometry.levels[l].tiles_x) * geometry.levels[l].tiles_y, 0);
  }
  m_pyramid_missing = uint32_t(m_pyramid_have.size());
  m_front_map = computeUsableMap(geometry, c, config.pyramid_level, {});
  return okStatus();
}

ClipmapRenderer::Impl::~Impl() {
  glDeleteProgram(m_program[0]);
  glDeleteProgram(m_program[1]);
  glDeleteVertexArrays(1, &m_vao);
  glDeleteTextures(2, m_stack);
  glDeleteTextures(2, m_usable_tex);
}

void ClipmapRenderer::Impl::beginFrame() {
  m_stats = {};
  m_issue_ms = 0.0;
  // The next staging region; the frame that wrote it kStagingFrames frames
  // ago must have had its copies run (normally long done: no wait).
  if (staged()) m_staging.beginFrame();
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

size_t ClipmapRenderer::Impl::tileBytes() const {
  return size_t(tileContentBytes(m_config.tile_content, m_geometry.tile_px));
}

const uint8_t* ClipmapRenderer::Impl::beginTileUpload(const uint8_t* pixels) {
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  if (!staged()) return pixels;
  // From the frame's staging region: `pixels` becomes an offset into the
  // bound pixel-unpack buffer.
  const int64_t offset = m_staging.stage(pixels, tileBytes());
  if (offset < 0) {
    ++m_stats.unstaged;
    return pixels;
  }
  glBindBuffer(GL_PIXEL_UNPACK_BUFFER, m_staging.buffer());
  return reinterpret_cast<const uint8_t*>(uintptr_t(offset));
}

void ClipmapRenderer::Impl::uploadStack(uint32_t set, const TileKey& key, const uint8_t* pixels) {
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

void ClipmapRenderer::Impl::fillCoarserMips(uint32_t set) {
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

void ClipmapRenderer::Impl::uploadTile(const TileKey& key,
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

void ClipmapRenderer::Impl::setResidency(const std::vector<LevelResidency>& residency) {
  m_residency = residency;
  m_changed = true;
}

void ClipmapRenderer::Impl::endUploads() {
  if (!m_changed) {
    m_stats.upload_ms = m_issue_ms;
    return;
  }
  const auto start = Clock::now();
  if (paged()) {
    // Pages are written here (the tiles the frame samples), so the fence
    // over the staging region follows them.
    endUploadsPaged(usableSets() == 1 ? 0 : 1 - m_front);
    if (staged()) m_staging.fenceFrame();
    if (usableSets() == 2) m_front = 1 - m_front;
    m_changed = false;
    m_issue_ms += msSince(start);
    m_stats.upload_ms = m_issue_ms;
    return;
  }
  if (staged()) m_staging.fenceFrame();
  const uint32_t target = stackSets() == 1 ? 0 : 1 - m_front;
  const uint32_t usable_target = usableSets() == 1 ? 0 : 1 - m_front;
  fillCoarserMips(target);
  const auto mips_done = Clock::now();
  m_stats.coarser_mips_ms = std::chrono::duration<double, std::milli>(mips_done - start).count();
  writeUsableMap(usable_target);
  m_stats.usable_ms = msSince(mips_done);
  if (usableSets() == 2) m_front = 1 - m_front;
  m_changed = false;
  m_issue_ms += msSince(start);
  m_stats.upload_ms = m_issue_ms;
}

// The usable map of this frame's residency into set `target`: rewritten
// when its windows or finest levels changed, or always with two sets (the
// back one is a frame behind).
void ClipmapRenderer::Impl::writeUsableMap(uint32_t target) {
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
      glTextureSubImage3D(m_usable_tex[target], 0, 0, 0, 0, GLsizei(c), GLsizei(c),
                          GLsizei(map.usable.size()), GL_RED_INTEGER, GL_UNSIGNED_SHORT, flat.data());
      glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    }
  }
  m_front_map = std::move(map);
}

void ClipmapRenderer::Impl::draw(const Camera& camera, const Viewport& viewport) {
  const GLuint p = m_program[m_overlay == Overlay::kOff ? 0 : 1];
  bindColour(p, camera, viewport);
  glUseProgram(p);
  glBindVertexArray(m_vao);
  glDisable(GL_DEPTH_TEST);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glBindVertexArray(0);
  glUseProgram(0);
}

std::string ClipmapRenderer::Impl::shaderDefines() const {
  if (!paged()) return "";
  return "#define PAGED 1\n#define PAGE_BORDER " + std::to_string(m_page_border) + "\n";
}

void ClipmapRenderer::Impl::bindColour(uint32_t p, const Camera& camera, const Viewport& viewport) const {
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

}  // namespace clipstream
