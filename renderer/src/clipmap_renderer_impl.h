// ClipmapRenderer's implementation: its GL objects and the state of its
// frames, shared by the files that implement it: clipmap_renderer.cpp
// (creation, the frame protocol, drawing), pyramid_fill.cpp (the coarse
// pyramid and its fallbacks), paged.cpp (TextureMemory::kPaged) and
// staging_ring.h (Buffering::kStaged's ring). Internal to the library:
// the library's other drawers (TerrainRenderer) sample the colour through
// bindColour(), and tests reach setSlotBias() here.
//
// GL thread only, as ClipmapRenderer.
#pragma once

#include "staging_ring.h"

#include <clipstream/renderer/clipmap.h>
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/page_table.h>
#include <clipstream/renderer/renderer.h>

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

namespace clipstream {

struct ClipmapRenderer::Impl {
  ~Impl();

  // ClipmapRenderer::create()'s checks and allocations.
  Status init(const PyramidGeometry& geometry, const RendererConfig& config);
  Status createStack();

  // The frame protocol (ClipmapRenderer's public methods).
  void beginFrame();
  void uploadTile(const TileKey& key, std::shared_ptr<const std::vector<uint8_t>> rgba);
  void setResidency(const std::vector<LevelResidency>& residency);
  void endUploads();
  void draw(const Camera& camera, const Viewport& viewport);
  uint32_t loadPyramid(const PyramidTileFn& tile);

  // Binds the colour stack and usable map (texture units 0 and 1) and sets
  // the sampling uniforms of ground_clipmap.frag on `program` for this
  // camera: what draw() does before its triangle, for programs that draw
  // other geometry with the same fragment shader (TerrainRenderer).
  void bindColour(uint32_t program, const Camera& camera, const Viewport& viewport) const;
  // The #defines every program that samples the colour with
  // ground_clipmap.frag needs for this renderer (bindColour()).
  std::string shaderDefines() const;
  // Puts every stack tile `bias` slots off its true slot
  // (toroidalSlot(x + bias)): a deliberately wrong toroidal offset, which
  // tests use to show that the frames' checks catch one.
  void setSlotBias(int64_t bias) { m_slot_bias = bias; }

  // Fills every pyramid tile that was never uploaded: the tile is
  // magnified from its parent (bilinear GPU blit, coarse levels first, so a
  // filled parent serves its children); a tile with no parent in the chain
  // is averaged down from its children, or else cleared to mid grey. Filled
  // tiles count as uploaded (a later upload of the tile is skipped).
  // Returns the number of tiles filled.
  uint32_t fillMissingPyramidTiles();
  struct Pending {
    TileKey key;
    std::shared_ptr<const std::vector<uint8_t>> rgba;
  };
  void uploadStack(uint32_t set, const TileKey& key, const uint8_t* pixels);
  void uploadPyramid(const TileKey& key, const uint8_t* pixels);
  // BC1: one pyramid tile made on the CPU (read back, decoded, filtered,
  // encoded): magnified from its parent, averaged from its children, or
  // mid grey. Compressed textures cannot be blit or cleared into.
  enum class Fill { kFromParent, kFromChildren, kGrey };
  void fillPyramidTileBc1(const TileKey& key, Fill fill);
  // Decoded RGBA8 of the pyramid layer's region [x, x + w) x [y, y + h)
  // of `mip` (block-aligned, inside the mip), set 0.
  std::vector<uint8_t> readPyramidRegion(uint32_t mip, uint32_t x, uint32_t y, uint32_t w, uint32_t h) const;
  bool compressed() const { return m_config.tile_content == TileContent::kBc1; }
  bool paged() const { return m_config.texture_memory == TextureMemory::kPaged; }

  // kPaged (paged.cpp). The pool and the indirection maps.
  Status createPaged();
  // A stack tile is kept (pixels) until it leaves its window; a pyramid
  // tile gets its pinned page at once.
  void uploadTilePaged(const TileKey& key, std::shared_ptr<const std::vector<uint8_t>> rgba);
  // Gives pages to the tiles the frame samples (coarse levels first, near
  // the window's centre first), fills their borders and mip 1, and writes
  // the indirection maps into set `target`.
  void endUploadsPaged(uint32_t target);
  // endUploadsPaged()'s steps, in order. Drops the pixels kept for stack
  // tiles no longer resident, re-indexes the pages when the windows moved;
  // each stack level's residency where it is drawn (else null).
  std::vector<const LevelResidency*> keepResidentPages();
  // Keeps the pages of the tiles the frame reads and places the others,
  // coarse levels first, near each window's centre first, while the pool
  // has pages.
  void placeWantedPages(const std::vector<const LevelResidency*>& by_level);
  // Mip 1 of every page from its parent's page (only after a page moved).
  void copyMip1FromParents();
  // The usable map over what has a page, computed again only when that
  // changed; clears m_pages_changed.
  void updatePagedUsableMap(const std::vector<const LevelResidency*>& by_level);
  // Writes the indirection map into set `target` when it holds an older one.
  void writeIndirectionMap(uint32_t target);
  // Takes a page for `key` and writes `pixels` into it (with its borders
  // from the neighbours' pages); kNoPage when the pool is full this frame.
  uint32_t placePage(const TileKey& key, const uint8_t* pixels, bool pin);
  // The pyramid level's tile (x, y) lives at a fixed page, which the shader
  // computes the same way (its fallback then needs no lookup): layer
  // 1 + (y / 2) * m_pyramid_layers_x + x / 2, the quarter of its parity.
  uint32_t pyramidPage(uint32_t x, uint32_t y) const {
    return 4 * (1 + (y >> 1) * m_pyramid_layers_x + (x >> 1)) + (x & 1) + 2 * (y & 1);
  }
  // The page of level `level`'s tile (x, y), or PageTable::kNoPage: an
  // array read for a tile of its window (or a pyramid level's), from the
  // index indexPages() builds; a hash find elsewhere.
  uint32_t pageOf(uint32_t level, int64_t x, int64_t y) const;
  void indexPages();
  size_t slotIndex(uint32_t level, int64_t x, int64_t y) const {
    return (size_t(level) * m_slots + toroidalSlot(y, m_slots)) * m_slots + toroidalSlot(x, m_slots);
  }
  void writePage(uint32_t page, const uint8_t* pixels);
  void copyPageRegion(uint32_t src_page, uint32_t src_mip, uint32_t sx, uint32_t sy, uint32_t dst_page,
                      uint32_t dst_mip, uint32_t dx, uint32_t dy, uint32_t w, uint32_t h);
  void fillBorders(uint32_t page, const TileKey& key);
  uint32_t fillMissingPyramidPages();
  size_t tileBytes() const;
  void fillCoarserMips(uint32_t set);
  // Writes the usable map into set `target` when it changed.
  void writeUsableMap(uint32_t target);
  // Stack arrays and usable maps: two of each when double-buffered; staged
  // keeps one stack and two usable maps.
  uint32_t stackSets() const {
    return m_config.buffering == Buffering::kDoubleUploadTwice || m_config.buffering == Buffering::kDoubleCopy
               ? 2
               : 1;
  }
  uint32_t usableSets() const { return m_config.buffering == Buffering::kSingle ? 1 : 2; }
  bool staged() const { return m_config.buffering == Buffering::kStaged; }
  // Unpack state for one tile's upload; kStaged: stages `pixels` and binds
  // the ring, returning the offset to pass instead (unbind after the call).
  const uint8_t* beginTileUpload(const uint8_t* pixels);
  uint32_t slot(int64_t tile, uint32_t period) const { return toroidalSlot(tile + m_slot_bias, period); }

  PyramidGeometry m_geometry;
  RendererConfig m_config;
  uint32_t m_slots = 0;  // slot period: clip_tiles rounded down to even, plus 2 (see init())
  uint32_t m_mips = 0;   // mips of the stack array: 0 = level L, 1 = level L + 1, ...
  // Two builds of the ground shader: without and with the overlay. A
  // uniform switch would cost the overlay's arithmetic on every fragment
  // (llvmpipe runs both sides of a branch), about 0.6 ms per 640x360 frame.
  uint32_t m_program[2] = {0, 0};
  uint32_t m_vao = 0;
  uint32_t m_stack[2] = {0, 0};
  uint32_t m_usable_tex[2] = {0, 0};
  uint32_t m_front = 0;           // index of the set the shader samples
  // Which tile each slot holds, per set and stack level (x | y << 32;
  // kNoTile = none): mip 0 slots (period m_slots) and mip 1 slots (period
  // m_slots / 2, the next coarser level over this level's window).
  static constexpr uint64_t kNoTile = ~uint64_t(0);
  std::vector<std::vector<uint64_t>> m_mip0_tile[2];
  std::vector<std::vector<uint64_t>> m_mip1_tile[2];
  std::vector<Pending> m_pending; // landed in the front set, not yet in the back
  std::vector<LevelResidency> m_residency;
  UsableMap m_front_map;
  bool m_changed = false;
  uint32_t m_max_texture_lod = 0;
  Overlay m_overlay = Overlay::kOff;
  int64_t m_slot_bias = 0;
  std::vector<uint8_t> m_pyramid_have;  // per pyramid tile, 1 = uploaded
  std::vector<size_t> m_pyramid_first;  // index of each pyramid level's first tile
  uint32_t m_pyramid_missing = 0;
  TextureBytes m_texture_bytes;
  StagingRing m_staging;  // kStaged
  UploadStats m_stats;
  double m_issue_ms = 0.0;
  // kPaged: m_stack[0] is the pool (a layer per page), m_usable_tex the
  // indirection maps (every level), page 0 a black page for slots that
  // have none.
  std::unique_ptr<PageTable> m_pages;
  std::unordered_map<uint64_t, std::shared_ptr<const std::vector<uint8_t>>> m_page_pixels;
  uint32_t m_page_border = 0;  // texels of border on each side (mip 0)
  uint32_t m_page_px = 0;      // tile_px + 2 borders
  uint32_t m_pyramid_layers_x = 0;  // layers a row of the pyramid level's pages (pyramidPage())
  uint64_t m_frame = 1;
  // kPaged, per frame: each window tile's and pyramid tile's page by slot (indexPages(); 0 =
  // none) over the windows it was built for; whether a page was placed
  // since the last endUploadsPaged(); the usable map's input then, and a
  // generation of the indirection maps' contents with the one each set holds.
  std::vector<uint32_t> m_slot_pages;
  std::vector<TileRect> m_page_windows;
  bool m_pages_changed = true;
  std::vector<LevelResidency> m_paged_input;
  bool m_paged_input_valid = false;
  uint64_t m_map_generation = 1;
  uint64_t m_map_written[2] = {0, 0};
};

// x | y << 32: a tile's position, as the slot tables hold it.
inline uint64_t packTile(int64_t x, int64_t y) { return uint64_t(uint32_t(x)) | (uint64_t(uint32_t(y)) << 32); }

}  // namespace clipstream
