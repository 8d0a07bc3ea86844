// TileStoreReader: reads the header, level table, page directories and
// metadata at open and has format_check.h judge each; index pages are read
// on first use, outside any lock, checked the same way, and published with
// a compare-and-swap (a racing loser frees its copy).
#include "byte_source.h"
#include "disk_cache.h"
#include "format.h"
#include "format_check.h"
#include "worker_threads.h"

#include <clipstream/store/tile_store.h>

#include <algorithm>
#include <cerrno>
#include <functional>
#include <mutex>
#include <thread>
#include <tuple>

namespace clipstream {

namespace {

using format::PageDirEntry;
using format::TileEntry;

struct Page {
  std::vector<TileEntry> entries;
};

struct LevelRead {
  uint64_t payload_offset = 0;
  uint64_t payload_bytes = 0;
  uint32_t pages_x = 0;
  uint32_t pages_y = 0;
  std::vector<PageDirEntry> directory;
  std::unique_ptr<std::atomic<const Page*>[]> pages;  // null until loaded
};

}  // namespace

struct TileStoreReader::Impl {
  std::string path;
  RemoteOptions remote;
  std::unique_ptr<ByteSource> source;
  StoreInfo info;
  format::CheckedHeader header;  // what the header says, checked at open
  std::vector<LevelRead> levels;
  mutable std::atomic<uint64_t> bytes_read{0};
  mutable std::atomic<uint64_t> pages_loaded{0};
  // The payload order the first telling index page showed (learnOrder()):
  // 0 not known yet, 1 rows, 2 curve.
  mutable std::atomic<int> order_seen{0};
  // The disk cache of a URL store (RemoteOptions::disk_cache_dir), or null.
  std::shared_ptr<DiskCache> disk_cache;
  std::string cache_key;  // this store version's sub-folder
  mutable DiskCache::Counts disk_counts;

  ~Impl() {
    for (LevelRead& level : levels) {
      if (!level.pages) continue;
      for (size_t i = 0; i < level.directory.size(); ++i) delete level.pages[i].load();
    }
  }

  Status read(void* data, size_t bytes, uint64_t offset) const {
    bytes_read.fetch_add(bytes, std::memory_order_relaxed);
    return source->read(data, bytes, offset);
  }
  void readMany(std::span<const ByteRange> ranges, std::span<Status> statuses) const {
    for (const ByteRange& r : ranges) bytes_read.fetch_add(r.bytes, std::memory_order_relaxed);
    source->readMany(ranges, statuses);
  }

  // Looks `name` up in the disk cache (DiskCache::getChecked()).
  template <typename Valid>
  bool fromDiskCache(const std::string& name, uint64_t bytes, std::vector<uint8_t>* out,
                     const Valid& valid) const {
    return disk_cache->getChecked(cache_key, name, size_t(bytes), out, valid, &disk_counts);
  }
  static std::string tileName(const TileKey& key) {
    return "t" + std::to_string(key.level) + "-" + std::to_string(key.x) + "-" + std::to_string(key.y);
  }
  // The disk cache's copy of a payload, checked against its checksum like
  // the server's bytes; false (and a torn or wrong copy removed) otherwise.
  bool cachedPayload(const TileKey& key, const TileLocation& location,
                     std::vector<uint8_t>* payload) const {
    if (!disk_cache) return false;
    if (fromDiskCache(tileName(key), location.stored_bytes, payload, [&](const std::vector<uint8_t>& b) {
          return format::tileChecksum(b.data(), b.size()) == location.checksum;
        }))
      return true;
    payload->clear();
    return false;
  }
  void keepPayload(const TileKey& key, std::span<const uint8_t> payload) const {
    if (!disk_cache) return;
    disk_cache->put(cache_key, tileName(key), payload);
  }
  static std::string pageName(uint32_t level_index, uint32_t px, uint32_t py) {
    return "p" + std::to_string(level_index) + "-" + std::to_string(px) + "-" + std::to_string(py);
  }
  // The disk cache's copy of an index page, checked like the server's.
  bool cachedPage(uint32_t level_index, uint32_t px, uint32_t py,
                  std::unique_ptr<Page>* out) const {
    if (!disk_cache) return false;
    const LevelRead& level = levels[level_index];
    const PageDirEntry& dir = level.directory[size_t(py) * level.pages_x + px];
    std::vector<uint8_t> bytes;
    return fromDiskCache(pageName(level_index, px, py), dir.bytes, &bytes,
                         [&](const std::vector<uint8_t>& b) { return decodePage(level_index, px, py, b, out); });
  }
  void keepPage(uint32_t level_index, uint32_t px, uint32_t py,
                std::span<const uint8_t> bytes) const {
    if (disk_cache) disk_cache->put(cache_key, pageName(level_index, px, py), bytes);
  }

  // A failed check of the store's bytes (format_check.h), its message
  // prefixed with the store's path; a success passes through.
  Status named(const Status& status) const {
    return status ? status : Status::error(status.code, path + ": " + status.message);
  }

  // Opens the source and checks the header, the level table, every page
  // directory and the metadata (format_check.h), reading each once.
  Status openImpl();
  // Reads and checks the header into `header` and `info`.
  Status openHeader();
  // Reads and checks the level table into *layout and `levels`.
  Status openLevelTable(format::IndexLayout* layout);
  // Reads and checks level l's page directory into levels[l].
  Status openPageDirectory(const format::IndexLayout& layout, uint32_t l);
  // Reads and checks one index page without publishing it.
  Status readPage(uint32_t level_index, uint32_t px, uint32_t py,
                  std::unique_ptr<Page>* out) const;
  // Checks one index page's bytes (read from the file or a cache).
  Status decodePage(uint32_t level_index, uint32_t px, uint32_t py, std::span<const uint8_t> bytes,
                    std::unique_ptr<Page>* out) const;
  // Notes the payload order a page shows (order_seen), if not known yet.
  void learnOrder(uint32_t level_index, uint32_t px, uint32_t py, const Page& page) const;
  // Publishes a page unless another thread did first; returns the published one.
  const Page* publish(uint32_t level_index, size_t page_index, std::unique_ptr<Page> page) const;
  // Reads every index page these tiles need that is not loaded yet, all in
  // flight at once (a batch spanning pages costs one round trip for them).
  void loadPagesOf(std::span<const TileKey> keys) const;
  // Returns the published page, reading and publishing it on first use.
  Status loadPage(uint32_t level_index, uint32_t px, uint32_t py, const Page** out) const;
  // Published page or, if not loaded yet, a private copy kept in *scratch:
  // whole-file scans use this so they do not pin the entire index in RAM.
  Status peekPage(uint32_t level_index, uint32_t px, uint32_t py, std::unique_ptr<Page>* scratch,
                  const Page** out) const;
  void entryLocation(uint32_t level_index, const TileEntry& entry, TileLocation* out) const;
  Status locate(const TileKey& key, TileLocation* out) const;
  Status readPayload(const TileKey& key, RawTile* out) const;
};

Status TileStoreReader::Impl::openImpl() {
  // A local regular file, or a URL read by HTTP range requests.
  Status opened = isStoreUrl(path) ? openHttpSource(path, remote, &source)
                                   : openFileSource(path, &source);
  if (!opened) return opened;
  if (!remote.disk_cache_dir.empty() && isStoreUrl(path) && !source->version().empty()) {
    Status cache = DiskCache::open(remote.disk_cache_dir, remote.disk_cache_bytes, &disk_cache);
    if (!cache) return cache;
    cache_key = DiskCache::storeKey(path, source->version());
    disk_counts.folder_refused = !disk_cache->usableStoreDir(cache_key);
  }
  path = displayStorePath(path);  // from here on `path` only names the store in messages
  Status status = openHeader();
  if (!status) return status;
  // Level table and metadata lie back to back at the end: one read remotely.
  const format::Header& fields = header.fields;
  source->prefetch(fields.level_table_offset, fields.file_bytes - fields.level_table_offset);
  format::IndexLayout layout;
  status = openLevelTable(&layout);
  if (!status) return status;
  // Every page directory, back to back before the level table.
  source->prefetch(layout.pages_end, fields.level_table_offset - layout.pages_end);
  for (uint32_t l = 0; l < fields.level_count; ++l) {
    status = openPageDirectory(layout, l);
    if (!status) return status;
  }
  std::vector<uint8_t> metadata(static_cast<size_t>(fields.metadata_bytes));
  status = read(metadata.data(), metadata.size(), fields.metadata_offset);
  if (!status) return status;
  return named(format::checkMetadata(metadata, header, &info));
}

Status TileStoreReader::Impl::openHeader() {
  const uint64_t actual_bytes = source->size();
  uint8_t bytes[format::kHeaderBytes];
  // A file too short to hold the magic is not read: the check says so.
  size_t given = 0;
  if (actual_bytes >= format::kMagicEndBytes) {
    given = static_cast<size_t>(std::min<uint64_t>(actual_bytes, sizeof(bytes)));
    Status status = read(bytes, given, 0);
    if (!status) return status;
  }
  Status status = format::checkHeader(std::span(bytes, given), actual_bytes, &header);
  if (!status) return named(status);
  info.geometry = header.geometry;
  info.encoding = header.encoding;
  info.file_bytes = header.fields.file_bytes;
  info.format_version = header.fields.format_version;
  return okStatus();
}

Status TileStoreReader::Impl::openLevelTable(format::IndexLayout* layout) {
  // Its size was checked against the level count with the header.
  std::vector<uint8_t> bytes(static_cast<size_t>(header.fields.level_table_bytes));
  Status status = read(bytes.data(), bytes.size(), header.fields.level_table_offset);
  if (!status) return status;
  status = format::checkLevelTable(bytes, header, layout);
  if (!status) return named(status);
  levels.resize(layout->levels.size());
  for (size_t l = 0; l < levels.size(); ++l) {
    const format::LevelEntry& entry = layout->levels[l];
    levels[l].pages_x = entry.pages_x;
    levels[l].pages_y = entry.pages_y;
    levels[l].payload_offset = entry.payload_offset;
    levels[l].payload_bytes = entry.payload_bytes;
  }
  return okStatus();
}

Status TileStoreReader::Impl::openPageDirectory(const format::IndexLayout& layout, uint32_t l) {
  uint64_t offset = 0;
  Status status = format::checkDirectoryPlace(layout, l, &offset);
  if (!status) return named(status);
  // Its size was checked against the page grid with the level table.
  std::vector<uint8_t> bytes(static_cast<size_t>(layout.levels[l].directory_bytes));
  status = read(bytes.data(), bytes.size(), offset);
  if (!status) return status;
  LevelRead& level = levels[l];
  status = format::checkPageDirectory(bytes, header, layout, l, &level.directory);
  if (!status) return named(status);
  const size_t page_count = level.directory.size();
  level.pages.reset(new std::atomic<const Page*>[page_count]);
  for (size_t i = 0; i < page_count; ++i) level.pages[i].store(nullptr);
  return okStatus();
}

Status TileStoreReader::Impl::readPage(uint32_t level_index, uint32_t px, uint32_t py,
                                       std::unique_ptr<Page>* out) const {
  if (cachedPage(level_index, px, py, out)) return okStatus();
  const LevelRead& level = levels[level_index];
  const PageDirEntry& dir = level.directory[size_t(py) * level.pages_x + px];
  std::vector<uint8_t> bytes(dir.bytes);
  Status status = read(bytes.data(), bytes.size(), dir.offset);
  if (!status) return status;
  status = decodePage(level_index, px, py, bytes, out);
  if (status) keepPage(level_index, px, py, bytes);
  return status;
}

Status TileStoreReader::Impl::decodePage(uint32_t level_index, uint32_t px, uint32_t py,
                                         std::span<const uint8_t> bytes,
                                         std::unique_ptr<Page>* out) const {
  const LevelRead& level = levels[level_index];
  const PageDirEntry& dir = level.directory[size_t(py) * level.pages_x + px];
  auto page = std::make_unique<Page>();
  Status status = format::checkIndexPage(bytes, header, level_index, px, py, dir.checksum,
                                         level.payload_bytes, &page->entries);
  if (!status) return named(status);
  *out = std::move(page);
  return okStatus();
}

void TileStoreReader::Impl::learnOrder(uint32_t level_index, uint32_t px, uint32_t py,
                                       const Page& page) const {
  if (order_seen.load(std::memory_order_relaxed) != 0) return;
  const LevelInfo& level_info = info.geometry.levels[level_index];
  // A level two tiles wide lies in aligned squares in either order.
  if (level_info.tiles_x <= 2) return;
  const uint32_t w = format::pageSpan(level_info.tiles_x, px);
  const uint32_t h = format::pageSpan(level_info.tiles_y, py);
  uint32_t together = 0, apart = 0;
  for (uint32_t y = 0; y + 1 < h; y += 2) {
    for (uint32_t x = 0; x + 1 < w; x += 2) {
      const format::TileEntry* square[4] = {
          &page.entries[size_t(y) * w + x], &page.entries[size_t(y) * w + x + 1],
          &page.entries[size_t(y + 1) * w + x], &page.entries[size_t(y + 1) * w + x + 1]};
      uint64_t first = UINT64_MAX, end = 0, bytes = 0;
      bool payloads = true;
      for (const format::TileEntry* e : square) {
        payloads &= e->stored_bytes > 0;
        first = std::min(first, e->offset_or_value);
        end = std::max(end, e->offset_or_value + e->stored_bytes);
        bytes += e->stored_bytes;
      }
      if (!payloads) continue;
      (end - first == bytes ? together : apart) += 1;
    }
  }
  // Four squares tell; nine in ten together is a curve (the written order
  // puts a row's payloads between the halves of every square).
  if (together + apart < 4) return;
  int expected = 0;
  order_seen.compare_exchange_strong(expected, together * 10 >= (together + apart) * 9 ? 2 : 1,
                                     std::memory_order_relaxed);
}

const Page* TileStoreReader::Impl::publish(uint32_t level_index, size_t page_index,
                                           std::unique_ptr<Page> page) const {
  const LevelRead& level = levels[level_index];
  learnOrder(level_index, uint32_t(page_index % level.pages_x),
             uint32_t(page_index / level.pages_x), *page);
  const Page* expected = nullptr;
  const Page* mine = page.get();
  if (level.pages[page_index].compare_exchange_strong(expected, mine, std::memory_order_acq_rel,
                                                      std::memory_order_acquire)) {
    page.release();
    pages_loaded.fetch_add(1, std::memory_order_relaxed);
    return mine;
  }
  return expected;  // another thread published first; ours is freed
}

Status TileStoreReader::Impl::loadPage(uint32_t level_index, uint32_t px, uint32_t py,
                                       const Page** out) const {
  const LevelRead& level = levels[level_index];
  const size_t page_index = size_t(py) * level.pages_x + px;
  if (const Page* page = level.pages[page_index].load(std::memory_order_acquire)) {
    *out = page;
    return okStatus();
  }
  // Read and check without any lock; concurrent first users may both read.
  std::unique_ptr<Page> page;
  Status status = readPage(level_index, px, py, &page);
  if (!status) return status;
  *out = publish(level_index, page_index, std::move(page));
  return okStatus();
}

void TileStoreReader::Impl::loadPagesOf(std::span<const TileKey> keys) const {
  struct Wanted {
    uint32_t level = 0, px = 0, py = 0;
    std::vector<uint8_t> bytes;
  };
  std::vector<Wanted> wanted;
  for (const TileKey& key : keys) {
    if (!info.geometry.contains(key)) continue;
    const LevelRead& level = levels[key.level];
    const uint32_t px = key.x / format::kPageTiles, py = key.y / format::kPageTiles;
    const size_t page_index = size_t(py) * level.pages_x + px;
    if (level.directory[page_index].flags & format::kPageFlagConstant) continue;
    if (level.pages[page_index].load(std::memory_order_acquire) != nullptr) continue;
    bool listed = false;
    for (const Wanted& w : wanted) listed |= w.level == key.level && w.px == px && w.py == py;
    if (listed) continue;
    if (std::unique_ptr<Page> page; cachedPage(key.level, px, py, &page)) {
      publish(key.level, page_index, std::move(page));
      continue;
    }
    wanted.push_back({key.level, px, py, {}});
  }
  if (wanted.size() < 2) return;  // one page: locate() reads it as before
  std::vector<ByteRange> ranges(wanted.size());
  std::vector<Status> statuses(wanted.size());
  for (size_t i = 0; i < wanted.size(); ++i) {
    Wanted& w = wanted[i];
    const LevelRead& level = levels[w.level];
    const PageDirEntry& dir = level.directory[size_t(w.py) * level.pages_x + w.px];
    w.bytes.resize(dir.bytes);
    ranges[i] = ByteRange{w.bytes.data(), w.bytes.size(), dir.offset};
  }
  readMany(ranges, statuses);
  for (size_t i = 0; i < wanted.size(); ++i) {
    const Wanted& w = wanted[i];
    std::unique_ptr<Page> page;
    // A failure is left for locate(), which reads the page again and reports.
    if (!statuses[i] || !decodePage(w.level, w.px, w.py, w.bytes, &page)) continue;
    keepPage(w.level, w.px, w.py, w.bytes);
    publish(w.level, size_t(w.py) * levels[w.level].pages_x + w.px, std::move(page));
  }
}

Status TileStoreReader::Impl::peekPage(uint32_t level_index, uint32_t px, uint32_t py,
                                       std::unique_ptr<Page>* scratch, const Page** out) const {
  const LevelRead& level = levels[level_index];
  if (const Page* page =
          level.pages[size_t(py) * level.pages_x + px].load(std::memory_order_acquire)) {
    *out = page;
    return okStatus();
  }
  Status status = readPage(level_index, px, py, scratch);
  if (!status) return status;
  *out = scratch->get();
  return okStatus();
}

void TileStoreReader::Impl::entryLocation(uint32_t level_index, const TileEntry& entry,
                                          TileLocation* out) const {
  *out = TileLocation{};
  out->min_height = entry.min_height;
  out->max_height = entry.max_height;
  out->error = entry.error;
  if (entry.stored_bytes == 0) {
    out->constant = true;
    std::memcpy(out->constant_pixel, &entry.offset_or_value, 8);
    return;
  }
  out->offset = levels[level_index].payload_offset + entry.offset_or_value;
  out->stored_bytes = entry.stored_bytes;
  out->checksum = entry.checksum;
}

Status TileStoreReader::Impl::locate(const TileKey& key, TileLocation* out) const {
  if (!info.geometry.contains(key)) {
    return Status::error(ErrorCode::kOutOfRange, format::keyText(key) + " is outside the pyramid");
  }
  *out = TileLocation{};
  const LevelRead& level = levels[key.level];
  const uint32_t px = key.x / format::kPageTiles;
  const uint32_t py = key.y / format::kPageTiles;
  const PageDirEntry& dir = level.directory[size_t(py) * level.pages_x + px];
  if (dir.flags & format::kPageFlagConstant) {
    out->constant = true;
    std::memcpy(out->constant_pixel, &dir.constant_value, 8);
    if (info.elevation.present) {
      // A constant page of an elevation store is flat ground (the writer's rule).
      out->min_height = out->max_height =
          float(heightOfSample(info.geometry.format, info.elevation, out->constant_pixel));
    }
    return okStatus();
  }
  const Page* page = nullptr;
  Status status = loadPage(key.level, px, py, &page);
  if (!status) return status;
  const uint32_t w = format::pageSpan(info.geometry.levels[key.level].tiles_x, px);
  entryLocation(key.level,
                page->entries[size_t(key.y % format::kPageTiles) * w + key.x % format::kPageTiles],
                out);
  return okStatus();
}

Status TileStoreReader::Impl::readPayload(const TileKey& key, RawTile* out) const {
  out->key = key;
  out->payload.clear();
  if (out->location.constant) return okStatus();
  if (cachedPayload(key, out->location, &out->payload)) return okStatus();
  out->payload.resize(out->location.stored_bytes);
  Status status = read(out->payload.data(), out->payload.size(), out->location.offset);
  if (!status) {
    return Status::error(status.code, format::keyText(key) + ": " + status.message);
  }
  // Checked before any decompression: zstd never sees bytes we did not write.
  if (format::tileChecksum(out->payload.data(), out->payload.size()) != out->location.checksum) {
    return Status::error(ErrorCode::kCorruptTile,
                         format::keyText(key) + ": payload checksum mismatch");
  }
  keepPayload(key, out->payload);
  return okStatus();
}

void TileStoreReader::readRawBatch(std::span<const TileKey> keys, std::span<RawTile> out,
                                   std::span<Status> statuses) const {
  const Impl& impl = *m_impl;
  const size_t n = std::min({keys.size(), out.size(), statuses.size()});
  impl.loadPagesOf(keys.first(n));
  // Locate everything; payloads to read, in file order.
  std::vector<size_t> order;
  for (size_t i = 0; i < n; ++i) {
    out[i].key = keys[i];
    out[i].payload.clear();
    statuses[i] = impl.locate(keys[i], &out[i].location);
    if (statuses[i] && !out[i].location.constant &&
        !impl.cachedPayload(keys[i], out[i].location, &out[i].payload))
      order.push_back(i);
  }
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return out[a].location.offset < out[b].location.offset;
  });
  // Runs of payloads close together: [first, last) of `order` each.
  struct Run {
    size_t first = 0, last = 0;
    uint64_t begin = 0, end = 0;
  };
  std::vector<Run> runs;
  for (size_t first = 0; first < order.size();) {
    // Grow the run while the next payload starts close to this one's end.
    const uint64_t begin = out[order[first]].location.offset;
    uint64_t end = begin + out[order[first]].location.stored_bytes;
    size_t last = first + 1;
    while (last < order.size()) {
      const TileLocation& next = out[order[last]].location;
      const uint64_t next_end = std::max(end, next.offset + next.stored_bytes);
      if (next.offset > end + impl.remote.coalesce_gap_bytes ||
          next_end - begin > impl.remote.coalesce_max_bytes)
        break;
      end = next_end;
      ++last;
    }
    runs.push_back({first, last, begin, end});
    first = last;
  }
  // Every run is in flight at once (one round trip for the batch). A run of
  // one tile is read straight into its payload; longer runs into a buffer
  // each, then split.
  std::vector<std::vector<uint8_t>> buffers(runs.size());
  std::vector<ByteRange> ranges(runs.size());
  std::vector<Status> run_status(runs.size());
  for (size_t r = 0; r < runs.size(); ++r) {
    const Run& run = runs[r];
    uint8_t* data = nullptr;
    if (run.last == run.first + 1) {
      std::vector<uint8_t>& payload = out[order[run.first]].payload;
      payload.resize(static_cast<size_t>(run.end - run.begin));
      data = payload.data();
    } else {
      buffers[r].resize(static_cast<size_t>(run.end - run.begin));
      data = buffers[r].data();
    }
    ranges[r] = ByteRange{data, static_cast<size_t>(run.end - run.begin), run.begin};
  }
  impl.readMany(ranges, run_status);
  for (size_t r = 0; r < runs.size(); ++r) {
    const Run& run = runs[r];
    const Status& status = run_status[r];
    for (size_t k = run.first; k < run.last; ++k) {
      const size_t i = order[k];
      if (!status) {
        out[i].payload.clear();
        statuses[i] = Status::error(status.code, format::keyText(keys[i]) + ": " + status.message);
        continue;
      }
      const TileLocation& location = out[i].location;
      if (run.last != run.first + 1) {
        const uint8_t* payload = buffers[r].data() + (location.offset - run.begin);
        out[i].payload.assign(payload, payload + location.stored_bytes);
      }
      // Checked before any decompression, as readRaw() does.
      if (format::tileChecksum(out[i].payload.data(), out[i].payload.size()) != location.checksum) {
        statuses[i] = Status::error(ErrorCode::kCorruptTile,
                                    format::keyText(keys[i]) + ": payload checksum mismatch");
      } else {
        impl.keepPayload(keys[i], out[i].payload);
      }
    }
  }
}

BatchShape TileStoreReader::suggestedBatchShape() const {
  return m_impl->order_seen.load(std::memory_order_relaxed) == 2 ? BatchShape::kSquare
                                                                 : BatchShape::kRow;
}

unsigned TileStoreReader::suggestedBatchTiles() const {
  return isStoreUrl(m_impl->path) ? std::max(1u, m_impl->remote.batch_tiles) : 1u;
}

TileStoreReader::TileStoreReader() : m_impl(std::make_unique<Impl>()) {}
TileStoreReader::~TileStoreReader() = default;

Status TileStoreReader::open(const std::string& path, std::unique_ptr<TileStoreReader>* out) {
  return open(path, RemoteOptions{}, out);
}

Status TileStoreReader::open(const std::string& path, const RemoteOptions& remote,
                             std::unique_ptr<TileStoreReader>* out) {
  if (out == nullptr) return Status::error(ErrorCode::kInvalidArgument, "null output");
  out->reset();
  std::unique_ptr<TileStoreReader> reader(new TileStoreReader());
  reader->m_impl->path = path;
  reader->m_impl->remote = remote;
  Status status = reader->m_impl->openImpl();
  if (!status) return status;
  *out = std::move(reader);
  return okStatus();
}

const StoreInfo& TileStoreReader::info() const { return m_impl->info; }

uint64_t TileStoreReader::bytesRead() const {
  return m_impl->bytes_read.load(std::memory_order_relaxed);
}

uint64_t TileStoreReader::indexPagesLoaded() const {
  return m_impl->pages_loaded.load(std::memory_order_relaxed);
}

unsigned TileStoreReader::suggestedReadThreads() const {
  return m_impl->source->suggestedReadThreads();
}

RemoteStats TileStoreReader::remoteStats() const {
  RemoteStats stats = m_impl->source->remoteStats();
  m_impl->disk_counts.fill(&stats);
  return stats;
}

Status TileStoreReader::locate(const TileKey& key, TileLocation* out) const {
  if (out == nullptr) return Status::error(ErrorCode::kInvalidArgument, "null output");
  return m_impl->locate(key, out);
}

Status TileStoreReader::readRaw(const TileKey& key, RawTile* out) const {
  if (out == nullptr) return Status::error(ErrorCode::kInvalidArgument, "null output");
  out->key = key;
  out->payload.clear();
  Status status = m_impl->locate(key, &out->location);
  if (!status) return status;
  return m_impl->readPayload(key, out);
}

Status TileStoreReader::decode(const RawTile& raw, std::span<uint8_t> pixels) const {
  return decodeTile(m_impl->info.geometry, m_impl->info.encoding, raw, pixels);
}

Status TileStoreReader::readTile(const TileKey& key, std::vector<uint8_t>* pixels) const {
  if (pixels == nullptr) return Status::error(ErrorCode::kInvalidArgument, "null output");
  RawTile raw;
  Status status = readRaw(key, &raw);
  if (!status) return status;
  pixels->resize(geometry().tileBytes());
  return decode(raw, *pixels);
}

Status TileStoreReader::levelStats(std::vector<LevelStats>* out) const {
  if (out == nullptr) return Status::error(ErrorCode::kInvalidArgument, "null output");
  const Impl& impl = *m_impl;
  out->assign(impl.levels.size(), LevelStats{});
  const PyramidGeometry& geometry = impl.info.geometry;
  for (uint32_t l = 0; l < impl.levels.size(); ++l) {
    const LevelRead& level = impl.levels[l];
    LevelStats& stats = (*out)[l];
    stats.tiles = uint64_t(geometry.levels[l].tiles_x) * geometry.levels[l].tiles_y;
    stats.raw_bytes = stats.tiles * geometry.tileBytes();
    for (uint32_t py = 0; py < level.pages_y; ++py) {
      for (uint32_t px = 0; px < level.pages_x; ++px) {
        const PageDirEntry& dir = level.directory[size_t(py) * level.pages_x + px];
        if (dir.flags & format::kPageFlagConstant) {
          stats.constant_tiles += uint64_t(format::pageSpan(geometry.levels[l].tiles_x, px)) *
                                  format::pageSpan(geometry.levels[l].tiles_y, py);
          continue;
        }
        std::unique_ptr<Page> scratch;
        const Page* page = nullptr;
        Status status = impl.peekPage(l, px, py, &scratch, &page);
        if (!status) return status;
        for (const TileEntry& entry : page->entries) {
          if (entry.stored_bytes == 0) {
            ++stats.constant_tiles;
          } else {
            stats.stored_bytes += entry.stored_bytes;
          }
        }
      }
    }
  }
  return okStatus();
}

Status TileStoreReader::verifyAll(std::vector<Problem>* problems, size_t max_problems,
                                  const std::function<void(uint64_t, uint64_t)>& progress,
                                  unsigned threads) const {
  const Impl& impl = *m_impl;
  const PyramidGeometry& geometry = impl.info.geometry;
  // Work items are index pages, numbered level by level, row-major, so one
  // atomic counter hands out work roughly in file order. Pages not already
  // loaded are read privately and dropped after use: verifying a huge store
  // holds one page per thread, not the whole index.
  std::vector<uint64_t> level_start(geometry.levels.size() + 1, 0);
  uint64_t total = 0;
  for (size_t l = 0; l < geometry.levels.size(); ++l) {
    level_start[l + 1] = level_start[l] + impl.levels[l].directory.size();
    total += uint64_t(geometry.levels[l].tiles_x) * geometry.levels[l].tiles_y;
  }
  const uint64_t page_total = level_start.back();
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = static_cast<unsigned>(std::min<uint64_t>(threads, page_total));

  std::atomic<uint64_t> next{0};
  std::atomic<uint64_t> done{0};
  std::atomic<uint64_t> failed{0};
  std::mutex problems_mutex;  // guards found and first_failure
  Status first_failure;
  std::vector<Problem> found;

  auto record = [&](const TileKey& key, const Status& status) {
    failed.fetch_add(1);
    std::lock_guard<std::mutex> lock(problems_mutex);
    if (first_failure.ok()) first_failure = status;
    if (found.size() < max_problems) found.push_back({key, status});
  };

  auto worker = [&]() {
    std::vector<uint8_t> pixels(geometry.tileBytes());
    RawTile raw;
    for (;;) {
      const uint64_t item = next.fetch_add(1);
      if (item >= page_total) break;
      uint32_t l = 0;
      while (item >= level_start[l + 1]) ++l;
      const LevelRead& level = impl.levels[l];
      const uint64_t page_index = item - level_start[l];
      const uint32_t px = static_cast<uint32_t>(page_index % level.pages_x);
      const uint32_t py = static_cast<uint32_t>(page_index / level.pages_x);
      const uint32_t w = format::pageSpan(geometry.levels[l].tiles_x, px);
      const uint32_t h = format::pageSpan(geometry.levels[l].tiles_y, py);
      auto keyOf = [&](uint32_t slot) {
        return TileKey{l, px * format::kPageTiles + slot % w, py * format::kPageTiles + slot / w};
      };
      if (level.directory[page_index].flags & format::kPageFlagConstant) {
        done.fetch_add(uint64_t(w) * h);  // checked at open; nothing to read
        continue;
      }
      std::unique_ptr<Page> scratch;
      const Page* page = nullptr;
      const Status page_status = impl.peekPage(l, px, py, &scratch, &page);
      for (uint32_t slot = 0; slot < w * h; ++slot) {
        const TileKey key = keyOf(slot);
        Status status = page_status;
        if (status) {
          impl.entryLocation(l, page->entries[slot], &raw.location);
          status = impl.readPayload(key, &raw);
        }
        if (status) status = decode(raw, pixels);
        if (!status) record(key, status);
      }
      done.fetch_add(uint64_t(w) * h);
    }
  };

  std::function<void()> report;
  if (progress) report = [&] { progress(done.load(), total); };
  runWorkers(threads, worker, report);

  // Report in file order regardless of which worker found what.
  std::sort(found.begin(), found.end(), [](const Problem& a, const Problem& b) {
    return std::tie(a.key.level, a.key.y, a.key.x) < std::tie(b.key.level, b.key.y, b.key.x);
  });
  if (problems != nullptr) *problems = std::move(found);
  if (failed.load() == 0) return okStatus();
  return Status::error(first_failure.code,
                       std::to_string(failed.load()) + " of " + std::to_string(total) +
                           " tiles failed verification in " + m_impl->path);
}

}  // namespace clipstream
