// TileStoreWriter: payloads of level 0 go straight into the temporary
// output after the header; coarser levels are spilled to one temporary file
// per level and appended at finish(), so the file is laid out level by level
// without holding payloads in RAM. Index pages are serialised to their own
// temporary file as soon as every tile of the page has been written, so RAM
// holds entries only for pages still being filled.
//
// PayloadOrder::kCurve: level 0 spills too, and finish() copies each level's
// payloads into the output along a Hilbert curve over the level's tile grid.
// The curve covers each index page (an aligned square of 64 x 64 tiles) in
// one stretch, so the copy goes page by page, rewriting each page (same
// size, new offsets and checksum) in its temporary file: one page's entries
// and one payload in RAM at a time.
#include <clipstream/util/file_io.h>
#include "format.h"

#include <clipstream/util/output_file.h>
#include <clipstream/store/tile_store.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <random>

namespace clipstream {

namespace {

// A tile's index entry while its page is being filled: the on-disk record.
using PendingEntry = format::TileEntry;

enum class PageState : uint8_t { kEmpty, kFilling, kDone, kConstant };

struct PageBuild {
  PageState state = PageState::kEmpty;
  uint32_t claimed = 0;  // tiles whose slot is taken (payload may be in flight)
  uint32_t stored = 0;   // tiles whose entry is complete
  std::unique_ptr<PendingEntry[]> entries;
  std::unique_ptr<uint64_t[]> claimed_bits;
  // Directory entry once done (offset relative to the index pages region).
  uint64_t rel_offset = 0;
  uint32_t bytes = 0;
  uint64_t constant_value = 0;
  uint64_t checksum = 0;
};

// Position of (x, y) along a Hilbert curve over a square grid of `side`
// cells (a power of two). Every aligned square of 2^k cells is one stretch
// of the curve.
uint64_t hilbertIndex(uint64_t side, uint64_t x, uint64_t y) {
  uint64_t d = 0;
  for (uint64_t s = side / 2; s > 0; s /= 2) {
    const uint64_t rx = (x & s) ? 1 : 0;
    const uint64_t ry = (y & s) ? 1 : 0;
    d += s * s * ((3 * rx) ^ ry);
    if (ry == 0) {  // rotate the quadrant so the curve stays continuous
      if (rx == 1) {
        x = side - 1 - x;
        y = side - 1 - y;
      }
      std::swap(x, y);
    }
  }
  return d;
}
static_assert((format::kPageTiles & (format::kPageTiles - 1)) == 0,
              "index pages are aligned squares of a power-of-two side, so the curve visits "
              "each page's tiles in one stretch");

struct LevelBuild {
  int fd = -1;              // level 0 shares the main output
  std::string temp_path;    // empty for level 0
  uint64_t payload_bytes = 0;
  uint32_t pages_x = 0;
  uint32_t pages_y = 0;
  std::vector<PageBuild> pages;
};

uint64_t packValue(const uint8_t* pixel, size_t bpp) {
  uint64_t value = 0;
  std::memcpy(&value, pixel, bpp);
  return value;
}

}  // namespace

struct TileStoreWriter::Impl {
  std::string path;
  // The store under its temporary name; the index and the coarser levels'
  // payloads spill to its scratch files until finish() lays them out.
  std::unique_ptr<OutputFile> output;
  std::string main_temp;  // output->tempPath(), for error messages
  std::string index_temp;
  PyramidGeometry geometry;
  WriterOptions options;
  int main_fd = -1;  // output->fd()
  int index_fd = -1;

  std::mutex mutex;  // guards everything below
  std::vector<LevelBuild> levels;
  uint64_t index_bytes = 0;
  Status failure;     // first I/O failure; later calls return it
  bool finished = false;
  std::atomic<uint64_t> bytes_written{0};
  std::atomic<uint64_t> constant_tiles{0};

  ~Impl() { removeTemps(); }

  // Closes the scratch files; destroying `output` removes every temporary
  // (after a successful commit() only the scratch files remain to remove).
  void removeTemps() {
    if (index_fd >= 0) ::close(index_fd);
    index_fd = -1;
    for (LevelBuild& level : levels) {
      if (level.fd >= 0 && !level.temp_path.empty()) ::close(level.fd);
      level.fd = -1;
    }
    main_fd = -1;
    output.reset();
  }

  // Called with the mutex held.
  Status levelFd(uint32_t level_index, int* fd) {
    LevelBuild& level = levels[level_index];
    if (level.fd < 0) {
      Status status = output->createScratch("L" + std::to_string(level_index), &level.fd,
                                            &level.temp_path);
      if (!status) return status;
    }
    *fd = level.fd;
    return okStatus();
  }

  bool curveOrder() const { return options.payload_order == PayloadOrder::kCurve; }

  uint64_t payloadBase(uint32_t level_index) const {
    // Level 0 payloads live in the main file right after the header (unless
    // they are reordered at finish()).
    return level_index == 0 && !curveOrder() ? format::kHeaderBytes : 0;
  }

  // kCurve: copies level `l`'s payloads from its spill file into the output
  // at `level_start`, page by page along the curve, and rewrites the pages.
  Status reorderLevel(uint32_t l, uint64_t level_start);

  void pageSpan(uint32_t level_index, uint32_t px, uint32_t py, uint32_t* w, uint32_t* h) const {
    const LevelInfo& info = geometry.levels[level_index];
    *w = format::pageSpan(info.tiles_x, px);
    *h = format::pageSpan(info.tiles_y, py);
  }

  // Claims the slot of one tile (mutex held). kInvalidArgument if taken.
  Status claim(const TileKey& key, PageBuild** page_out, uint32_t* slot_out) {
    LevelBuild& level = levels[key.level];
    const uint32_t px = key.x / format::kPageTiles;
    const uint32_t py = key.y / format::kPageTiles;
    PageBuild& page = level.pages[size_t(py) * level.pages_x + px];
    uint32_t w, h;
    pageSpan(key.level, px, py, &w, &h);
    if (page.state == PageState::kDone || page.state == PageState::kConstant) {
      return Status::error(ErrorCode::kInvalidArgument, format::keyText(key) + " written twice");
    }
    const uint32_t slot = (key.y % format::kPageTiles) * w + (key.x % format::kPageTiles);
    if (page.state == PageState::kEmpty) {
      const uint32_t count = w * h;
      page.entries.reset(new PendingEntry[count]);
      page.claimed_bits.reset(new uint64_t[(count + 63) / 64]());
      page.state = PageState::kFilling;
    }
    uint64_t& word = page.claimed_bits[slot / 64];
    const uint64_t bit = uint64_t(1) << (slot % 64);
    if (word & bit) {
      return Status::error(ErrorCode::kInvalidArgument, format::keyText(key) + " written twice");
    }
    word |= bit;
    ++page.claimed;
    *page_out = &page;
    *slot_out = slot;
    return okStatus();
  }

  // Records a completed entry and serialises the page once full (mutex held).
  Status store(const TileKey& key, PageBuild* page, uint32_t slot, const PendingEntry& entry) {
    page->entries[slot] = entry;
    ++page->stored;
    uint32_t w, h;
    pageSpan(key.level, key.x / format::kPageTiles, key.y / format::kPageTiles, &w, &h);
    if (page->stored == w * h) return sealPage(page, w * h);
    return okStatus();
  }

  // Writes a full page to the index temporary file, or turns it into a
  // page-level constant when every tile holds the same constant value.
  Status sealPage(PageBuild* page, uint32_t count) {
    bool all_constant = true;
    for (uint32_t i = 0; i < count && all_constant; ++i) {
      all_constant = page->entries[i].stored_bytes == 0 &&
                     page->entries[i].offset_or_value == page->entries[0].offset_or_value &&
                     flatEntry(page->entries[i]);
    }
    if (all_constant) {
      page->state = PageState::kConstant;
      page->constant_value = page->entries[0].offset_or_value;
    } else {
      std::vector<uint8_t> bytes;
      const uint64_t checksum = format::encodeIndexPage(
          std::span<const PendingEntry>(page->entries.get(), count), entryBytes(), &bytes);
      Status status = fileio::pwriteAll(index_fd, bytes.data(), bytes.size(), index_bytes,
                                        index_temp);
      if (!status) return status;
      page->state = PageState::kDone;
      page->rel_offset = index_bytes;
      page->bytes = static_cast<uint32_t>(bytes.size());
      page->checksum = checksum;
      index_bytes += bytes.size();
    }
    page->entries.reset();
    page->claimed_bits.reset();
    return okStatus();
  }

  bool elevation() const { return options.elevation.present; }
  uint32_t entryBytes() const { return format::tileEntryBytes(elevation()); }

  // The height a constant entry's value stands for (elevation stores).
  float constantHeight(uint64_t value) const {
    uint8_t pixel[8];
    std::memcpy(pixel, &value, 8);
    return float(heightOfSample(geometry.format, options.elevation, pixel));
  }

  // A constant entry a constant page may stand for: in an elevation store
  // its bounds must be its own value and its error 0 (a coarse tile may be
  // constant while the ground under it is not), since a constant page
  // records the value alone.
  bool flatEntry(const PendingEntry& entry) const {
    if (!elevation()) return true;
    const float h = constantHeight(entry.offset_or_value);
    return entry.min_height == h && entry.max_height == h && entry.error == 0.0f;
  }

  Status fail(Status status) {
    if (failure.ok()) failure = status;
    return status;
  }

  // finish() with the mutex held: checks that every tile arrived, then lays
  // the file out region by region (docs/tile-store.md section 4), the
  // header last, and commits it.
  Status finishLocked();
  // kInvalidArgument naming the first tile never written, if any.
  Status checkComplete() const;
  // Puts every level's payloads in place after the header, level by level
  // from *position (moved to their end); (*payload_offset)[l] is where
  // level l's begin.
  Status writePayloads(std::vector<uint64_t>* payload_offset, uint64_t* position);
  // Copies the index pages to *position, then writes every level's page
  // directory after them (*position moved to their end) and fills the
  // level table's entries.
  Status writeIndex(const std::vector<uint64_t>& payload_offset, uint64_t* position,
                    std::vector<format::LevelEntry>* table);
  // Fills the header's fields that come from the geometry and options (the
  // region fields are the caller's) and writes it at offset 0.
  Status writeHeader(bool geo_present, format::Header* header);
};

const char* payloadOrderName(PayloadOrder order) {
  switch (order) {
    case PayloadOrder::kWritten: return "written";
    case PayloadOrder::kCurve: return "curve";
  }
  return "unknown";
}

TileStoreWriter::TileStoreWriter() : m_impl(std::make_unique<Impl>()) {}
TileStoreWriter::~TileStoreWriter() = default;

Status TileStoreWriter::create(const std::string& path, const PyramidGeometry& geometry,
                               const WriterOptions& options,
                               std::unique_ptr<TileStoreWriter>* out) {
  if (out == nullptr) return Status::error(ErrorCode::kInvalidArgument, "null output");
  out->reset();
  if (path.empty()) return Status::error(ErrorCode::kInvalidArgument, "empty output path");
  if (geometry.tile_px < format::kMinTilePx || geometry.tile_px > format::kMaxTilePx) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "tile size " + std::to_string(geometry.tile_px) + " outside " +
                             std::to_string(format::kMinTilePx) + ".." +
                             std::to_string(format::kMaxTilePx));
  }
  PyramidGeometry expected;
  if (!makePyramidGeometry(geometry.width_px, geometry.height_px, geometry.tile_px,
                           geometry.format, &expected) ||
      expected.levels.size() != geometry.levels.size()) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "geometry is not the pyramid makePyramidGeometry() gives for " +
                             std::to_string(geometry.width_px) + "x" +
                             std::to_string(geometry.height_px));
  }
  for (size_t i = 0; i < expected.levels.size(); ++i) {
    const LevelInfo& a = expected.levels[i];
    const LevelInfo& b = geometry.levels[i];
    if (a.width_px != b.width_px || a.height_px != b.height_px || a.tiles_x != b.tiles_x ||
        a.tiles_y != b.tiles_y) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "level " + std::to_string(i) + " size differs from the pyramid rule");
    }
  }
  const StoreEncoding& encoding = options.encoding;
  if (encoding.compression != Compression::kNone && encoding.compression != Compression::kZstd) {
    return Status::error(ErrorCode::kInvalidArgument, "unknown compression");
  }
  if (encoding.compression == Compression::kZstd &&
      (encoding.zstd_level < ZSTD_minCLevel() || encoding.zstd_level > ZSTD_maxCLevel())) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "zstd level " + std::to_string(encoding.zstd_level) + " out of range");
  }
  if (encoding.predictor != Predictor::kNone && encoding.predictor != Predictor::kLeftDelta) {
    return Status::error(ErrorCode::kInvalidArgument, "unknown predictor");
  }
  if (encoding.filter != DownsampleFilter::kBox && encoding.filter != DownsampleFilter::kLanczos3 &&
      encoding.filter != DownsampleFilter::kDecimate) {
    return Status::error(ErrorCode::kInvalidArgument, "unknown downsample filter");
  }
  if (options.elevation.present ? !isHeightFormat(geometry.format)
                                 : !isColourFormat(geometry.format)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         std::string("pixel format ") + pixelFormatName(geometry.format) +
                             (options.elevation.present ? " cannot hold heights"
                                                        : " is for elevation stores only"));
  }
  if (options.elevation.present &&
      (!isValidHeightUnits(uint32_t(options.elevation.units)) ||
       !std::isfinite(options.elevation.scale) || options.elevation.scale <= 0.0 ||
       !std::isfinite(options.elevation.offset))) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "elevation scale, offset or units out of range");
  }
  if (options.geo.crs.size() > format::kMaxCrsBytes) {
    return Status::error(ErrorCode::kInvalidArgument, "CRS text longer than 1 MiB");
  }

  std::unique_ptr<TileStoreWriter> writer(new TileStoreWriter());
  Impl& impl = *writer->m_impl;
  impl.path = path;
  impl.geometry = geometry;
  impl.options = options;
  OutputOptions output_options;
  output_options.existing = options.replace ? ExistingOutput::kReplaceRegular : ExistingOutput::kRefuse;
  output_options.fsync = options.fsync;
  Status status = OutputFile::create(path, output_options, &impl.output);
  if (!status) return status;
  impl.main_temp = impl.output->tempPath();
  impl.main_fd = impl.output->fd();
  status = impl.output->createScratch("idx", &impl.index_fd, &impl.index_temp);
  if (!status) return status;
  impl.levels.resize(geometry.levels.size());
  for (size_t i = 0; i < geometry.levels.size(); ++i) {
    LevelBuild& level = impl.levels[i];
    level.pages_x = format::pagesAlong(geometry.levels[i].tiles_x);
    level.pages_y = format::pagesAlong(geometry.levels[i].tiles_y);
    level.pages.resize(size_t(level.pages_x) * level.pages_y);
  }
  if (options.payload_order != PayloadOrder::kWritten &&
      options.payload_order != PayloadOrder::kCurve) {
    return Status::error(ErrorCode::kInvalidArgument, "unknown payload order");
  }
  if (!impl.curveOrder()) impl.levels[0].fd = impl.main_fd;
  *out = std::move(writer);
  return okStatus();
}

Status TileStoreWriter::write(EncodedTile&& tile) {
  Impl& impl = *m_impl;
  const TileKey key = tile.key;
  if (!impl.geometry.contains(key)) {
    return Status::error(ErrorCode::kOutOfRange, format::keyText(key) + " is outside the pyramid");
  }
  PendingEntry entry;
  const size_t bpp = bytesPerPixel(impl.geometry.format);
  if (impl.elevation()) {
    const TileLocation& l = tile.location;
    if (!std::isfinite(l.min_height) || !std::isfinite(l.max_height) || !std::isfinite(l.error) ||
        l.min_height > l.max_height || l.error < 0.0f) {
      return Status::error(ErrorCode::kInvalidArgument,
                           format::keyText(key) + ": height bounds are not finite and ordered");
    }
    entry.min_height = l.min_height;
    entry.max_height = l.max_height;
    entry.error = l.error;
  }
  if (tile.location.constant) {
    if (!tile.payload.empty()) {
      return Status::error(ErrorCode::kInvalidArgument,
                           format::keyText(key) + ": constant tile with a payload");
    }
    entry.offset_or_value = packValue(tile.location.constant_pixel, bpp);
  } else {
    const size_t max_bytes = format::maxStoredBytes(impl.geometry.tileBytes(),
                                                    impl.options.encoding.compression);
    // Uncompressed payloads are exactly one raw tile (the reader rejects
    // any other size), so a short one is refused here, not found later.
    const bool size_ok = impl.options.encoding.compression == Compression::kNone
                             ? tile.payload.size() == impl.geometry.tileBytes()
                             : !tile.payload.empty() && tile.payload.size() <= max_bytes;
    if (!size_ok || tile.payload.size() != tile.location.stored_bytes) {
      return Status::error(ErrorCode::kInvalidArgument,
                           format::keyText(key) + ": payload size " +
                               std::to_string(tile.payload.size()) + " is invalid");
    }
    if (format::tileChecksum(tile.payload.data(), tile.payload.size()) !=
        tile.location.checksum) {
      return Status::error(ErrorCode::kInvalidArgument,
                           format::keyText(key) + ": payload does not match its checksum");
    }
    entry.stored_bytes = static_cast<uint32_t>(tile.payload.size());
    entry.checksum = tile.location.checksum;
  }

  PageBuild* page = nullptr;
  uint32_t slot = 0;
  int fd = -1;
  uint64_t file_offset = 0;
  {
    std::lock_guard<std::mutex> lock(impl.mutex);
    if (!impl.failure.ok()) return impl.failure;
    if (impl.finished) return Status::error(ErrorCode::kInvalidArgument, "write after finish");
    Status status = impl.claim(key, &page, &slot);
    if (!status) return status;
    if (tile.location.constant) {
      impl.constant_tiles.fetch_add(1, std::memory_order_relaxed);
      status = impl.store(key, page, slot, entry);
      if (!status) return impl.fail(status);
      return okStatus();
    }
    status = impl.levelFd(key.level, &fd);
    if (!status) return impl.fail(status);
    entry.offset_or_value = impl.levels[key.level].payload_bytes;
    impl.levels[key.level].payload_bytes += entry.stored_bytes;
    file_offset = impl.payloadBase(key.level) + entry.offset_or_value;
  }
  // The payload is written outside the lock: its range is reserved above.
  const std::string& file_path = impl.levels[key.level].temp_path.empty()
                                    ? impl.main_temp
                                    : impl.levels[key.level].temp_path;
  Status status = fileio::pwriteAll(fd, tile.payload.data(), tile.payload.size(), file_offset,
                                    file_path);
  std::lock_guard<std::mutex> lock(impl.mutex);
  if (!status) return impl.fail(status);
  impl.bytes_written.fetch_add(entry.stored_bytes, std::memory_order_relaxed);
  status = impl.store(key, page, slot, entry);
  if (!status) return impl.fail(status);
  return okStatus();
}

Status TileStoreWriter::writeConstantTiles(uint32_t level_index, uint32_t x0, uint32_t y0,
                                           uint32_t x1, uint32_t y1,
                                           std::span<const uint8_t> pixel) {
  Impl& impl = *m_impl;
  const size_t bpp = bytesPerPixel(impl.geometry.format);
  if (pixel.size() != bpp) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "constant pixel has " + std::to_string(pixel.size()) +
                             " bytes, the format needs " + std::to_string(bpp));
  }
  if (level_index >= impl.geometry.levels.size()) {
    return Status::error(ErrorCode::kOutOfRange, "level " + std::to_string(level_index) +
                                                     " is outside the pyramid");
  }
  const LevelInfo& info = impl.geometry.levels[level_index];
  if (x0 > x1 || y0 > y1 || x1 > info.tiles_x || y1 > info.tiles_y) {
    return Status::error(ErrorCode::kOutOfRange, "constant rectangle outside level " +
                                                     std::to_string(level_index));
  }
  PendingEntry entry;
  entry.offset_or_value = packValue(pixel.data(), bpp);
  // Constant rectangles are flat ground in an elevation store.
  if (impl.elevation()) entry.min_height = entry.max_height = impl.constantHeight(entry.offset_or_value);

  std::lock_guard<std::mutex> lock(impl.mutex);
  if (!impl.failure.ok()) return impl.failure;
  if (impl.finished) return Status::error(ErrorCode::kInvalidArgument, "write after finish");
  LevelBuild& level = impl.levels[level_index];
  const uint32_t kPage = format::kPageTiles;
  if (x0 == x1 || y0 == y1) return okStatus();
  for (uint32_t py = y0 / kPage; py <= (y1 - 1) / kPage; ++py) {
    for (uint32_t px = x0 / kPage; px <= (x1 - 1) / kPage; ++px) {
      PageBuild& page = level.pages[size_t(py) * level.pages_x + px];
      uint32_t w, h;
      impl.pageSpan(level_index, px, py, &w, &h);
      const uint32_t bx0 = px * kPage, by0 = py * kPage;
      const bool covers = x0 <= bx0 && y0 <= by0 && x1 >= bx0 + w && y1 >= by0 + h;
      if (covers && page.state == PageState::kEmpty) {
        // Whole page at once: no per-tile memory, no page on disk.
        page.state = PageState::kConstant;
        page.constant_value = entry.offset_or_value;
        impl.constant_tiles.fetch_add(uint64_t(w) * h, std::memory_order_relaxed);
        continue;
      }
      const uint32_t tx0 = std::max(x0, bx0), tx1 = std::min(x1, bx0 + w);
      const uint32_t ty0 = std::max(y0, by0), ty1 = std::min(y1, by0 + h);
      for (uint32_t ty = ty0; ty < ty1; ++ty) {
        for (uint32_t tx = tx0; tx < tx1; ++tx) {
          const TileKey key{level_index, tx, ty};
          PageBuild* claimed = nullptr;
          uint32_t slot = 0;
          Status status = impl.claim(key, &claimed, &slot);
          if (!status) return status;
          impl.constant_tiles.fetch_add(1, std::memory_order_relaxed);
          status = impl.store(key, claimed, slot, entry);
          if (!status) return impl.fail(status);
        }
      }
    }
  }
  return okStatus();
}

Status TileStoreWriter::setElevationFigures(uint64_t filled_samples, double max_error,
                                            double min_height, double max_height) {
  Impl& impl = *m_impl;
  if (!impl.elevation()) {
    return Status::error(ErrorCode::kInvalidArgument, "not an elevation store");
  }
  if (!std::isfinite(max_error) || max_error < 0.0 || !std::isfinite(min_height) ||
      !std::isfinite(max_height) || min_height > max_height) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "elevation figures are not finite and ordered");
  }
  std::lock_guard<std::mutex> lock(impl.mutex);
  ElevationInfo& e = impl.options.elevation;
  e.filled_samples = filled_samples;
  e.max_error = max_error;
  e.min_height = min_height;
  e.max_height = max_height;
  return okStatus();
}

uint64_t TileStoreWriter::bytesWritten() const {
  return m_impl->bytes_written.load(std::memory_order_relaxed);
}

const std::vector<std::string>& TileStoreWriter::sweptTemporaries() const {
  static const std::vector<std::string> kNone;
  return m_impl->output ? m_impl->output->swept() : kNone;
}

uint64_t TileStoreWriter::constantTiles() const {
  return m_impl->constant_tiles.load(std::memory_order_relaxed);
}

Status TileStoreWriter::finish() {
  Impl& impl = *m_impl;
  std::lock_guard<std::mutex> lock(impl.mutex);
  if (impl.finished) return Status::error(ErrorCode::kInvalidArgument, "finish called twice");
  impl.finished = true;
  Status status = impl.failure.ok() ? impl.finishLocked() : impl.failure;
  // Success renamed the main file away; either way no temporary remains.
  impl.removeTemps();
  return status;
}

Status TileStoreWriter::Impl::reorderLevel(uint32_t l, uint64_t level_start) {
  LevelBuild& level = levels[l];
  const LevelInfo& info = geometry.levels[l];
  uint64_t side = 1;
  while (side < info.tiles_x || side < info.tiles_y) side *= 2;
  // Pages holding payloads, in the curve's order of their first tiles
  // (16 bytes per page, for this call).
  std::vector<std::pair<uint64_t, uint32_t>> order;
  for (uint32_t i = 0; i < level.pages.size(); ++i) {
    if (level.pages[i].state != PageState::kDone) continue;
    const uint64_t x0 = uint64_t(i % level.pages_x) * format::kPageTiles;
    const uint64_t y0 = uint64_t(i / level.pages_x) * format::kPageTiles;
    order.push_back({hilbertIndex(side, x0, y0), i});
  }
  std::sort(order.begin(), order.end());
  uint64_t position = 0;  // inside the level's region
  std::vector<uint8_t> page_bytes, payload;
  std::vector<format::TileEntry> entries;
  std::vector<std::pair<uint64_t, uint32_t>> slots;  // (curve position, slot) of one page
  for (const auto& [page_curve, index] : order) {
    (void)page_curve;
    PageBuild& page = level.pages[index];
    const uint32_t px = index % level.pages_x, py = index / level.pages_x;
    uint32_t w, h;
    pageSpan(l, px, py, &w, &h);
    page_bytes.resize(page.bytes);
    Status status = fileio::preadAll(index_fd, page_bytes.data(), page_bytes.size(),
                                     page.rel_offset, index_temp);
    if (!status) return status;
    if (format::decodeIndexPage(page_bytes, page.checksum, entryBytes(), &entries) !=
        format::Decoded::kOk) {
      return Status::error(ErrorCode::kIo, index_temp + ": an index page changed on disk");
    }
    slots.clear();
    for (uint32_t slot = 0; slot < w * h; ++slot) {
      if (entries[slot].stored_bytes == 0) continue;  // constant: no payload
      const uint64_t x = uint64_t(px) * format::kPageTiles + slot % w;
      const uint64_t y = uint64_t(py) * format::kPageTiles + slot / w;
      slots.push_back({hilbertIndex(side, x, y), slot});
    }
    std::sort(slots.begin(), slots.end());
    for (const auto& [curve, slot] : slots) {
      (void)curve;
      format::TileEntry& entry = entries[slot];
      payload.resize(entry.stored_bytes);
      status = fileio::preadAll(level.fd, payload.data(), payload.size(), entry.offset_or_value,
                                level.temp_path);
      if (!status) return status;
      status = fileio::pwriteAll(main_fd, payload.data(), payload.size(), level_start + position,
                                 main_temp);
      if (!status) return status;
      entry.offset_or_value = position;
      position += entry.stored_bytes;
    }
    page.checksum = format::encodeIndexPage(entries, entryBytes(), &page_bytes);
    status = fileio::pwriteAll(index_fd, page_bytes.data(), page_bytes.size(), page.rel_offset,
                               index_temp);
    if (!status) return status;
  }
  if (position != level.payload_bytes) {
    return Status::error(ErrorCode::kIo, "level " + std::to_string(l) + ": " +
                                             std::to_string(position) + " payload bytes laid out, " +
                                             std::to_string(level.payload_bytes) + " written");
  }
  return okStatus();
}

Status TileStoreWriter::Impl::finishLocked() {
  // Every tile must be present before anything is laid out.
  Status status = checkComplete();
  if (!status) return status;
  format::Header header;  // filled in region by region, written last

  // Payload regions, level by level.
  std::vector<uint64_t> payload_offset(levels.size());
  uint64_t position = format::kHeaderBytes;
  status = writePayloads(&payload_offset, &position);
  if (!status) return status;

  // Index region: all pages, then every level's page directory.
  header.index_offset = position;
  std::vector<format::LevelEntry> table(levels.size());
  status = writeIndex(payload_offset, &position, &table);
  if (!status) return status;
  header.index_bytes = position - header.index_offset;

  // Level table.
  header.level_table_offset = position;
  const std::vector<uint8_t> table_bytes = format::encodeLevelTable(table);
  status = fileio::pwriteAll(main_fd, table_bytes.data(), table_bytes.size(), position, main_temp);
  if (!status) return status;
  header.level_table_bytes = table_bytes.size();
  position += table_bytes.size();

  // Metadata block: georeference.
  header.metadata_offset = position;
  // Without a georeference the block holds the identity transform and no
  // CRS, so stale caller values never reach the file.
  const GeoReference geo = options.geo.present ? options.geo : GeoReference{};
  const std::vector<uint8_t> metadata = format::encodeMetadata(
      geo.transform, geo.crs, elevation() ? &options.elevation : nullptr,
      options.shard.present ? &options.shard : nullptr);
  status = fileio::pwriteAll(main_fd, metadata.data(), metadata.size(), position, main_temp);
  if (!status) return status;
  header.metadata_bytes = metadata.size();
  position += metadata.size();
  header.file_bytes = position;

  // Header last: a crash before this point leaves no valid magic.
  status = writeHeader(geo.present, &header);
  if (!status) return status;

  return output->commit();
}

Status TileStoreWriter::Impl::checkComplete() const {
  for (uint32_t l = 0; l < levels.size(); ++l) {
    const LevelBuild& level = levels[l];
    for (uint32_t py = 0; py < level.pages_y; ++py) {
      for (uint32_t px = 0; px < level.pages_x; ++px) {
        const PageBuild& page = level.pages[size_t(py) * level.pages_x + px];
        if (page.state == PageState::kDone || page.state == PageState::kConstant) continue;
        uint32_t w, h;
        pageSpan(l, px, py, &w, &h);
        for (uint32_t slot = 0; slot < w * h; ++slot) {
          const bool claimed = page.state == PageState::kFilling &&
                               (page.claimed_bits[slot / 64] >> (slot % 64)) & 1;
          if (!claimed) {
            const TileKey key{l, px * format::kPageTiles + slot % w,
                              py * format::kPageTiles + slot / w};
            return Status::error(ErrorCode::kInvalidArgument,
                                 format::keyText(key) + " was never written");
          }
        }
        return Status::error(ErrorCode::kInvalidArgument,
                             "level " + std::to_string(l) + ": a tile write did not complete");
      }
    }
  }
  return okStatus();
}

Status TileStoreWriter::Impl::writePayloads(std::vector<uint64_t>* payload_offset,
                                            uint64_t* position) {
  for (uint32_t l = 0; l < levels.size(); ++l) {
    (*payload_offset)[l] = *position;
    if (levels[l].fd != main_fd && levels[l].payload_bytes > 0) {
      Status status = curveOrder() ? reorderLevel(l, *position)
                                   : fileio::copyRange(levels[l].fd, levels[l].temp_path,
                                                       levels[l].payload_bytes, main_fd, *position,
                                                       main_temp);
      if (!status) return status;
      // The spill file is no longer needed; free its disk space early.
      ::close(levels[l].fd);
      levels[l].fd = -1;
      ::unlink(levels[l].temp_path.c_str());
      levels[l].temp_path.clear();
    }
    *position += levels[l].payload_bytes;
  }
  return okStatus();
}

Status TileStoreWriter::Impl::writeIndex(const std::vector<uint64_t>& payload_offset,
                                         uint64_t* position,
                                         std::vector<format::LevelEntry>* table) {
  const uint64_t index_offset = *position;
  if (index_bytes > 0) {
    Status status = fileio::copyRange(index_fd, index_temp, index_bytes, main_fd, *position,
                                      main_temp);
    if (!status) return status;
  }
  *position += index_bytes;
  for (uint32_t l = 0; l < levels.size(); ++l) {
    const LevelBuild& level = levels[l];
    std::vector<format::PageDirEntry> entries(level.pages.size());
    for (size_t i = 0; i < level.pages.size(); ++i) {
      const PageBuild& page = level.pages[i];
      format::PageDirEntry& entry = entries[i];
      if (page.state == PageState::kConstant) {
        entry.flags = format::kPageFlagConstant;
        entry.constant_value = page.constant_value;
      } else {
        entry.offset = index_offset + page.rel_offset;
        entry.bytes = page.bytes;
        entry.checksum = page.checksum;
      }
    }
    const std::vector<uint8_t> bytes = format::encodePageDirectory(entries);
    Status status = fileio::pwriteAll(main_fd, bytes.data(), bytes.size(), *position, main_temp);
    if (!status) return status;
    const LevelInfo& info = geometry.levels[l];
    format::LevelEntry& entry = (*table)[l];
    entry.width_px = info.width_px;
    entry.height_px = info.height_px;
    entry.tiles_x = info.tiles_x;
    entry.tiles_y = info.tiles_y;
    entry.pages_x = level.pages_x;
    entry.pages_y = level.pages_y;
    entry.payload_offset = payload_offset[l];
    entry.payload_bytes = level.payload_bytes;
    entry.directory_offset = *position;
    entry.directory_bytes = bytes.size();
    *position += bytes.size();
  }
  return okStatus();
}

Status TileStoreWriter::Impl::writeHeader(bool geo_present, format::Header* header) {
  header->width_px = geometry.width_px;
  header->height_px = geometry.height_px;
  header->tile_px = geometry.tile_px;
  header->pixel_format = static_cast<uint32_t>(geometry.format);
  header->level_count = static_cast<uint32_t>(levels.size());
  const StoreEncoding& encoding = options.encoding;
  header->compression = static_cast<uint32_t>(encoding.compression);
  header->zstd_level = encoding.zstd_level;
  header->predictor = static_cast<uint32_t>(encoding.predictor);
  header->filter = static_cast<uint32_t>(encoding.filter);
  if (encoding.linear_light) header->flags |= format::kFlagLinearLight;
  if (geo_present) header->flags |= format::kFlagGeoPresent;
  if (elevation()) header->flags |= format::kFlagElevation;
  if (options.shard.present) header->flags |= format::kFlagShard;
  header->tile_entry_bytes = entryBytes();
  uint8_t bytes[format::kHeaderBytes];
  format::encodeHeader(*header, bytes);
  return fileio::pwriteAll(main_fd, bytes, sizeof(bytes), 0, main_temp);
}

}  // namespace clipstream
