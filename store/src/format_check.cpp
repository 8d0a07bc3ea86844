// The checks between a tile store's fields and regions (format_check.h),
// one function per record, in the order the reader meets the records.
#include "format_check.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace clipstream::format {

namespace {

// a + b <= limit without overflow.
bool fits(uint64_t a, uint64_t b, uint64_t limit) { return a <= limit && b <= limit - a; }

// Bytes above the pixel size in a packed constant value must be zero.
bool valueFits(uint64_t value, size_t bpp) { return bpp >= 8 || (value >> (8 * bpp)) == 0; }

Status callerError(const char* what) { return Status::error(ErrorCode::kInvalidArgument, what); }

// What must hold before any header field is read: the file's size, the
// magic, the version and the header checksum, in the order section 5 gives.
Status checkHeaderFrame(std::span<const uint8_t> prefix, uint64_t actual_bytes) {
  if (actual_bytes < kMagicEndBytes) {
    return Status::error(ErrorCode::kTruncated, "file is " + std::to_string(actual_bytes) +
                                                    " bytes, too short to be a tile store");
  }
  if (prefix.size() != std::min<uint64_t>(actual_bytes, kHeaderBytes)) {
    return callerError("header prefix is not the file's first bytes");
  }
  if (!hasMagic(prefix.data())) {
    return Status::error(ErrorCode::kBadMagic, "not a clipstream tile store (bad magic)");
  }
  if (prefix.size() < kVersionEndBytes) {
    return Status::error(ErrorCode::kTruncated, "file ends inside the header");
  }
  const uint32_t version = decodeVersion(prefix.data());
  if (version < kOldestVersion || version > kVersion) {
    return Status::error(ErrorCode::kBadVersion,
                         "format version " + std::to_string(version) +
                             " (this reader knows versions " + std::to_string(kOldestVersion) +
                             " to " + std::to_string(kVersion) + ")");
  }
  if (prefix.size() < kHeaderBytes) {
    return Status::error(ErrorCode::kTruncated, "file is " + std::to_string(actual_bytes) +
                                                    " bytes, shorter than the " +
                                                    std::to_string(kHeaderBytes) + "-byte header");
  }
  if (!headerChecksumOk(prefix.data())) {
    return Status::error(ErrorCode::kBadHeader, "header checksum mismatch");
  }
  return okStatus();
}

// The file is exactly as long as the header says.
Status checkFileSize(uint64_t file_bytes, uint64_t actual_bytes) {
  if (actual_bytes < file_bytes) {
    return Status::error(ErrorCode::kTruncated, "file is " + std::to_string(actual_bytes) +
                                                    " bytes, the header says " +
                                                    std::to_string(file_bytes));
  }
  if (actual_bytes > file_bytes) {
    return Status::error(ErrorCode::kBadHeader,
                         "file has " + std::to_string(actual_bytes - file_bytes) +
                             " bytes after the end the header records");
  }
  return okStatus();
}

// Every field of a header whose frame passed, and the geometry they give.
Status checkHeaderFields(const Header& header, CheckedHeader* out) {
  if (header.header_bytes != kHeaderBytes) {
    return Status::error(ErrorCode::kBadHeader,
                         "header size field is not " + std::to_string(kHeaderBytes));
  }
  const uint32_t tile_px = header.tile_px;
  if (tile_px < kMinTilePx || tile_px > kMaxTilePx) {
    return Status::error(ErrorCode::kBadHeader,
                         "tile size " + std::to_string(tile_px) + " outside 16..4096");
  }
  const bool v1 = header.format_version == 1;
  if (!isValidPixelFormat(header.pixel_format) ||
      (v1 && !isColourFormat(PixelFormat(header.pixel_format)))) {
    return Status::error(ErrorCode::kUnsupported,
                         "unknown pixel format " + std::to_string(header.pixel_format));
  }
  if (header.compression > 1) {
    return Status::error(ErrorCode::kUnsupported,
                         "unknown compression " + std::to_string(header.compression));
  }
  if (header.predictor > 1) {
    return Status::error(ErrorCode::kUnsupported,
                         "unknown predictor " + std::to_string(header.predictor));
  }
  if (header.filter > (v1 ? 1u : 2u)) {
    return Status::error(ErrorCode::kBadHeader, "unknown filter " + std::to_string(header.filter));
  }
  if ((header.flags & ~(v1 ? kKnownFlagsV1 : kKnownFlags)) != 0) {
    return Status::error(ErrorCode::kBadHeader, "unknown header flags");
  }
  const bool elevation = (header.flags & kFlagElevation) != 0;
  const PixelFormat pixel_format = static_cast<PixelFormat>(header.pixel_format);
  if (elevation ? !isHeightFormat(pixel_format) : !isColourFormat(pixel_format)) {
    return Status::error(ErrorCode::kBadHeader,
                         std::string("pixel format ") + pixelFormatName(pixel_format) +
                             (elevation ? " cannot hold heights"
                                        : " is for elevation stores only"));
  }
  const uint32_t entry_bytes = tileEntryBytes(elevation);
  if (header.page_tiles != kPageTiles || header.tile_entry_bytes != entry_bytes) {
    return Status::error(ErrorCode::kBadHeader, "index page shape is not 64 tiles of " +
                                                    std::to_string(entry_bytes) + " bytes");
  }
  PyramidGeometry geometry;
  if (!makePyramidGeometry(header.width_px, header.height_px, tile_px, pixel_format, &geometry)) {
    return Status::error(ErrorCode::kBadHeader,
                         "image size " + std::to_string(header.width_px) + "x" +
                             std::to_string(header.height_px) + " is not representable");
  }
  if (geometry.levelCount() != header.level_count) {
    return Status::error(ErrorCode::kBadHeader,
                         "level count " + std::to_string(header.level_count) +
                             " does not match the image size (expected " +
                             std::to_string(geometry.levelCount()) + ")");
  }
  out->fields = header;
  out->geometry = geometry;
  out->encoding.compression = static_cast<Compression>(header.compression);
  out->encoding.zstd_level = header.zstd_level;
  out->encoding.predictor = static_cast<Predictor>(header.predictor);
  out->encoding.filter = static_cast<DownsampleFilter>(header.filter);
  out->encoding.linear_light = (header.flags & kFlagLinearLight) != 0;
  out->elevation = elevation;
  out->shard = (header.flags & kFlagShard) != 0;
  out->geo_present = (header.flags & kFlagGeoPresent) != 0;
  out->entry_bytes = entry_bytes;
  out->max_stored_bytes = maxStoredBytes(geometry.tileBytes(), out->encoding.compression);
  return okStatus();
}

// Region layout: payloads, index, level table, metadata, end of file, each
// starting where the previous ends; the metadata block's size in range.
Status checkRegions(const CheckedHeader& checked) {
  const Header& header = checked.fields;
  const uint64_t file_bytes = header.file_bytes;
  const uint64_t table_offset = header.level_table_offset;
  const uint64_t table_bytes = header.level_table_bytes;
  const uint64_t index_offset = header.index_offset;
  const uint64_t index_bytes = header.index_bytes;
  const uint64_t metadata_offset = header.metadata_offset;
  const uint64_t metadata_bytes = header.metadata_bytes;
  if (table_bytes != levelTableBytes(header.level_count)) {
    return Status::error(ErrorCode::kBadHeader, "level table size does not match the level count");
  }
  if (!fits(index_offset, index_bytes, file_bytes) ||
      table_offset != index_offset + index_bytes || !fits(table_offset, table_bytes, file_bytes) ||
      metadata_offset != table_offset + table_bytes ||
      !fits(metadata_offset, metadata_bytes, file_bytes) ||
      metadata_offset + metadata_bytes != file_bytes || index_offset < kHeaderBytes) {
    return Status::error(ErrorCode::kBadHeader, "region offsets in the header are inconsistent");
  }
  if (metadata_bytes < metadataBytes(0, checked.elevation, checked.shard) ||
      metadata_bytes > metadataBytes(kMaxCrsBytes, checked.elevation, checked.shard)) {
    return Status::error(ErrorCode::kBadHeader, "metadata block size out of range");
  }
  return okStatus();
}

// One level table entry against the pyramid rule; `payload_end` is where
// the previous level's payloads end, moved on to where this one's do.
Status checkLevelEntry(const LevelEntry& entry, const LevelInfo& expected, uint32_t level,
                       uint64_t index_offset, uint64_t* payload_end) {
  const std::string where = "level table entry " + std::to_string(level) + ": ";
  if (entry.width_px != expected.width_px || entry.height_px != expected.height_px ||
      entry.tiles_x != expected.tiles_x || entry.tiles_y != expected.tiles_y) {
    return Status::error(ErrorCode::kCorruptIndex, where + "size does not match the pyramid rule");
  }
  if (entry.pages_x != pagesAlong(expected.tiles_x) ||
      entry.pages_y != pagesAlong(expected.tiles_y)) {
    return Status::error(ErrorCode::kCorruptIndex,
                         where + "page grid does not match the tile grid");
  }
  if (entry.payload_offset != *payload_end ||
      !fits(entry.payload_offset, entry.payload_bytes, index_offset)) {
    return Status::error(ErrorCode::kCorruptIndex, where + "payload region out of place");
  }
  *payload_end = entry.payload_offset + entry.payload_bytes;
  const uint64_t page_count = uint64_t(entry.pages_x) * entry.pages_y;
  if (entry.directory_bytes != pageDirectoryBytes(page_count)) {
    return Status::error(ErrorCode::kCorruptIndex, where + "page directory size does not match");
  }
  return okStatus();
}

}  // namespace

Status checkHeader(std::span<const uint8_t> prefix, uint64_t actual_bytes, CheckedHeader* out) {
  Status status = checkHeaderFrame(prefix, actual_bytes);
  if (!status) return status;
  Header header;
  decodeHeader(prefix.data(), &header);
  status = checkFileSize(header.file_bytes, actual_bytes);
  if (!status) return status;
  CheckedHeader checked;
  status = checkHeaderFields(header, &checked);
  if (!status) return status;
  status = checkRegions(checked);
  if (!status) return status;
  *out = std::move(checked);
  return okStatus();
}

Status checkLevelTable(std::span<const uint8_t> table, const CheckedHeader& header,
                       IndexLayout* out) {
  const uint32_t level_count = header.fields.level_count;
  if (table.size() != header.fields.level_table_bytes ||
      header.geometry.levelCount() != level_count) {
    return callerError("level table bytes do not match the checked header");
  }
  IndexLayout layout;
  // Its size was checked against the level count with the header.
  if (decodeLevelTable(table, &layout.levels) != Decoded::kOk) {
    return Status::error(ErrorCode::kCorruptIndex, "level table checksum mismatch");
  }
  const uint64_t index_offset = header.fields.index_offset;
  const uint64_t index_bytes = header.fields.index_bytes;
  uint64_t payload_end = kHeaderBytes;
  uint64_t directories_bytes = 0;
  for (uint32_t l = 0; l < level_count; ++l) {
    Status status = checkLevelEntry(layout.levels[l], header.geometry.levels[l], l, index_offset,
                                    &payload_end);
    if (!status) return status;
    directories_bytes += layout.levels[l].directory_bytes;
  }
  if (payload_end != index_offset) {
    return Status::error(ErrorCode::kCorruptIndex,
                         "payload regions do not end where the index begins");
  }
  // Directories sit back to back at the end of the index region.
  if (directories_bytes > index_bytes) {
    return Status::error(ErrorCode::kCorruptIndex,
                         "page directories larger than the index region");
  }
  layout.pages_begin = index_offset;
  layout.pages_end = index_offset + index_bytes - directories_bytes;
  *out = std::move(layout);
  return okStatus();
}

Status checkDirectoryPlace(const IndexLayout& layout, uint32_t level, uint64_t* offset) {
  if (level >= layout.levels.size()) return callerError("level outside the level table");
  uint64_t expected = layout.pages_end;
  for (uint32_t l = 0; l < level; ++l) expected += layout.levels[l].directory_bytes;
  if (layout.levels[level].directory_offset != expected) {
    return Status::error(ErrorCode::kCorruptIndex, "level table entry " + std::to_string(level) +
                                                       ": page directory out of place");
  }
  *offset = expected;
  return okStatus();
}

Status checkPageDirectory(std::span<const uint8_t> directory, const CheckedHeader& header,
                          const IndexLayout& layout, uint32_t level,
                          std::vector<PageDirEntry>* out) {
  if (level >= layout.levels.size() || level >= header.geometry.levelCount() ||
      layout.levels[level].pages_x != pagesAlong(header.geometry.levels[level].tiles_x) ||
      directory.size() != layout.levels[level].directory_bytes) {
    return callerError("page directory bytes do not match the level table");
  }
  const LevelEntry& level_entry = layout.levels[level];
  const LevelInfo& level_info = header.geometry.levels[level];
  // Its size was checked against the page grid with the level table.
  if (decodePageDirectory(directory, out) != Decoded::kOk) {
    return Status::error(ErrorCode::kCorruptIndex,
                         "page directory of level " + std::to_string(level) +
                             ": checksum mismatch");
  }
  const size_t bpp = bytesPerPixel(header.geometry.format);
  for (size_t i = 0; i < out->size(); ++i) {
    const PageDirEntry& entry = (*out)[i];
    const uint32_t px = static_cast<uint32_t>(i % level_entry.pages_x);
    const uint32_t py = static_cast<uint32_t>(i / level_entry.pages_x);
    const std::string where = "index page (" + std::to_string(px) + ", " + std::to_string(py) +
                              ") of level " + std::to_string(level) + ": ";
    if ((entry.flags & ~kPageFlagConstant) != 0) {
      return Status::error(ErrorCode::kCorruptIndex, where + "unknown flags");
    }
    if (entry.flags & kPageFlagConstant) {
      if (entry.offset != 0 || entry.bytes != 0 || entry.checksum != 0 ||
          !valueFits(entry.constant_value, bpp)) {
        return Status::error(ErrorCode::kCorruptIndex, where + "malformed constant page entry");
      }
      continue;
    }
    const uint64_t tiles =
        uint64_t(pageSpan(level_info.tiles_x, px)) * pageSpan(level_info.tiles_y, py);
    if (entry.bytes != tiles * header.entry_bytes || entry.constant_value != 0 ||
        entry.offset < layout.pages_begin || !fits(entry.offset, entry.bytes, layout.pages_end)) {
      return Status::error(ErrorCode::kCorruptIndex, where + "page location out of bounds");
    }
  }
  return okStatus();
}

Status checkMetadata(std::span<const uint8_t> block, const CheckedHeader& header, StoreInfo* out) {
  if (block.size() != header.fields.metadata_bytes) {
    return callerError("metadata bytes do not match the checked header");
  }
  const bool elevation = header.elevation;
  const bool shard = header.shard;
  switch (decodeMetadata(block, &out->geo, elevation ? &out->elevation : nullptr,
                         shard ? &out->shard : nullptr)) {
    case Decoded::kOk: break;
    case Decoded::kBadChecksum:
      return Status::error(ErrorCode::kBadHeader, "metadata block checksum mismatch");
    case Decoded::kBadSize:
      return Status::error(
          ErrorCode::kBadHeader,
          elevation ? "metadata block: CRS length does not match the block size, or the "
                      "elevation record has unknown flags or units"
          : shard   ? "metadata block: CRS length does not match the block size, or the "
                      "shard record's reserved words are not 0"
                    : "metadata CRS length does not match the block size");
  }
  if (shard) {
    // The band must lie inside the whole image, on its tile grid, and own
    // levels this store has.
    const ShardInfo& sh = out->shard;
    const uint64_t block_px = sh.owned_levels >= 1 && sh.owned_levels <= 32
                                  ? uint64_t(header.fields.tile_px) << (sh.owned_levels - 1)
                                  : 0;
    if (sh.count == 0 || sh.index == 0 || sh.index > sh.count || sh.owned_levels == 0 ||
        sh.owned_levels > header.fields.level_count || block_px == 0 ||
        !fits(sh.x0_px, header.fields.width_px, sh.full_width_px) ||
        !fits(sh.y0_px, header.fields.height_px, sh.full_height_px) || sh.x0_px % block_px != 0 ||
        sh.y0_px % block_px != 0) {
      return Status::error(ErrorCode::kBadHeader,
                           "shard record: shard " + std::to_string(sh.index) + "/" +
                               std::to_string(sh.count) +
                               " does not describe a band of the whole image");
    }
  }
  out->geo.present = header.geo_present;
  if (elevation) {
    const ElevationInfo& e = out->elevation;
    if (!std::isfinite(e.scale) || e.scale <= 0.0 || !std::isfinite(e.offset) ||
        !std::isfinite(e.max_error) || e.max_error < 0.0 || !std::isfinite(e.min_height) ||
        !std::isfinite(e.max_height) || e.min_height > e.max_height) {
      return Status::error(ErrorCode::kBadHeader,
                           "elevation record: scale, offset or bounds out of range");
    }
  }
  return okStatus();
}

Status checkIndexPage(std::span<const uint8_t> page, const CheckedHeader& header, uint32_t level,
                      uint32_t px, uint32_t py, uint64_t checksum, uint64_t payload_bytes,
                      std::vector<TileEntry>* out) {
  if (level >= header.geometry.levelCount() ||
      px >= pagesAlong(header.geometry.levels[level].tiles_x) ||
      py >= pagesAlong(header.geometry.levels[level].tiles_y)) {
    return callerError("index page outside the pyramid");
  }
  const std::string where = "index page (" + std::to_string(px) + ", " + std::to_string(py) +
                            ") of level " + std::to_string(level);
  // Its size was checked against the page's tile count with its directory.
  switch (decodeIndexPage(page, checksum, header.entry_bytes, out)) {
    case Decoded::kOk: break;
    case Decoded::kBadChecksum:
      return Status::error(ErrorCode::kCorruptIndex, where + ": checksum mismatch");
    case Decoded::kBadSize:
      return Status::error(ErrorCode::kCorruptIndex, where + ": malformed entries");
  }
  const uint32_t w = pageSpan(header.geometry.levels[level].tiles_x, px);
  const size_t bpp = bytesPerPixel(header.geometry.format);
  for (size_t i = 0; i < out->size(); ++i) {
    const TileEntry& entry = (*out)[i];
    const bool bounds_ok = !header.elevation ||
                           (std::isfinite(entry.min_height) && std::isfinite(entry.max_height) &&
                            std::isfinite(entry.error) && entry.min_height <= entry.max_height &&
                            entry.error >= 0.0f);
    const bool ok = bounds_ok &&
                    (entry.stored_bytes == 0
                         ? entry.checksum == 0 && valueFits(entry.offset_or_value, bpp)
                         : entry.stored_bytes <= header.max_stored_bytes &&
                               fits(entry.offset_or_value, entry.stored_bytes, payload_bytes));
    if (!ok) {
      const TileKey key{level, px * kPageTiles + uint32_t(i % w),
                        py * kPageTiles + uint32_t(i / w)};
      return Status::error(ErrorCode::kCorruptIndex,
                           where + ": entry for " + keyText(key) + " is out of bounds");
    }
  }
  return okStatus();
}

}  // namespace clipstream::format
