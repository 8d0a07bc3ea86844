// The clipmap on the GPU and the ground it draws.
//
// Owned by the GL thread: every method must be called on the thread whose
// context was current at create(). Tile pixels are shared_ptr-held so the
// double-buffered mode can upload them a second time a frame later without
// copying.
#pragma once

#include <clipstream/renderer/clipmap.h>
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/page_table.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

namespace clipstream {

// How stack tiles reach the texture the shader samples.
enum class Buffering {
  kSingle,             // one set of layers: upload straight into what is sampled
  kDoubleUploadTwice,  // two sets; a tile goes to the back set, and again a frame later
  kDoubleCopy,         // two sets; the second copy is glCopyImageSubData on the GPU
  // One set of layers; only the bytes being replaced are double-buffered:
  // each frame's tiles are written into its own region of a ring of
  // kStagingFrames pixel-unpack regions, and the texture takes them by a
  // copy the GPU runs after the frames already queued (which read the old
  // tiles). Two usable maps, alternating. The memory of `single`.
  kStaged,
};
// The default everywhere (renderer, Flight, clipstream-fly): staged keeps
// what double buffering is for (no write to memory a queued frame reads, no
// CPU wait) at the memory of one set, and measured at least as fast as
// double-upload on llvmpipe (docs/decisions.md D231).
inline constexpr Buffering kDefaultBuffering = Buffering::kStaged;
const char* bufferingName(Buffering buffering);
// The inverse of bufferingName(): "single", "double-upload", "double-copy"
// or "staged". kInvalidArgument naming the choices otherwise.
Status bufferingFromName(const std::string& name, Buffering* out);

// Where the colour tiles live on the GPU.
enum class TextureMemory {
  // Every stack level's whole window, toroidally, in one array layer per
  // level (the classic clipmap): memory follows the clip size, whatever
  // the frame samples.
  kStack,
  // One fixed pool of pages shared by all levels, each page a tile with a
  // border; a tile gets a page when the frame samples it, the least
  // recently used page is reused, and per-level indirection maps name each
  // window slot's page. Memory is the pool's; a view that needs more pages
  // than the pool has is drawn from coarser levels where it falls short.
  kPaged,
};
const char* textureMemoryName(TextureMemory memory);
// "stack" or "paged"; kInvalidArgument naming the choices otherwise.
Status textureMemoryFromName(const std::string& name, TextureMemory* out);
// The mode a program takes when the user does not choose (--texture-memory
// auto, the default of clipstream-fly and clipstream-view): kPaged, whose
// memory follows the screen, unless the frames draw terrain or double-
// buffer the stack, which kPaged does not do yet; then kStack
// (docs/decisions.md D224).
TextureMemory automaticTextureMemory(bool terrain, Buffering buffering);
// A program's --texture-memory: "auto" (automaticTextureMemory() of the
// frames' terrain and buffering), "stack" or "paged"; kInvalidArgument
// naming the three otherwise, or when `pool_given` (--pool-mb) but the
// choice is not paged (saying why auto chose the stack).
Status textureMemoryFromChoice(const std::string& name, bool terrain, Buffering buffering, bool pool_given,
                               TextureMemory* out);

// The planner settings `memory` needs: kPaged pins the pyramid in its pool,
// so it asks for a small one (PlannerConfig::pyramid_tiles, when 0, set to
// renderer_config::kPagedPyramidTiles); kStack takes `planner` as it is.
PlannerConfig plannerFor(TextureMemory memory, PlannerConfig planner);
// kPaged's pool for a viewport when the caller does not size it:
// renderer_config::kDefaultPoolPagesPerScreenTile pages per tile-sized area
// of the screen, at least kPoolMinPages, in bytes of `content` pages.
uint64_t defaultPoolBytes(const Viewport& viewport, uint32_t tile_px, TileContent content);
// Bytes of one kPaged page (mip 0 and mip 1) for tiles of `tile_px` holding
// `content` (kRgba8 or kBc1), borders included.
uint64_t pageBytes(uint32_t tile_px, TileContent content);

enum class Overlay { kOff = 0, kLevels = 1 };

struct RendererConfig {
  uint32_t clip_tiles = 0;     // from the plan (ClipmapPlan::clip_tiles)
  uint32_t pyramid_level = 0;  // from the plan (ClipmapPlan::pyramid_level)
  Buffering buffering = kDefaultBuffering;
  // What uploadTile() is given and the stack array holds: kRgba8 (GL_RGBA8)
  // or kBc1 (COMPRESSED_RGB_S3TC_DXT1_EXT, an eighth of the bytes, sampled
  // by the same shader). The source's content(): see createClipmapRenderer().
  TileContent tile_content = TileContent::kRgba8;
  // kStaged: tiles a frame can stage (its region of the ring); more go
  // straight from client memory. The flight's upload budget.
  uint32_t staging_tiles = renderer_config::kDefaultUploadTilesPerFrame;
  TextureMemory texture_memory = TextureMemory::kStack;
  // kPaged: the pool's size (pages of tile_px + 2 borders, with mip 1);
  // 0 = defaultPoolBytes() of 1920x1080 (createClipmapRenderer() sizes it to
  // the viewport: defaultPoolBytes()). At most GL_MAX_ARRAY_TEXTURE_LAYERS
  // pages. The plan's pyramid must fit in it (PlannerConfig::pyramid_tiles =
  // renderer_config::kPagedPyramidTiles keeps it to a few pages).
  uint64_t pool_bytes = 0;
};

// Video memory the renderer allocated, computed from its textures' sizes,
// formats and mip chains (every set counted). The colour clip stack is
// stack + usable.
struct TextureBytes {
  uint64_t stack = 0;    // the stack array(s): every layer, every mip (kPaged: the pool)
  uint64_t usable = 0;   // the usable map(s) (kPaged: the indirection maps)
  uint64_t staging = 0;  // kStaged: the pixel-unpack ring
  uint64_t total() const { return stack + usable + staging; }
};

struct UploadStats {
  uint32_t tiles = 0;          // new tiles this frame (stack and pyramid)
  uint32_t second_copies = 0;  // tiles re-uploaded / copied into the other set
  uint32_t unstaged = 0;       // kStaged: stack tiles past the frame's region, sent directly
  double upload_ms = 0.0;      // wall time of all of the frame's texture work below
  double coarser_mips_ms = 0.0;  // mip-1 copies (level L + 1 under level L's window)
  double usable_ms = 0.0;      // usable map: compute and upload
  // kPaged: pages given this frame, and tiles the frame samples that got
  // no page because every page was pinned or in use (drawn coarser).
  uint32_t pages_filled = 0;
  uint32_t pages_short = 0;
  // kPaged: the pages this frame needs: its sampled tiles' (with a page or
  // short of one) and the pinned ones. Its maximum over a flight is the
  // working set a pool must hold to never fall short.
  uint32_t pages_wanted = 0;
};

class ClipmapRenderer {
 public:
  // Compiles the shaders and allocates the textures: the stack array (one
  // or two sets of pyramid_level + 1 layers of slots^2 tiles, where slots is
  // clip_tiles rounded down to even plus 2; layer L < pyramid_level holds
  // level L in mip 0 and level L + 1 over the same ground in mip 1; layer
  // pyramid_level holds the whole coarse pyramid as its mip chain) and the
  // usable map. kInvalidArgument for a zero clip, a pyramid level outside
  // the geometry, a tile content that is not colour, or BC1 with a tile size
  // that is not a multiple of 4; kUnavailable if GL fails (with the shader
  // log) or lacks EXT_texture_compression_s3tc for BC1.
  static Status create(const PyramidGeometry& geometry, const RendererConfig& config,
                       std::unique_ptr<ClipmapRenderer>* out);
  ~ClipmapRenderer();
  ClipmapRenderer(const ClipmapRenderer&) = delete;
  ClipmapRenderer& operator=(const ClipmapRenderer&) = delete;

  // Frame protocol: beginFrame(), any number of uploadTile(), then
  // setResidency()/setMaxTextureLod(), endUploads(), draw(). beginFrame()
  // brings the back set up to date with the front (double-buffered modes).
  void beginFrame();

  // Uploads one tile of the configured content: RGBA8 (tile_px^2 * 4
  // bytes) or BC1 blocks (bc1TileBytes(tile_px)); other sizes, and keys
  // outside the pyramid, are ignored. Stack levels go to the slot toroidalSlot() names; levels at or
  // above pyramid_level go to the pyramid layer's mip chain, in every set,
  // once (a pyramid tile already loaded is skipped).
  void uploadTile(const TileKey& key, std::shared_ptr<const std::vector<uint8_t>> rgba);

  // Windows and resident flags of the stack levels after this frame's
  // uploads (FrameHandoff::residency). Turned into the usable map.
  void setResidency(const std::vector<LevelResidency>& residency);
  void setMaxTextureLod(uint32_t level) { m_max_texture_lod = level; }

  // Publishes the frame's uploads: writes the usable map and, when
  // double-buffered and anything changed, swaps the sets.
  void endUploads();

  // All of the above for one streamer handoff.
  void applyHandoff(const FrameHandoff& handoff);

  // Draws the ground seen by `camera` into the bound framebuffer (whole
  // viewport; the caller clears it to kSkyRgba first or uses clearSky()).
  void draw(const Camera& camera, const Viewport& viewport);
  static void clearSky();

  // Binds the colour stack and usable map (texture units 0 and 1) and sets
  // the sampling uniforms of ground_clipmap.frag on `program` for this
  // camera: what draw() does before its triangle, for programs that draw
  // other geometry with the same fragment shader (TerrainRenderer).
  void bindColour(uint32_t program, const Camera& camera, const Viewport& viewport) const;

  void setOverlay(Overlay overlay) { m_overlay = overlay; }
  Overlay overlay() const { return m_overlay; }

  // Test hook: puts every stack tile `bias` slots off its true slot
  // (toroidalSlot(x + bias)), a deliberately wrong toroidal offset.
  void setTestSlotBias(int64_t bias) { m_test_slot_bias = bias; }

  // Loads the coarse pyramid: every tile of every level >= pyramid_level,
  // each asked of `tile` once (nullptr = the tile cannot be had: damaged or
  // missing). A tile `tile` cannot give is filled from its ancestor, so the
  // pyramid, the fallback of every other level, has no hole (see
  // fillMissingPyramidTiles()). Call between beginFrame() and endUploads().
  // Returns the number of tiles `tile` could not give.
  using PyramidTileFn =
      std::function<std::shared_ptr<const std::vector<uint8_t>>(const TileKey& key)>;
  uint32_t loadPyramid(const PyramidTileFn& tile);


  const UsableMap& usableMap() const { return m_front_map; }
  const UploadStats& lastUploads() const { return m_stats; }
  const PyramidGeometry& geometry() const { return m_geometry; }
  const TextureBytes& textureBytes() const { return m_texture_bytes; }
  TileContent tileContent() const { return m_config.tile_content; }
  TextureMemory textureMemory() const { return m_config.texture_memory; }
  // kPaged: the pool's pages, and those holding a tile now. 0 in kStack.
  uint32_t poolPages() const { return m_pages ? m_pages->pages() : 0; }
  uint32_t poolPagesUsed() const { return m_pages ? m_pages->used() : 0; }
  // The #defines every program that samples the colour with
  // ground_clipmap.frag needs for this renderer (bindColour()).
  std::string shaderDefines() const;

 private:
  // Fills every pyramid tile that was never uploaded: the tile is
  // magnified from its parent (bilinear GPU blit, coarse levels first, so a
  // filled parent serves its children); a tile with no parent in the chain
  // is averaged down from its children, or else cleared to mid grey. Filled
  // tiles count as uploaded (a later upload of the tile is skipped).
  // Returns the number of tiles filled.
  uint32_t fillMissingPyramidTiles();
  ClipmapRenderer() = default;
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
  std::vector<uint8_t> readPyramidRegion(uint32_t mip, uint32_t x, uint32_t y, uint32_t w,
                                         uint32_t h) const;
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
  // Stack arrays and usable maps: two of each when double-buffered; staged
  // keeps one stack and two usable maps.
  uint32_t stackSets() const {
    return m_config.buffering == Buffering::kDoubleUploadTwice || m_config.buffering == Buffering::kDoubleCopy
               ? 2
               : 1;
  }
  uint32_t usableSets() const { return m_config.buffering == Buffering::kSingle ? 1 : 2; }
  bool staged() const { return m_config.buffering == Buffering::kStaged; }
  // kStaged: copies `pixels` into this frame's staging region and returns
  // its offset in the buffer, or -1 when the region is full.
  int64_t stage(const uint8_t* pixels, size_t bytes);
  // Unpack state for one tile's upload; kStaged: stages `pixels` and binds
  // the ring, returning the offset to pass instead (unbind after the call).
  const uint8_t* beginTileUpload(const uint8_t* pixels);
  // kStaged: the ring, persistently mapped (m_staging*).
  Status createStaging();
  uint32_t slot(int64_t tile, uint32_t period) const {
    return toroidalSlot(tile + m_test_slot_bias, period);
  }

  PyramidGeometry m_geometry;
  RendererConfig m_config;
  uint32_t m_slots = 0;  // slot period: clip_tiles rounded down to even, plus 2 (see create())
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
  int64_t m_test_slot_bias = 0;
  std::vector<uint8_t> m_pyramid_have;  // per pyramid tile, 1 = uploaded
  std::vector<size_t> m_pyramid_first;  // index of each pyramid level's first tile
  uint32_t m_pyramid_missing = 0;
  TextureBytes m_texture_bytes;
  // kStaged: the ring (kStagingFrames regions of staging_tiles tiles),
  // persistently mapped, and per region the fence of the last frame that
  // wrote it.
  uint32_t m_staging = 0;
  uint8_t* m_staging_map = nullptr;
  size_t m_staging_region_bytes = 0;
  uint32_t m_staging_region = 0;
  size_t m_staging_used = 0;
  void* m_staging_fence[renderer_config::kStagingFrames] = {};
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

// An offscreen framebuffer: RGBA8 colour + 24-bit depth, with readback.
// Owned by the GL thread.
class OffscreenTarget {
 public:
  // kUnavailable if the framebuffer is incomplete.
  static Status create(const Viewport& viewport, std::unique_ptr<OffscreenTarget>* out);
  ~OffscreenTarget();
  OffscreenTarget(const OffscreenTarget&) = delete;
  OffscreenTarget& operator=(const OffscreenTarget&) = delete;

  void bind() const;  // binds the FBO for drawing and sets the GL viewport
  // Reads the colour buffer as RGBA8, top row first (waits for the GPU).
  void readRgba(std::vector<uint8_t>* rgba) const;
  const Viewport& viewport() const { return m_viewport; }

 private:
  OffscreenTarget() = default;
  Viewport m_viewport;
  uint32_t m_fbo = 0, m_color = 0, m_depth = 0;
};

// Binds the window's default framebuffer and sets the GL viewport to it.
// GL thread only.
void bindWindowFramebuffer(const Viewport& framebuffer);

}  // namespace clipstream
