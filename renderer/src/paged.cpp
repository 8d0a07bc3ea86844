// TextureMemory::kPaged: the colour tiles in one pool of pages behind
// per-level indirection maps. Bookkeeping: page_table.h; the shader's side:
// shaders/ground_clipmap.frag (PAGED); the design and its measurements:
// docs/renderer.md, "Paged texture memory".
//
// The pool is an array texture of layers of 2 x 2 pages (so it may hold
// four times GL_MAX_ARRAY_TEXTURE_LAYERS pages); a tile always takes a page
// in the quarter its x and y parity name (PageTable's classes), so its
// texels sit at the same place in a layer, and are sampled with the same
// coordinates, whichever layer it gets. A page is the tile in the middle, a border
// of m_page_border texels of its 8 neighbours around it, and in mip 1 the
// next coarser level over the tile with half that border. So one trilinear
// fetch inside the page reads what the full stack's fetch reads, and no
// filter footprint leaves the page. Borders are copied on the GPU from the
// neighbours' pages, in both directions, when a page is filled; a
// neighbour without a page leaves that border unfilled, which keeps the
// tile from being drawn (computeUsableMap() requires every neighbour the
// frame reads to have a page) until it comes. A tile's texels never
// change while it is in the pool, so a filled border stays right even
// after its neighbour's page is reused.
#include "clipmap_renderer_impl.h"

#include "gl.h"
#include "gl_util.h"
#include "tile_fill.h"

#include <clipstream/streamer/bc1.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

namespace clipstream {

using gl_util::msSince;

uint64_t pageBytes(uint32_t tile_px, TileContent content) {
  const bool bc1 = content == TileContent::kBc1;
  const uint64_t page_px = tile_px + 2 * (bc1 ? renderer_config::kPageBorderBc1 : renderer_config::kPageBorderRgba8);
  const uint64_t m0 = page_px * page_px, m1 = (page_px / 2) * (page_px / 2);
  return bc1 ? (m0 + m1) / 2 : (m0 + m1) * 4;
}

Status ClipmapRenderer::Impl::createPaged() {
  const bool bc1 = compressed();
  const uint32_t levels = m_geometry.levelCount();
  const uint64_t pool_bytes =
      m_config.pool_bytes != 0 ? m_config.pool_bytes
                               : defaultPoolBytes(Viewport{1920, 1080}, m_geometry.tile_px, m_config.tile_content);
  GLint max_layers = 0;
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
  const uint64_t page_bytes = pageBytes(m_geometry.tile_px, m_config.tile_content);
  // Whole layers of four pages.
  const uint64_t pages = std::min<uint64_t>(pool_bytes / page_bytes, 4 * uint64_t(std::max(max_layers, 1))) / 4 * 4;
  const LevelInfo& top = m_geometry.levels[m_config.pyramid_level];
  if (top.tiles_x > renderer_config::kPagedPyramidTiles || top.tiles_y > renderer_config::kPagedPyramidTiles)
    return Status::error(ErrorCode::kInvalidArgument,
                         "renderer: paged texture memory takes a pyramid of at most " +
                             std::to_string(renderer_config::kPagedPyramidTiles) +
                             " tiles a side (PlannerConfig::pyramid_tiles; plannerFor() sets it)");
  // Page 0 stays black (slots with no page point there), the pyramid level
  // takes the layers after it at fixed places (pyramidPage()), and the
  // coarser levels are pinned where they land. A tile only takes a page of
  // its parity class (a quarter of the pool), so every class must keep a
  // page for the stack levels after its share of those.
  m_pyramid_layers_x = (top.tiles_x + 1) / 2;
  const uint32_t pyramid_layers = m_pyramid_layers_x * ((top.tiles_y + 1) / 2);
  const uint32_t reserved_end = pyramidPage(0, 0) + 4 * pyramid_layers;
  uint64_t taken[4] = {1 + uint64_t(pyramid_layers), pyramid_layers, pyramid_layers, pyramid_layers};
  for (uint32_t l = m_config.pyramid_level + 1; l < levels; ++l)
    for (uint32_t y = 0; y < m_geometry.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < m_geometry.levels[l].tiles_x; ++x) ++taken[(x & 1) + 2 * (y & 1)];
  const uint64_t most_taken = *std::max_element(taken, taken + 4);
  if (pages / 4 < most_taken + 1) {
    char size[32];
    std::snprintf(size, sizeof size, "%.2f MiB", double(pool_bytes) / (1 << 20));
    return Status::error(ErrorCode::kInvalidArgument,
                         "renderer: a pool of " + std::string(size) + " holds " + std::to_string(pages) +
                             " pages of " + std::to_string(m_page_px) +
                             " px (at most 4 x GL_MAX_ARRAY_TEXTURE_LAYERS " + std::to_string(max_layers) +
                             "), a quarter of them for each tile parity; the black page and the pinned "
                             "pyramid take " +
                             std::to_string(most_taken) + " of one quarter and leave none: give a larger pool");
  }

  gl_util::clearErrors();
  const GLsizei layers = GLsizei(pages / 4), layer_px = GLsizei(2 * m_page_px);
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &m_stack[0]);
  glTextureStorage3D(m_stack[0], 2, bc1 ? kBc1Format : GL_RGBA8, layer_px, layer_px, layers);
  glTextureParameteri(m_stack[0], GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTextureParameteri(m_stack[0], GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(m_stack[0], GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(m_stack[0], GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glTextureParameteri(m_stack[0], GL_TEXTURE_MAX_LEVEL, 1);
  for (GLint m = 0; m < 2; ++m) {
    const GLsizei size = layer_px >> m;
    if (bc1) {
      const std::vector<uint8_t> zeros(size_t(size / 4) * size_t(size / 4) * kBc1BlockBytes, 0);
      for (GLsizei layer = 0; layer < layers; ++layer)
        glCompressedTextureSubImage3D(m_stack[0], m, 0, 0, layer, size, size, 1, kBc1Format,
                                      GLsizei(zeros.size()), zeros.data());
    } else {
      const uint8_t zero[4] = {0, 0, 0, 0};
      glClearTexImage(m_stack[0], m, GL_RGBA, GL_UNSIGNED_BYTE, zero);
    }
  }
  m_texture_bytes.stack = pages * page_bytes;
  char what[160];
  std::snprintf(what, sizeof what, "the page pool (%llu pages, %.1f MiB of %s)", (unsigned long long)pages,
                double(m_texture_bytes.stack) / (1 << 20), bc1 ? "BC1" : "RGBA8");
  if (Status s = gl_util::checkCreated(what, "a smaller pool (--pool-mb) needs less"); !s) return s;

  const uint32_t c = m_slots;
  for (uint32_t set = 0; set < usableSets(); ++set) {
    const uint32_t zero[4] = {0, 0, 0, 0};
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &m_usable_tex[set]);
    glTextureStorage3D(m_usable_tex[set], 1, GL_R32UI, GLsizei(c), GLsizei(c), GLsizei(levels));
    glTextureParameteri(m_usable_tex[set], GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(m_usable_tex[set], GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glClearTexImage(m_usable_tex[set], 0, GL_RED_INTEGER, GL_UNSIGNED_INT, zero);
    m_texture_bytes.usable += uint64_t(c) * c * levels * 4;
    if (Status s = gl_util::checkCreated("the page pool's indirection maps"); !s) return s;
  }
  if (staged()) {
    if (Status s = m_staging.create(size_t(std::max(m_config.staging_tiles, 1u)) * tileBytes()); !s) return s;
    m_texture_bytes.staging = m_staging.bytes();
  }

  m_pages = std::make_unique<PageTable>(uint32_t(pages), 4);
  // Page 0: black, pinned, no tile's (a key outside every pyramid). Pages
  // 1-3 are free; the pyramid level's layers follow.
  m_pages->reserve(0, 1);
  m_pages->reserve(pyramidPage(0, 0), reserved_end);
  m_pages->allocateAt(0, TileKey{63, 0, 0}, 0);
  for (uint32_t l = m_config.pyramid_level; l < levels; ++l) {
    m_pyramid_first.push_back(m_pyramid_have.size());
    m_pyramid_have.resize(m_pyramid_have.size() + size_t(m_geometry.levels[l].tiles_x) * m_geometry.levels[l].tiles_y,
                          0);
  }
  m_pyramid_missing = uint32_t(m_pyramid_have.size());
  m_front_map = computeUsableMap(m_geometry, c, m_config.pyramid_level, {});
  return okStatus();
}

void ClipmapRenderer::Impl::writePage(uint32_t page, const uint8_t* pixels) {
  const GLsizei tp = GLsizei(m_geometry.tile_px);
  const GLint b = GLint(m_page_border);
  pixels = beginTileUpload(pixels);
  const GLint x = GLint((page & 1) * m_page_px) + b, y = GLint(((page >> 1) & 1) * m_page_px) + b;
  if (compressed())
    glCompressedTextureSubImage3D(m_stack[0], 0, x, y, GLint(page / 4), tp, tp, 1, kBc1Format,
                                  GLsizei(tileBytes()), pixels);
  else
    glTextureSubImage3D(m_stack[0], 0, x, y, GLint(page / 4), tp, tp, 1, GL_RGBA, GL_UNSIGNED_BYTE, pixels);
  if (staged()) glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
}

void ClipmapRenderer::Impl::copyPageRegion(uint32_t src_page, uint32_t src_mip, uint32_t sx, uint32_t sy,
                                     uint32_t dst_page, uint32_t dst_mip, uint32_t dx, uint32_t dy, uint32_t w,
                                     uint32_t h) {
  // Page p is quarter p % 4 of layer p / 4; positions are the page's own.
  auto at = [&](uint32_t page, uint32_t mip, uint32_t x, uint32_t y, GLint* gx, GLint* gy) {
    *gx = GLint((((page & 1) * m_page_px) >> mip) + x);
    *gy = GLint(((((page >> 1) & 1) * m_page_px) >> mip) + y);
  };
  GLint ax, ay, bx, by;
  at(src_page, src_mip, sx, sy, &ax, &ay);
  at(dst_page, dst_mip, dx, dy, &bx, &by);
  glCopyImageSubData(m_stack[0], GL_TEXTURE_2D_ARRAY, GLint(src_mip), ax, ay, GLint(src_page / 4), m_stack[0],
                     GL_TEXTURE_2D_ARRAY, GLint(dst_mip), bx, by, GLint(dst_page / 4), GLsizei(w), GLsizei(h), 1);
}

void ClipmapRenderer::Impl::fillBorders(uint32_t page, const TileKey& key) {
  // Along one axis, for a neighbour at offset d in {-1, 0, 1}: where the
  // border lies in this page, and where its texels lie in the neighbour's
  // page (its edge facing this tile). A tile whose neighbour is outside the
  // level takes its own edge strip there instead.
  const uint32_t tp = m_geometry.tile_px, b = m_page_border;
  auto border_at = [&](int d) { return d < 0 ? 0u : d == 0 ? b : b + tp; };
  auto edge_at = [&](int d) { return d < 0 ? tp : d == 0 ? b : b; };  // in the neighbour, facing us
  auto own_at = [&](int d) { return d < 0 ? b : d == 0 ? b : tp; };   // this tile's own edge strip
  auto extent = [&](int d) { return d == 0 ? tp : b; };
  const LevelInfo& info = m_geometry.levels[key.level];
  uint8_t filled = 0;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      if (dx == 0 && dy == 0) continue;
      const int64_t nx = int64_t(key.x) + dx, ny = int64_t(key.y) + dy;
      const uint32_t bit = 1u << borderBit(dx, dy);
      if (nx < 0 || ny < 0 || nx >= int64_t(info.tiles_x) || ny >= int64_t(info.tiles_y)) {
        copyPageRegion(page, 0, own_at(dx), own_at(dy), page, 0, border_at(dx), border_at(dy), extent(dx),
                       extent(dy));
        filled |= uint8_t(bit);
        continue;
      }
      const uint32_t other = m_pages->find(TileKey{key.level, uint32_t(nx), uint32_t(ny)});
      if (other == PageTable::kNoPage) continue;
      // Its edge into our border, and ours into its border facing us.
      copyPageRegion(other, 0, edge_at(dx), edge_at(dy), page, 0, border_at(dx), border_at(dy), extent(dx),
                     extent(dy));
      filled |= uint8_t(bit);
      copyPageRegion(page, 0, edge_at(-dx), edge_at(-dy), other, 0, border_at(-dx), border_at(-dy), extent(dx),
                     extent(dy));
      m_pages->addBorders(other, uint8_t(1u << borderBit(-dx, -dy)));
    }
  m_pages->addBorders(page, filled);
}

uint32_t ClipmapRenderer::Impl::placePage(const TileKey& key, const uint8_t* pixels, bool pin) {
  const uint32_t page = key.level == m_config.pyramid_level
                            ? m_pages->allocateAt(pyramidPage(key.x, key.y), key, m_frame)
                            : m_pages->allocate(key, m_frame, pin);
  if (page == PageTable::kNoPage) return page;
  writePage(page, pixels);
  fillBorders(page, key);
  ++m_stats.pages_filled;
  m_pages_changed = true;
  return page;
}

void ClipmapRenderer::Impl::uploadTilePaged(const TileKey& key, std::shared_ptr<const std::vector<uint8_t>> rgba) {
  if (key.level >= m_config.pyramid_level) {
    const size_t index = m_pyramid_first[key.level - m_config.pyramid_level] +
                         size_t(key.y) * m_geometry.levels[key.level].tiles_x + key.x;
    if (m_pyramid_have[index]) return;
    if (placePage(key, rgba->data(), true) == PageTable::kNoPage) return;  // create() made room
    m_pyramid_have[index] = 1;
    --m_pyramid_missing;
    m_page_pixels[PageTable::pack(key)] = std::move(rgba);
  } else {
    m_page_pixels[PageTable::pack(key)] = std::move(rgba);
  }
  ++m_stats.tiles;
  m_changed = true;
}

uint32_t ClipmapRenderer::Impl::fillMissingPyramidPages() {
  // A pyramid tile the source could not give is made from its parent's
  // pixels (the quarter over it, magnified bilinearly), coarse levels
  // first so a made parent serves its children; with no parent, mid grey.
  const uint32_t tp = m_geometry.tile_px;
  uint32_t filled = 0;
  for (uint32_t l = m_geometry.levelCount(); l-- > m_config.pyramid_level;) {
    const LevelInfo& info = m_geometry.levels[l];
    for (uint32_t y = 0; y < info.tiles_y; ++y)
      for (uint32_t x = 0; x < info.tiles_x; ++x) {
        const size_t index = m_pyramid_first[l - m_config.pyramid_level] + size_t(y) * info.tiles_x + x;
        if (m_pyramid_have[index]) continue;
        std::vector<uint8_t> rgba(size_t(tp) * tp * 4, 128);
        for (size_t i = 3; i < rgba.size(); i += 4) rgba[i] = 255;
        const auto parent = m_page_pixels.find(PageTable::pack(TileKey{l + 1, x / 2, y / 2}));
        if (l + 1 < m_geometry.levelCount() && parent != m_page_pixels.end()) {
          std::vector<uint8_t> decoded;
          const uint8_t* src = parent->second->data();
          if (compressed()) {
            if (!decodeBc1Tile(*parent->second, tp, &decoded)) continue;
            src = decoded.data();
          }
          magnifyQuarter(src, tp, (x & 1) * (tp / 2), (y & 1) * (tp / 2), tp / 2, tp / 2, tp, rgba.data());
        }
        auto pixels = std::make_shared<std::vector<uint8_t>>();
        if (compressed()) {
          if (!encodeBc1Tile(rgba, tp, pixels.get())) continue;
        } else {
          *pixels = std::move(rgba);
        }
        uploadTilePaged(TileKey{l, x, y}, std::move(pixels));
        ++filled;
      }
  }
  return filled;
}

void ClipmapRenderer::Impl::indexPages() {
  // Every page's tile at its slot: a stack level's window tile at its
  // toroidal slot (one tile of a window per slot), a pyramid level's tile
  // at x + y * c (its levels are at most clip_tiles < c tiles a side).
  // Pages of tiles outside their window are left out.
  const uint32_t c = m_slots, pyramid = m_config.pyramid_level;
  m_slot_pages.assign(size_t(c) * c * m_geometry.levelCount(), 0);
  for (uint32_t page = 1; page < m_pages->pages(); ++page) {
    if (!m_pages->holds(page)) continue;
    const TileKey& k = m_pages->key(page);
    if (k.level < pyramid && !m_page_windows[k.level].contains(k.x, k.y)) continue;
    m_slot_pages[slotIndex(k.level, k.x, k.y)] = page;
  }
}

uint32_t ClipmapRenderer::Impl::pageOf(uint32_t level, int64_t x, int64_t y) const {
  if (level < m_config.pyramid_level && !m_page_windows[level].contains(x, y))
    return m_pages->find(TileKey{level, uint32_t(x), uint32_t(y)});
  const uint32_t page = m_slot_pages[slotIndex(level, x, y)];
  return page != 0 && m_pages->holds(page) && m_pages->key(page) == TileKey{level, uint32_t(x), uint32_t(y)}
             ? page
             : PageTable::kNoPage;
}

void ClipmapRenderer::Impl::endUploadsPaged(uint32_t target) {
  ++m_frame;
  const std::vector<const LevelResidency*> by_level = keepResidentPages();
  placeWantedPages(by_level);
  // Only a page placed (this frame's, or a pyramid tile's since the last
  // frame) changes what follows from the pages: their borders, mip 1 and
  // the maps' page numbers.
  if (m_pages_changed) copyMip1FromParents();
  const auto usable_start = std::chrono::steady_clock::now();
  updatePagedUsableMap(by_level);
  writeIndirectionMap(target);
  m_stats.usable_ms = msSince(usable_start);
}

std::vector<const LevelResidency*> ClipmapRenderer::Impl::keepResidentPages() {
  const uint32_t pyramid = m_config.pyramid_level;
  const uint32_t c = m_slots;
  // Stack tiles are kept while their window holds them resident.
  std::vector<const LevelResidency*> by_level(pyramid, nullptr);
  for (const LevelResidency& r : m_residency)
    // A window wider than the slots would alias them (computeUsableMap()
    // refuses it too): its level is not drawn.
    if (r.level < pyramid && r.window.width() <= int64_t(c) && r.window.height() <= int64_t(c) &&
        r.resident.size() == size_t(r.window.width()) * size_t(r.window.height()))
      by_level[r.level] = &r;
  auto resident = [&](const TileKey& k) {
    const LevelResidency* r = by_level[k.level];
    if (r == nullptr || !r->window.contains(k.x, k.y)) return false;
    return r->resident[size_t(int64_t(k.y) - r->window.y0) * size_t(r->window.width()) +
                       size_t(int64_t(k.x) - r->window.x0)] != 0;
  };
  for (auto it = m_page_pixels.begin(); it != m_page_pixels.end();) {
    const TileKey k = PageTable::unpack(it->first);
    if (k.level < pyramid && !resident(k)) it = m_page_pixels.erase(it);
    else ++it;
  }
  // Where each page's tile sits this frame (the windows move): the lookups
  // below are array reads, not hash finds over every window slot.
  std::vector<TileRect> windows(pyramid);
  for (uint32_t l = 0; l < pyramid; ++l)
    if (by_level[l] != nullptr) windows[l] = by_level[l]->window;
  if (windows != m_page_windows || m_pages_changed) {
    m_page_windows = std::move(windows);
    indexPages();
  }
  return by_level;
}

void ClipmapRenderer::Impl::placeWantedPages(const std::vector<const LevelResidency*>& by_level) {
  const uint32_t pyramid = m_config.pyramid_level;
  // The tiles the frame reads, coarse levels first (every finer tile needs
  // its ancestors), near the window's centre first within a level (the
  // windows lie around the camera's ground point). Those with a page keep
  // it this frame; the others take one while the pool has pages to give.
  struct Want {
    double distance;
    TileKey key;
  };
  std::vector<Want> wants;
  for (uint32_t l = pyramid; l-- > 0;) {
    const LevelResidency* r = by_level[l];
    if (r == nullptr) continue;
    const TileRect& w = r->window;
    const bool any_unread = r->unread.size() == r->resident.size();
    const double cx = 0.5 * double(w.x0 + w.x1), cy = 0.5 * double(w.y0 + w.y1);
    const size_t first = wants.size();
    size_t i = 0;
    for (int64_t y = w.y0; y < w.y1; ++y)
      for (int64_t x = w.x0; x < w.x1; ++x, ++i) {
        if (!r->resident[i] || (any_unread && r->unread[i])) continue;
        const uint32_t page = pageOf(l, x, y);
        if (page != PageTable::kNoPage) {
          m_pages->use(page, m_frame);
          ++m_stats.pages_wanted;
          continue;
        }
        const TileKey key{l, uint32_t(x), uint32_t(y)};
        if (m_page_pixels.count(PageTable::pack(key)) == 0) continue;
        wants.push_back({std::hypot(x + 0.5 - cx, y + 0.5 - cy), key});
      }
    std::stable_sort(wants.begin() + std::ptrdiff_t(first), wants.end(),
                     [](const Want& a, const Want& b) { return a.distance < b.distance; });
  }
  m_stats.pages_wanted += uint32_t(wants.size()) + m_pages->pinned();
  const uint32_t filled_before = m_stats.pages_filled;
  for (const Want& want : wants) {
    const auto& pixels = m_page_pixels[PageTable::pack(want.key)];
    if (placePage(want.key, pixels->data(), false) == PageTable::kNoPage) ++m_stats.pages_short;
  }
  // The index above predates this frame's pages (and what they evicted).
  if (m_stats.pages_filled != filled_before) indexPages();
}

void ClipmapRenderer::Impl::copyMip1FromParents() {
  const uint32_t levels = m_geometry.levelCount();
  // Mip 1 of every page: the parent's texels over it, copied again when
  // the parent's page has borders it did not have at the last copy.
  const uint32_t tp = m_geometry.tile_px, b = m_page_border;
  for (uint32_t page = 1; page < m_pages->pages(); ++page) {
    if (!m_pages->holds(page)) continue;
    const uint16_t from = m_pages->mip1From(page);
    if (from == kAllBorders) continue;  // the parent has nothing more to give
    const TileKey& k = m_pages->key(page);
    if (k.level + 1 >= levels) continue;
    const uint32_t parent = pageOf(k.level + 1, k.x / 2, k.y / 2);
    if (parent == PageTable::kNoPage) continue;
    const uint16_t has = m_pages->borders(parent);
    if (from != PageTable::kMip1Empty && (has & ~from) == 0) continue;
    copyPageRegion(parent, 0, b + (k.x & 1) * (tp / 2) - b / 2, b + (k.y & 1) * (tp / 2) - b / 2, page, 1, 0, 0,
                   tp / 2 + b, tp / 2 + b);
    m_pages->setMip1From(page, has);
  }
}

void ClipmapRenderer::Impl::updatePagedUsableMap(const std::vector<const LevelResidency*>& by_level) {
  const uint32_t pyramid = m_config.pyramid_level;
  const uint32_t c = m_slots;
  // The usable map over what has a page, computed again only when that
  // changed (the windows, residency or pages).
  std::vector<LevelResidency> paged;
  paged.reserve(m_residency.size());
  for (const LevelResidency& r : m_residency) {
    if (r.level >= pyramid || by_level[r.level] != &r) continue;
    LevelResidency p;
    p.level = r.level;
    p.window = r.window;
    p.unread = r.unread;
    p.resident.resize(r.resident.size());
    // The index holds exactly the window's tiles with a page.
    const uint32_t* slots = m_slot_pages.data() + size_t(r.level) * c * c;
    size_t i = 0;
    for (int64_t y = r.window.y0; y < r.window.y1; ++y) {
      const uint32_t* row = slots + size_t(toroidalSlot(y, c)) * c;
      for (int64_t x = r.window.x0; x < r.window.x1; ++x, ++i) p.resident[i] = row[toroidalSlot(x, c)] != 0;
    }
    paged.push_back(std::move(p));
  }
  const bool same_input = m_paged_input_valid && paged.size() == m_paged_input.size() &&
                          std::equal(paged.begin(), paged.end(), m_paged_input.begin(),
                                     [](const LevelResidency& a, const LevelResidency& b) {
                                       return a.level == b.level && a.window == b.window &&
                                              a.resident == b.resident && a.unread == b.unread;
                                     });
  if (!same_input) {
    UsableMap map = computeUsableMap(m_geometry, c, pyramid, paged);
    if (m_pages_changed || map.windows != m_front_map.windows || map.finest != m_front_map.finest) ++m_map_generation;
    m_front_map = std::move(map);
    m_paged_input = std::move(paged);
    m_paged_input_valid = true;
  } else if (m_pages_changed) {
    ++m_map_generation;
  }
  m_pages_changed = false;
}

void ClipmapRenderer::Impl::writeIndirectionMap(uint32_t target) {
  const uint32_t pyramid = m_config.pyramid_level;
  const uint32_t levels = m_geometry.levelCount();
  const uint32_t c = m_slots;
  // Per slot of every level: usableCode() | levels up << 8 | page << 16,
  // the page of the finest usable tile over the slot's tile (its ancestor
  // `up` levels coarser). Stack levels: their window's tiles; the pyramid's
  // levels: every tile (they fit the slots). 0 elsewhere. Written into a
  // set only when it holds an older map.
  if (m_map_written[target] != m_map_generation) {
    const UsableMap& map = m_front_map;
    std::vector<uint32_t> flat(size_t(c) * c * levels, 0);
    for (uint32_t l = 0; l < levels; ++l) {
      const TileRect w = l < pyramid ? map.windows[l]
                                     : TileRect{0, 0, int64_t(m_geometry.levels[l].tiles_x),
                                                int64_t(m_geometry.levels[l].tiles_y)};
      // A window tile's own page is its slot's (the index is this window's).
      const bool indexed = l >= pyramid || w == m_page_windows[l];
      const uint32_t* slots = m_slot_pages.data() + size_t(l) * c * c;
      uint32_t* out = flat.data() + size_t(l) * c * c;
      const uint8_t* finest = l < pyramid ? map.finest[l].data() : nullptr;
      forEachWindowSlot(w, c, [&](int64_t x, int64_t y, size_t i, uint8_t code) {
        const uint32_t up = finest != nullptr ? finest[i] - l : 0;
        uint32_t page = 0;
        if (up == 0 && indexed) {
          page = slots[i];
        } else if (const uint32_t p = pageOf(l + up, x >> up, y >> up); p != PageTable::kNoPage) {
          page = p;
        }
        out[i] = uint32_t(code) | (up << 8) | (page << 16);
      });
    }
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glTextureSubImage3D(m_usable_tex[target], 0, 0, 0, 0, GLsizei(c), GLsizei(c), GLsizei(levels), GL_RED_INTEGER,
                        GL_UNSIGNED_INT, flat.data());
    m_map_written[target] = m_map_generation;
  }
}

}  // namespace clipstream
