// CogReader: a tiled TIFF as a pyramid of 128 x 128 tiles (cog.h).
//
// libtiff parses the directories and decodes the tiles; the bytes come from
// a ByteSource (a file, or HTTP range requests). The header, every
// directory and the tile tables are read once at open into `head` (grown
// while libtiff walks the directories, each growth one read; blocks far
// from it into `far`); afterwards both are frozen and read-only, so the libtiff handles that decode tiles on
// loader threads (a pool per directory, one thread per handle at a time)
// are opened from memory. A tile's bytes are read by one positional read
// outside any lock and decoded with TIFFReadFromUserBuffer().
#include <clipstream/store/cog.h>

#include <clipstream/store/geotiff.h>

#include "byte_source.h"
#include "cog_tiff.h"
#include "disk_cache.h"
#include "format.h"

#include <tiffio.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <future>
#include <list>
#include <map>
#include <mutex>
#include <unordered_map>
#include <vector>

namespace clipstream {

using cog::FileBytes;
using cog::ImageFields;

namespace {

// Bytes read first at open: the header and, in a COG, usually every
// directory and tile table (GDAL writes them first). More is read, doubling,
// only while libtiff asks for bytes beyond.
constexpr uint64_t kFirstHeadBytes = 64 << 10;
// Blocks read for the directories and tables that lie far from the start.
constexpr uint64_t kFarBlockBytes = 16 << 10;
// Decoded internal tiles kept for the pyramid tiles cut from them: a 512 px
// RGB tile feeds 16 pyramid tiles, which the streamer asks for one by one,
// often on other threads; without the cache each would read and decode it
// again. 64 MiB holds 64 such tiles (two screens of the finest level at
// 1080p); at least four tiles are kept whatever their size.
constexpr uint64_t kDecodedCacheBytes = 64ull << 20;
constexpr size_t kDecodedCacheMinTiles = 4;
// Largest side of the coarsest level a COG stores for the levels above it
// to be built (docs/decisions.md D294): building the single top tile reads
// the whole of that level, so a file without overviews larger than this is
// refused with the command that adds them rather than read whole.
constexpr uint64_t kMaxBuildFromPx = 4096;
constexpr uint32_t kMaxDirectories = 64;
// Levels missing in a row between two the file holds that are refused
// (finishLayout()): 3 would cost 64 stored tiles per built tile.
constexpr size_t kMaxMissingLevelsInARow = 3;
// The head grows at most to this (a COG's directories and tile tables lie
// together first: a 2^20-tile image's tables are 16 MiB); anything further
// is read in blocks into `far`. Opening reads at most kMaxOpenBytes in all.
constexpr uint64_t kMaxHeadBytes = 16 << 20;
constexpr uint64_t kMaxOpenBytes = 256 << 20;

using Pixels = std::shared_ptr<const std::vector<uint8_t>>;

// One image directory the pyramid reads from.
struct Directory {
  uint16_t index = 0;  // in the file
  uint32_t width = 0, height = 0;
  uint32_t tile_px = 0;       // its internal tile side (overviews may differ from the full image)
  bool ycbcr_jpeg = false;    // JPEG of YCbCr samples, decoded as RGB (JPEGCOLORMODE)
  size_t decoded_bytes = 0;   // one decoded internal tile
  uint32_t tiles_across = 0, tiles_down = 0;
  std::vector<uint64_t> offsets, counts;  // per internal tile, row by row
};

struct Level {
  int directory = -1;  // index into Impl::directories; -1: built from the level below
};

}  // namespace

struct CogReader::Impl final : FileBytes {
  std::string path;  // as given (a URL keys the disk cache)
  std::string name;  // for messages (displayStorePath())
  RemoteOptions remote;
  std::unique_ptr<ByteSource> source;
  StoreInfo info;
  CogLayout layout;
  std::vector<uint8_t> head;  // file bytes [0, head.size()); frozen after open
  bool growing = true;        // open() may still extend head and far
  std::map<uint64_t, std::vector<uint8_t>> far;  // kFarBlockBytes blocks read while opening, by index
  Status head_status;         // the first failed read while growing
  std::vector<Directory> directories;
  std::vector<Level> levels;
  uint32_t tile_px = 0;      // the full image's internal tile side
  uint32_t coarsest_stored = 0;  // the coarsest pyramid level the file holds
  uint16_t samples = 0;      // per pixel, as decoded
  uint16_t bits = 8;
  uint16_t compression = COMPRESSION_NONE;
  bool grey_alpha = false;   // two samples, widened to RGBA8
  // GDAL's no-data value of an 8-bit grey or RGB file, as the tiler takes
  // it (docs/decisions.md D293): RGBA8, a pixel whose every sample is
  // `nodata` becomes (0, 0, 0, 0), every other one opaque.
  bool nodata_alpha = false;
  uint8_t nodata = 0;

  mutable std::atomic<uint64_t> bytes_read{0};
  // Disk cache of a URL (RemoteOptions::disk_cache_dir), or null.
  std::shared_ptr<DiskCache> disk_cache;
  std::string cache_key;
  mutable DiskCache::Counts disk_counts;

  // Idle libtiff handles per directory.
  mutable std::mutex handles_mutex;
  mutable std::vector<std::vector<TIFF*>> idle_handles;

  // Decoded internal tiles, least recently used first out; a tile being
  // decoded is there as an unfinished future, so a second thread waits for
  // it instead of reading it again.
  struct Decoded {
    Status status;
    Pixels pixels;
  };
  struct CacheEntry {
    std::shared_future<Decoded> result;
    std::list<uint64_t>::iterator lru;
  };
  mutable std::mutex cache_mutex;
  mutable std::list<uint64_t> lru;  // most recent first
  mutable std::unordered_map<uint64_t, CacheEntry> decoded;
  // Built tiles of the levels above the coarsest the file holds, kept:
  // they are few.
  mutable std::mutex built_mutex;
  mutable std::unordered_map<TileKey, Pixels, TileKeyHash> built;

  ~Impl() {
    for (auto& list : idle_handles)
      for (TIFF* tif : list) TIFFClose(tif);
  }

  Status readSource(void* data, size_t bytes, uint64_t offset) const {
    bytes_read.fetch_add(bytes, std::memory_order_relaxed);
    return source->read(data, bytes, offset);
  }

  uint64_t fileSize() const override { return source->size(); }

  // Bytes for libtiff. While the file is opened, a read near the end of
  // `head` grows it (doubling, one read each time: a COG's directories and
  // tile tables lie together at the start); a read far beyond it (a TIFF
  // that keeps its directories at the end, as libtiff writes them) reads
  // the aligned blocks around it into `far`, so the file is never read
  // whole. Afterwards head and far are read-only: later libtiff handles
  // open from them, and anything else comes from the source.
  size_t readHead(uint64_t offset, void* dst, size_t n) override {
    const uint64_t size = source->size();
    if (offset >= size) return 0;
    n = size_t(std::min<uint64_t>(n, size - offset));
    if (offset + n > head.size() && growing && offset <= 2 * uint64_t(head.size()) &&
        offset + n <= kMaxHeadBytes) {
      const uint64_t want = std::min({size, kMaxHeadBytes, std::max<uint64_t>(offset + n, 2 * head.size())});
      const size_t old = head.size();
      if (!mayReadAtOpen(want - old)) return 0;
      head.resize(size_t(want));
      if (Status s = readSource(head.data() + old, head.size() - old, old); !s) {
        head.resize(old);
        if (head_status) head_status = s;
        return 0;
      }
      layout.header_bytes += head.size() - old;
    }
    if (offset + n <= head.size()) {
      std::memcpy(dst, head.data() + offset, n);
      return n;
    }
    // Block by block from `far`; while opening, the blocks missing from
    // the first one missing to the last asked for come in one read.
    const uint64_t first = offset / kFarBlockBytes, last = (offset + n - 1) / kFarBlockBytes;
    if (growing) {
      uint64_t from = first;
      while (from <= last && far.count(from) != 0) ++from;
      if (from <= last) {
        const uint64_t begin = from * kFarBlockBytes, end = std::min(size, (last + 1) * kFarBlockBytes);
        if (!mayReadAtOpen(end - begin)) return 0;
        std::vector<uint8_t> bytes(size_t(end - begin));
        if (Status s = readSource(bytes.data(), bytes.size(), begin); !s) {
          if (head_status) head_status = s;
          return 0;
        }
        layout.header_bytes += bytes.size();
        for (uint64_t b = from; b <= last; ++b) {
          const size_t at = size_t((b - from) * kFarBlockBytes);
          far.emplace(b, std::vector<uint8_t>(bytes.begin() + at, bytes.begin() + std::min(bytes.size(), at + kFarBlockBytes)));
        }
      }
    }
    uint8_t* out = static_cast<uint8_t*>(dst);
    size_t done = 0;
    while (done < n) {
      const uint64_t at = offset + done;
      const auto it = far.find(at / kFarBlockBytes);
      if (it == far.end()) break;
      const size_t within = size_t(at - it->first * kFarBlockBytes);
      if (within >= it->second.size()) break;
      const size_t take = std::min(n - done, it->second.size() - within);
      std::memcpy(out + done, it->second.data() + within, take);
      done += take;
    }
    if (done == n || growing) return done;
    return readSource(out + done, n - done, offset + done) ? n : done;
  }

  // Whether opening may read `bytes` more (kMaxOpenBytes in all); records
  // why not in head_status.
  bool mayReadAtOpen(uint64_t bytes) {
    if (layout.header_bytes + bytes <= kMaxOpenBytes) return true;
    if (head_status)
      head_status = Status::error(ErrorCode::kUnsupported,
                                  name + ": its directories and tile tables take more than " +
                                      std::to_string(kMaxOpenBytes >> 20) + " MiB to read");
    return false;
  }

  Status openImpl();
  Status readDirectories(TIFF* tif);
  Status acceptFullImage(const ImageFields& f);
  Status readTileTable(TIFF* tif, uint16_t d, const ImageFields& f, Directory* dir);
  Status finishLayout();
  Status openHandle(const Directory& dir, TIFF** out, std::string* error) const;
  Status internalTile(size_t directory, uint32_t cx, uint32_t cy, Pixels* out, uint64_t* bytes_read) const;
  Status decodeInternal(size_t directory, uint32_t cx, uint32_t cy, Pixels* out, uint64_t* bytes_read) const;
  Status rawTile(size_t directory, uint32_t cx, uint32_t cy, std::vector<uint8_t>* out, uint64_t* bytes_read) const;
  Status cutTile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* bytes_read) const;
  Status buildTile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* bytes_read) const;
  Status tile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* bytes_read) const;
};

namespace {

uint64_t cacheId(size_t directory, uint32_t cx, uint32_t cy) {
  return (uint64_t(directory) << 56) | (uint64_t(cy) << 28) | uint64_t(cx);
}

// Fills the texels of a pyramid tile beyond [0, valid_w) x [0, valid_h)
// with the nearest texel inside (the stores' clamp-to-edge padding).
void clampEdges(std::span<uint8_t> tile, uint32_t tile_px, uint32_t bpp, uint32_t valid_w, uint32_t valid_h) {
  const size_t row = size_t(tile_px) * bpp;
  for (uint32_t y = 0; y < valid_h; ++y) {
    uint8_t* r = tile.data() + y * row;
    for (uint32_t x = valid_w; x < tile_px; ++x) std::memcpy(r + x * bpp, r + (valid_w - 1) * bpp, bpp);
  }
  for (uint32_t y = valid_h; y < tile_px; ++y)
    std::memcpy(tile.data() + y * row, tile.data() + (valid_h - 1) * row, row);
}

}  // namespace

Status CogReader::Impl::openImpl() {
  name = displayStorePath(path);
  Status opened = isStoreUrl(path) ? openHttpSource(path, remote, &source) : openFileSource(path, &source);
  if (!opened) return opened;
  const uint64_t size = source->size();
  head.resize(size_t(std::min<uint64_t>(size, kFirstHeadBytes)));
  if (Status s = readSource(head.data(), head.size(), 0); !s) return s;
  layout.header_bytes = head.size();
  const bool tiff = head.size() >= 8 && ((head[0] == 'I' && head[1] == 'I' && (head[2] == 42 || head[2] == 43) && head[3] == 0) ||
                                         (head[0] == 'M' && head[1] == 'M' && head[2] == 0 && (head[3] == 42 || head[3] == 43)));
  if (!tiff) return Status::error(ErrorCode::kBadMagic, name + ": not a TIFF (bad magic)");

  std::string error;
  TIFF* tif = cog::openClient(this, name, &error);
  if (tif == nullptr) {
    if (!head_status) return head_status;
    return Status::error(ErrorCode::kBadHeader, name + ": not a readable TIFF: " + error);
  }
  Status status = readDirectories(tif);
  if (!head_status) status = head_status;  // a failed read, not the damage it looked like
  TIFFClose(tif);
  if (!status) return status;

  // The georeference, from the first directory's GeoTIFF tags.
  const TiffByteReader read = [this](uint64_t offset, void* dst, size_t n) { return readHead(offset, dst, n) == n; };
  ElevationTags tags;
  if (Status s = parseGeoTiffTags(name, size, read, &info.geo, &tags); !s) return head_status ? s : head_status;
  if (tags.has_nodata && bits == 8 && (samples == 1 || samples == 3) && tags.nodata >= 0.0 && tags.nodata <= 255.0 &&
      tags.nodata == std::floor(tags.nodata)) {
    nodata_alpha = true;
    nodata = uint8_t(tags.nodata);
    info.geometry.format = PixelFormat::kRGBA8;
  }
  growing = false;  // head is read-only from here on: loader threads share it
  info.file_bytes = size;

  if (!remote.disk_cache_dir.empty() && isStoreUrl(path) && !source->version().empty()) {
    if (Status s = DiskCache::open(remote.disk_cache_dir, remote.disk_cache_bytes, &disk_cache); !s) return s;
    cache_key = DiskCache::storeKey(path, source->version());
    disk_counts.folder_refused = !disk_cache->usableStoreDir(cache_key);
  }
  idle_handles.resize(directories.size());
  return okStatus();
}

Status CogReader::Impl::acceptFullImage(const ImageFields& f) {
  if (const std::string why = cog::refusalOf(f); !why.empty())
    return Status::error(ErrorCode::kUnsupported, name + ": " + why);
  samples = f.samples;
  bits = f.bits;
  compression = f.compression;
  grey_alpha = f.samples == 2;
  tile_px = f.tile_w;
  const PixelFormat pf = f.bits == 16      ? PixelFormat::kR16
                         : f.samples == 1  ? PixelFormat::kR8
                         : f.samples == 3  ? PixelFormat::kRGB8
                                           : PixelFormat::kRGBA8;
  if (!makePyramidGeometry(f.width, f.height, kCogPyramidTilePx, pf, &info.geometry))
    return Status::error(ErrorCode::kBadHeader, name + ": image of " + std::to_string(f.width) + " x " +
                                                    std::to_string(f.height) + " px");
  levels.assign(info.geometry.levelCount(), Level{});
  return okStatus();
}

Status CogReader::Impl::readTileTable(TIFF* tif, uint16_t d, const ImageFields& f, Directory* dir) {
  auto damaged = [&](const std::string& what) {
    const std::string why = cog::lastError(tif);
    return Status::error(ErrorCode::kBadHeader, name + ": directory " + std::to_string(d) + what +
                                                    (why.empty() ? "" : ": " + why));
  };
  dir->index = d;
  dir->width = f.width;
  dir->height = f.height;
  dir->tile_px = f.tile_w;
  dir->ycbcr_jpeg = f.photometric == PHOTOMETRIC_YCBCR && f.compression == COMPRESSION_JPEG;
  dir->decoded_bytes = size_t(f.tile_w) * f.tile_w * samples * (bits / 8);
  const uint64_t across = (uint64_t(f.width) + f.tile_w - 1) / f.tile_w;
  const uint64_t down = (uint64_t(f.height) + f.tile_w - 1) / f.tile_w;
  dir->tiles_across = uint32_t(across);
  dir->tiles_down = uint32_t(down);
  const uint64_t count = across * down;
  if (count == 0 || count != TIFFNumberOfTiles(tif)) return damaged("'s tile count");
  // Each tile has an offset and a byte count of at least 4 bytes each in
  // the file: a size claiming more tiles than that is a lie.
  if (count > 1 && count > source->size() / 8)
    return damaged(" claims " + std::to_string(count) + " tiles, more than the file has room to list");
  dir->offsets.resize(count);
  dir->counts.resize(count);
  for (uint64_t t = 0; t < count; ++t) {
    int err = 0;
    dir->offsets[t] = TIFFGetStrileOffsetWithErr(tif, uint32_t(t), &err);
    if (err == 0) dir->counts[t] = TIFFGetStrileByteCountWithErr(tif, uint32_t(t), &err);
    if (err != 0) return damaged("'s tile table");
    if (dir->counts[t] > 0 && (dir->offsets[t] > source->size() || dir->counts[t] > source->size() - dir->offsets[t]))
      return Status::error(ErrorCode::kTruncated, name + ": tile " + std::to_string(t) + " of directory " +
                                                      std::to_string(d) + " lies past the end of the file");
    if (dir->counts[t] > (uint64_t(64) << 20)) return damaged(" has a tile of " + std::to_string(dir->counts[t]) + " bytes");
  }
  return okStatus();
}

Status CogReader::Impl::readDirectories(TIFF* tif) {
  for (uint16_t d = 0;; ++d) {
    if (d >= kMaxDirectories)
      return Status::error(ErrorCode::kUnsupported,
                           name + ": more than " + std::to_string(kMaxDirectories) + " image directories");
    cog::clearError(tif);  // a message below is this directory's
    const ImageFields f = cog::readFields(tif);
    layout.directories = d + 1u;
    if (f.width == 0 || f.height == 0)
      return Status::error(ErrorCode::kBadHeader, name + ": directory " + std::to_string(d) + " has no image size");
    if (d == 0 && (f.subfile & FILETYPE_REDUCEDIMAGE) != 0)
      return Status::error(ErrorCode::kBadHeader, name + ": the first directory is an overview");
    const bool image = (f.subfile & FILETYPE_MASK) == 0 && (d == 0 || (f.subfile & FILETYPE_REDUCEDIMAGE) != 0);
    if (d == 0 && !TIFFIsTiled(tif))
      return Status::error(ErrorCode::kUnsupported,
                           name + ": a striped TIFF, not tiled: make a COG of it (gdal_translate -of COG IN "
                                  "OUT.tif) or tile it (clipstream-tile IN OUT.cstore)");
    if (d == 0)
      if (Status s = acceptFullImage(f); !s) return s;
    // An overview is used when it can be read like the full image (its own
    // tile size and codec allowed: each directory decodes with its own);
    // one that cannot (striped, other samples) is skipped and its level built.
    const bool usable = TIFFIsTiled(tif) && f.samples == samples && f.bits == bits && cog::refusalOf(f).empty();
    if (image && usable) {
      // Which pyramid level it is: the one of its size.
      for (size_t l = 0; l < levels.size(); ++l) {
        const LevelInfo& li = info.geometry.levels[l];
        if (li.width_px != f.width || li.height_px != f.height || levels[l].directory >= 0) continue;
        Directory dir;
        if (Status s = readTileTable(tif, d, f, &dir); !s) return s;
        levels[l].directory = int(directories.size());
        directories.push_back(std::move(dir));
        break;
      }
    }
    if (!TIFFReadDirectory(tif)) break;
  }
  if (levels.empty() || levels[0].directory != 0)
    return Status::error(ErrorCode::kBadHeader, name + ": no full-resolution image");
  return finishLayout();
}

Status CogReader::Impl::finishLayout() {
  layout.internal_tile_px = tile_px;
  layout.compression = cog::codecName(compression);
  layout.stored_levels.resize(levels.size());
  size_t coarsest = 0;
  for (size_t l = 0; l < levels.size(); ++l) {
    layout.stored_levels[l] = levels[l].directory >= 0;
    if (levels[l].directory >= 0) coarsest = l;
  }
  coarsest_stored = uint32_t(coarsest);
  const LevelInfo& top = info.geometry.levels[coarsest];
  if (coarsest + 1 < levels.size() && std::max(top.width_px, top.height_px) > kMaxBuildFromPx)
    return Status::error(ErrorCode::kUnsupported,
                         name + ": its coarsest image is " + std::to_string(top.width_px) + " x " +
                             std::to_string(top.height_px) +
                             " px: the levels above it would be built by reading all of it; add overviews "
                             "(gdal_translate -of COG IN OUT.tif, or gdaladdo -r average IN)");
  // Levels missing between two the file holds are built from the level
  // below on every ask (only the few above the coarsest are kept): each
  // tile of the k-th missing level in a row costs 4^k tiles of the stored
  // one. Three in a row (64 per tile) is past what a loader should do.
  for (size_t l = 0, run = 0; l <= coarsest; ++l) {
    run = levels[l].directory >= 0 ? 0 : run + 1;
    if (run >= kMaxMissingLevelsInARow)
      return Status::error(ErrorCode::kUnsupported,
                           name + ": its overviews leave " + std::to_string(run) +
                               " levels in a row missing (from level " + std::to_string(l + 1 - run) +
                               "): make overviews at every factor of 2 (gdal_translate -of COG IN OUT.tif, or "
                               "gdaladdo -r average IN 2 4 8 16 ...)");
  }
  return okStatus();
}

Status CogReader::Impl::openHandle(const Directory& dir, TIFF** out, std::string* error) const {
  const uint16_t directory = dir.index;
  *out = nullptr;
  TIFF* tif = cog::openClient(const_cast<Impl*>(this), name, error);
  if (tif == nullptr) return Status::error(ErrorCode::kIo, name + ": cannot reopen: " + *error);
  if (!TIFFSetDirectory(tif, directory)) {
    *error = cog::lastError(tif);
    TIFFClose(tif);
    return Status::error(ErrorCode::kIo, name + ": cannot reopen directory " + std::to_string(directory) + ": " + *error);
  }
  if (dir.ycbcr_jpeg) TIFFSetField(tif, TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
  *out = tif;
  return okStatus();
}

Status CogReader::Impl::rawTile(size_t d, uint32_t cx, uint32_t cy, std::vector<uint8_t>* out,
                                uint64_t* read) const {
  const Directory& dir = directories[d];
  const size_t t = size_t(cy) * dir.tiles_across + cx;
  const uint64_t bytes = dir.counts[t];
  // The disk cache's copy carries its own checksum (a COG records none).
  const std::string entry = "t" + std::to_string(dir.index) + "-" + std::to_string(cx) + "-" + std::to_string(cy);
  if (disk_cache) {
    std::vector<uint8_t> cached;
    const auto valid = [&](const std::vector<uint8_t>& b) {
      uint32_t sum;
      std::memcpy(&sum, b.data(), 4);
      return format::tileChecksum(b.data() + 4, bytes) == sum;
    };
    if (disk_cache->getChecked(cache_key, entry, size_t(bytes) + 4, &cached, valid, &disk_counts)) {
      out->assign(cached.begin() + 4, cached.end());
      return okStatus();
    }
  }
  out->resize(size_t(bytes));
  if (Status s = readSource(out->data(), out->size(), dir.offsets[t]); !s) return s;
  *read += bytes;
  if (disk_cache) {
    std::vector<uint8_t> kept(size_t(bytes) + 4);
    const uint32_t sum = format::tileChecksum(out->data(), out->size());
    std::memcpy(kept.data(), &sum, 4);
    std::memcpy(kept.data() + 4, out->data(), out->size());
    disk_cache->put(cache_key, entry, kept);
  }
  return okStatus();
}

Status CogReader::Impl::decodeInternal(size_t d, uint32_t cx, uint32_t cy, Pixels* out, uint64_t* read) const {
  const Directory& dir = directories[d];
  const size_t t = size_t(cy) * dir.tiles_across + cx;
  auto pixels = std::make_shared<std::vector<uint8_t>>(dir.decoded_bytes);
  if (dir.counts[t] == 0) {
    // A sparse tile (GDAL's SPARSE_OK): never written, read as zeros.
    *out = std::move(pixels);
    return okStatus();
  }
  thread_local std::vector<uint8_t> raw;
  if (Status s = rawTile(d, cx, cy, &raw, read); !s) return s;
  TIFF* tif = nullptr;
  {
    std::lock_guard lock(handles_mutex);
    if (!idle_handles[d].empty()) {
      tif = idle_handles[d].back();
      idle_handles[d].pop_back();
    }
  }
  if (tif == nullptr) {
    std::string error;
    if (Status s = openHandle(dir, &tif, &error); !s) return s;
  }
  cog::clearError(tif);
  const bool ok = TIFFReadFromUserBuffer(tif, uint32_t(t), raw.data(), tmsize_t(raw.size()), pixels->data(),
                                         tmsize_t(pixels->size())) != 0;
  const std::string why = ok ? std::string() : cog::lastError(tif);
  {
    std::lock_guard lock(handles_mutex);
    idle_handles[d].push_back(tif);
  }
  if (!ok)
    return Status::error(ErrorCode::kCorruptTile, name + ": internal tile (" + std::to_string(cx) + ", " +
                                                      std::to_string(cy) + ") of directory " + std::to_string(dir.index) +
                                                      " does not decode" + (why.empty() ? "" : ": " + why));
  *out = std::move(pixels);
  return okStatus();
}

Status CogReader::Impl::internalTile(size_t d, uint32_t cx, uint32_t cy, Pixels* out, uint64_t* read) const {
  const uint64_t id = cacheId(d, cx, cy);
  std::promise<Decoded> promise;
  std::shared_future<Decoded> result;
  bool mine = false;
  {
    std::lock_guard lock(cache_mutex);
    auto it = decoded.find(id);
    if (it != decoded.end()) {
      lru.splice(lru.begin(), lru, it->second.lru);
      result = it->second.result;
    } else {
      lru.push_front(id);
      result = promise.get_future().share();
      decoded.emplace(id, CacheEntry{result, lru.begin()});
      mine = true;
      // Keep the byte cap, but never drop a tile still being decoded.
      const size_t keep = std::max<size_t>(kDecodedCacheMinTiles,
                                           size_t(kDecodedCacheBytes / std::max<size_t>(1, directories[d].decoded_bytes)));
      for (auto victim = std::prev(lru.end()); decoded.size() > keep && victim != lru.begin();) {
        auto entry = decoded.find(*victim);
        auto previous = std::prev(victim);
        if (entry->second.result.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
          decoded.erase(entry);
          lru.erase(victim);
        }
        victim = previous;
      }
    }
  }
  if (mine) {
    Decoded d_out;
    try {
      d_out.status = decodeInternal(d, cx, cy, &d_out.pixels, read);
    } catch (const std::exception& e) {
      // The waiting threads must get an answer, never a broken promise.
      d_out.status = Status::error(ErrorCode::kIo, name + ": internal tile (" + std::to_string(cx) + ", " +
                                                       std::to_string(cy) + "): " + e.what());
    }
    promise.set_value(d_out);
    if (!d_out.status) {
      // A failure is not kept: the next ask tries again.
      std::lock_guard lock(cache_mutex);
      auto it = decoded.find(id);
      if (it != decoded.end()) {
        lru.erase(it->second.lru);
        decoded.erase(it);
      }
    }
  }
  const Decoded& done = result.get();
  *out = done.pixels;
  return done.status;
}

Status CogReader::Impl::cutTile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* read) const {
  const size_t d = size_t(levels[key.level].directory);
  const Directory& dir = directories[d];
  const uint32_t bpp = bytesPerPixel(info.geometry.format);
  const uint32_t P = kCogPyramidTilePx;
  const uint64_t x0 = uint64_t(key.x) * P, y0 = uint64_t(key.y) * P;
  const uint32_t valid_w = uint32_t(std::min<uint64_t>(P, dir.width - x0));
  const uint32_t valid_h = uint32_t(std::min<uint64_t>(P, dir.height - y0));
  const size_t src_bpp = size_t(samples) * (bits / 8);
  const uint64_t T = dir.tile_px;  // this directory's internal tile side
  // Every internal tile under the pyramid tile's valid texels.
  for (uint64_t cy = y0 / T; cy * T < y0 + valid_h; ++cy) {
    for (uint64_t cx = x0 / T; cx * T < x0 + valid_w; ++cx) {
      Pixels source_tile;
      if (Status s = internalTile(d, uint32_t(cx), uint32_t(cy), &source_tile, read); !s) return s;
      const uint64_t ix0 = std::max(x0, cx * T), ix1 = std::min(x0 + valid_w, (cx + 1) * T);
      const uint64_t iy0 = std::max(y0, cy * T), iy1 = std::min(y0 + valid_h, (cy + 1) * T);
      for (uint64_t y = iy0; y < iy1; ++y) {
        const uint8_t* src = source_tile->data() + ((y - cy * T) * T + (ix0 - cx * T)) * src_bpp;
        uint8_t* dst = pixels.data() + ((y - y0) * P + (ix0 - x0)) * bpp;
        if (nodata_alpha) {
          for (uint64_t x = ix0; x < ix1; ++x, src += samples, dst += 4) {
            bool empty = true;
            for (uint32_t c = 0; c < samples; ++c) empty = empty && src[c] == nodata;
            dst[0] = empty ? 0 : src[0];
            dst[1] = empty ? 0 : src[samples == 3 ? 1 : 0];
            dst[2] = empty ? 0 : src[samples == 3 ? 2 : 0];
            dst[3] = empty ? 0 : 255;
          }
        } else if (!grey_alpha) {
          std::memcpy(dst, src, (ix1 - ix0) * bpp);
        } else {
          for (uint64_t x = ix0; x < ix1; ++x, src += 2, dst += 4) dst[0] = dst[1] = dst[2] = src[0], dst[3] = src[1];
        }
      }
    }
  }
  clampEdges(pixels, P, bpp, valid_w, valid_h);
  return okStatus();
}

Status CogReader::Impl::buildTile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* read) const {
  {
    std::lock_guard lock(built_mutex);
    if (auto it = built.find(key); it != built.end()) {
      std::memcpy(pixels.data(), it->second->data(), pixels.size());
      return okStatus();
    }
  }
  const PyramidGeometry& g = info.geometry;
  const uint32_t P = kCogPyramidTilePx;
  const uint32_t bpp = bytesPerPixel(g.format);
  const LevelInfo& fine = g.levels[key.level - 1];
  const LevelInfo& coarse = g.levels[key.level];
  // The (up to) four tiles of the level below.
  std::vector<uint8_t> children[2][2];
  for (uint32_t j = 0; j < 2; ++j)
    for (uint32_t i = 0; i < 2; ++i) {
      const TileKey child{key.level - 1, 2 * key.x + i, 2 * key.y + j};
      if (child.x >= fine.tiles_x || child.y >= fine.tiles_y) continue;
      children[j][i].resize(g.tileBytes());
      if (Status s = tile(child, children[j][i], read); !s) return s;
    }
  // The box filter of docs/tile-store.md: (a + b + c + d + 2) / 4 of the
  // 2 x 2 texels below, coordinates clamped into the level below; texels
  // past the level's edge take the nearest inside.
  const uint64_t fx_base = uint64_t(2) * key.x * P, fy_base = uint64_t(2) * key.y * P;
  auto texel = [&](uint64_t fx, uint64_t fy) {
    fx = std::min<uint64_t>(fx, fine.width_px - 1);
    fy = std::min<uint64_t>(fy, fine.height_px - 1);
    const uint64_t lx = fx - fx_base, ly = fy - fy_base;
    const std::vector<uint8_t>& t = children[ly / P][lx / P];
    return t.data() + ((ly % P) * P + lx % P) * bpp;
  };
  const uint32_t channels = channelCount(g.format);
  const bool wide = g.format == PixelFormat::kR16;
  for (uint32_t y = 0; y < P; ++y) {
    const uint64_t cy = std::min<uint64_t>(uint64_t(key.y) * P + y, coarse.height_px - 1);
    for (uint32_t x = 0; x < P; ++x) {
      const uint64_t cx = std::min<uint64_t>(uint64_t(key.x) * P + x, coarse.width_px - 1);
      const uint8_t* a = texel(2 * cx, 2 * cy);
      const uint8_t* b = texel(2 * cx + 1, 2 * cy);
      const uint8_t* c = texel(2 * cx, 2 * cy + 1);
      const uint8_t* e = texel(2 * cx + 1, 2 * cy + 1);
      uint8_t* dst = pixels.data() + (size_t(y) * P + x) * bpp;
      if (wide) {
        auto v = [](const uint8_t* p) { return uint32_t(p[0]) | uint32_t(p[1]) << 8; };
        const uint32_t sum = (v(a) + v(b) + v(c) + v(e) + 2) / 4;
        dst[0] = uint8_t(sum);
        dst[1] = uint8_t(sum >> 8);
      } else {
        for (uint32_t ch = 0; ch < channels; ++ch) dst[ch] = uint8_t((a[ch] + b[ch] + c[ch] + e[ch] + 2) / 4);
      }
    }
  }
  // Kept only above the coarsest level the file holds: those levels are a
  // few tiles, and each is built from all of the level below. A level
  // missing between two the file holds may be huge; its tiles are built
  // again from four stored tiles when asked (the decoded cache holds those).
  if (key.level > coarsest_stored) {
    auto keep = std::make_shared<std::vector<uint8_t>>(pixels.begin(), pixels.end());
    std::lock_guard lock(built_mutex);
    built.emplace(key, std::move(keep));
  }
  return okStatus();
}

Status CogReader::Impl::tile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* read) const {
  return levels[key.level].directory >= 0 ? cutTile(key, pixels, read) : buildTile(key, pixels, read);
}

CogReader::CogReader() : m_impl(std::make_unique<Impl>()) {}
CogReader::~CogReader() = default;

Status CogReader::open(const std::string& path, const RemoteOptions& remote, std::unique_ptr<CogReader>* out) {
  if (out == nullptr) return Status::error(ErrorCode::kInvalidArgument, "null output");
  out->reset();
  std::unique_ptr<CogReader> reader(new CogReader());
  reader->m_impl->path = path;
  reader->m_impl->remote = remote;
  if (Status s = reader->m_impl->openImpl(); !s) return s;
  *out = std::move(reader);
  return okStatus();
}

const StoreInfo& CogReader::info() const { return m_impl->info; }
const CogLayout& CogReader::layout() const { return m_impl->layout; }

Status CogReader::readTile(const TileKey& key, std::span<uint8_t> pixels, uint64_t* bytes_read) const {
  *bytes_read = 0;
  const PyramidGeometry& g = m_impl->info.geometry;
  if (!g.contains(key))
    return Status::error(ErrorCode::kOutOfRange, m_impl->name + ": no tile " + format::keyText(key));
  if (pixels.size() != g.tileBytes())
    return Status::error(ErrorCode::kInvalidArgument, "pixel buffer is not one tile");
  return m_impl->tile(key, pixels, bytes_read);
}

unsigned CogReader::suggestedReadThreads() const { return m_impl->source->suggestedReadThreads(); }

RemoteStats CogReader::remoteStats() const {
  RemoteStats stats = m_impl->source->remoteStats();
  m_impl->disk_counts.fill(&stats);
  return stats;
}

uint64_t CogReader::bytesRead() const { return m_impl->bytes_read.load(std::memory_order_relaxed); }

Status readRasterInfo(const std::string& path, const RemoteOptions& remote, StoreInfo* out) {
  *out = StoreInfo{};
  std::unique_ptr<TileStoreReader> store;
  Status s = TileStoreReader::open(path, remote, &store);
  if (s) {
    *out = store->info();
    return okStatus();
  }
  if (s.code != ErrorCode::kBadMagic) return s;
  std::unique_ptr<CogReader> cog;
  const Status c = CogReader::open(path, remote, &cog);
  if (!c) return c.code == ErrorCode::kBadMagic ? s : c;
  *out = cog->info();
  return okStatus();
}

}  // namespace clipstream
