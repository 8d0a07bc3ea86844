// The clipmap on the GPU and the ground it draws.
//
// Owned by the GL thread: every method must be called on the thread whose
// context was current at create(). Tile pixels are shared_ptr-held so the
// double-buffered mode can upload them a second time a frame later without
// copying.
#pragma once

#include <clipstream/renderer/clipmap.h>
#include <clipstream/renderer/config.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
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
// The mode's word in reports and messages ("single", "double-upload",
// "double-copy", "staged"); programs parse it with cli::parseBuffering().
const char* bufferingName(Buffering buffering);

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
// "stack" or "paged", in reports; programs parse --texture-memory with
// cli::parseTextureMemory().
const char* textureMemoryName(TextureMemory memory);
// The mode a program takes when the user does not choose (--texture-memory
// auto, the default of clipstream-fly and clipstream-view): kPaged, whose
// memory follows the screen, unless the frames draw terrain or double-
// buffer the stack, which kPaged does not do yet; then kStack
// (docs/decisions.md D224).
TextureMemory automaticTextureMemory(bool terrain, Buffering buffering);

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
  void setMaxTextureLod(uint32_t level);

  // Publishes the frame's uploads: writes the usable map and, when
  // double-buffered and anything changed, swaps the sets.
  void endUploads();

  // All of the above for one streamer handoff.
  void applyHandoff(const FrameHandoff& handoff);

  // Draws the ground seen by `camera` into the bound framebuffer (whole
  // viewport; the caller clears it to kSkyRgba first or uses clearSky()).
  void draw(const Camera& camera, const Viewport& viewport);
  static void clearSky();

  void setOverlay(Overlay overlay);
  Overlay overlay() const;

  // Loads the coarse pyramid: every tile of every level >= pyramid_level,
  // each asked of `tile` once (nullptr = the tile cannot be had: damaged or
  // missing). A tile `tile` cannot give is filled from its ancestor, so the
  // pyramid, the fallback of every other level, has no hole. Call between
  // beginFrame() and endUploads(). Returns the number of tiles `tile` could
  // not give.
  using PyramidTileFn =
      std::function<std::shared_ptr<const std::vector<uint8_t>>(const TileKey& key)>;
  uint32_t loadPyramid(const PyramidTileFn& tile);

  const UsableMap& usableMap() const;
  const UploadStats& lastUploads() const;
  const PyramidGeometry& geometry() const;
  const TextureBytes& textureBytes() const;
  TileContent tileContent() const;
  TextureMemory textureMemory() const;
  // kPaged: the pool's pages, and those holding a tile now. 0 in kStack.
  uint32_t poolPages() const;
  uint32_t poolPagesUsed() const;

  // The implementation, for the library's own use: its definition is not
  // installed.
  struct Impl;
  Impl& impl() { return *m_impl; }
  const Impl& impl() const { return *m_impl; }

 private:
  ClipmapRenderer();
  std::unique_ptr<Impl> m_impl;
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
