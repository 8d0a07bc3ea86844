// The encoders and decoders of every tile-store record (format.h): the only
// code that knows where a field sits inside a record.
#include "format.h"

#include <xxhash.h>
#include <zstd.h>

namespace clipstream::format {

uint64_t checksum64(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }

size_t maxStoredBytes(size_t tile_bytes, Compression compression) {
  return compression == Compression::kZstd ? ZSTD_compressBound(tile_bytes) : tile_bytes;
}

std::string keyText(const TileKey& key) {
  return "level " + std::to_string(key.level) + " tile (" + std::to_string(key.x) + ", " +
         std::to_string(key.y) + ")";
}

namespace {

// Checksummed blocks: the last kChecksumBytes hold XXH3-64 of the rest.
void sealBlock(std::vector<uint8_t>* block) {
  const size_t body = block->size() - kChecksumBytes;
  put64(block->data() + body, checksum64(block->data(), body));
}

bool blockChecksumOk(std::span<const uint8_t> block) {
  const size_t body = block.size() - kChecksumBytes;
  return get64(block.data() + body) == checksum64(block.data(), body);
}

// A block of whole `entry_bytes` entries followed by a checksum: its entry
// count, or false when the size does not fit that shape.
bool entryCount(std::span<const uint8_t> block, size_t entry_bytes, size_t* count) {
  if (block.size() < kChecksumBytes || (block.size() - kChecksumBytes) % entry_bytes != 0) {
    return false;
  }
  *count = (block.size() - kChecksumBytes) / entry_bytes;
  return true;
}

}  // namespace

// ---- Header ----

void encodeHeader(const Header& h, uint8_t* out) {
  std::memset(out, 0, kHeaderBytes);
  std::memcpy(out + kOffMagic, kMagic, sizeof(kMagic));
  put32(out + kOffVersion, h.format_version);
  put32(out + kOffHeaderBytes, h.header_bytes);
  put64(out + kOffWidth, h.width_px);
  put64(out + kOffHeight, h.height_px);
  put32(out + kOffTilePx, h.tile_px);
  put32(out + kOffPixelFormat, h.pixel_format);
  put32(out + kOffLevelCount, h.level_count);
  put32(out + kOffCompression, h.compression);
  put32(out + kOffZstdLevel, static_cast<uint32_t>(h.zstd_level));
  put32(out + kOffPredictor, h.predictor);
  put32(out + kOffFilter, h.filter);
  put32(out + kOffFlags, h.flags);
  put32(out + kOffPageTiles, h.page_tiles);
  put32(out + kOffEntryBytes, h.tile_entry_bytes);
  put64(out + kOffLevelTableOffset, h.level_table_offset);
  put64(out + kOffLevelTableBytes, h.level_table_bytes);
  put64(out + kOffIndexOffset, h.index_offset);
  put64(out + kOffIndexBytes, h.index_bytes);
  put64(out + kOffMetadataOffset, h.metadata_offset);
  put64(out + kOffMetadataBytes, h.metadata_bytes);
  put64(out + kOffFileBytes, h.file_bytes);
  put64(out + kHeaderChecksumOffset, checksum64(out, kHeaderChecksumOffset));
}

bool hasMagic(const uint8_t* bytes) {
  return std::memcmp(bytes + kOffMagic, kMagic, sizeof(kMagic)) == 0;
}

uint32_t decodeVersion(const uint8_t* bytes) { return get32(bytes + kOffVersion); }

bool headerChecksumOk(const uint8_t* header) {
  return get64(header + kHeaderChecksumOffset) == checksum64(header, kHeaderChecksumOffset);
}

void decodeHeader(const uint8_t* in, Header* h) {
  h->format_version = get32(in + kOffVersion);
  h->header_bytes = get32(in + kOffHeaderBytes);
  h->width_px = get64(in + kOffWidth);
  h->height_px = get64(in + kOffHeight);
  h->tile_px = get32(in + kOffTilePx);
  h->pixel_format = get32(in + kOffPixelFormat);
  h->level_count = get32(in + kOffLevelCount);
  h->compression = get32(in + kOffCompression);
  h->zstd_level = static_cast<int32_t>(get32(in + kOffZstdLevel));
  h->predictor = get32(in + kOffPredictor);
  h->filter = get32(in + kOffFilter);
  h->flags = get32(in + kOffFlags);
  h->page_tiles = get32(in + kOffPageTiles);
  h->tile_entry_bytes = get32(in + kOffEntryBytes);
  h->level_table_offset = get64(in + kOffLevelTableOffset);
  h->level_table_bytes = get64(in + kOffLevelTableBytes);
  h->index_offset = get64(in + kOffIndexOffset);
  h->index_bytes = get64(in + kOffIndexBytes);
  h->metadata_offset = get64(in + kOffMetadataOffset);
  h->metadata_bytes = get64(in + kOffMetadataBytes);
  h->file_bytes = get64(in + kOffFileBytes);
}

// ---- Level table ----

std::vector<uint8_t> encodeLevelTable(std::span<const LevelEntry> levels) {
  std::vector<uint8_t> table(levelTableBytes(levels.size()));
  for (size_t l = 0; l < levels.size(); ++l) {
    uint8_t* p = table.data() + l * kLevelEntryBytes;
    const LevelEntry& e = levels[l];
    put64(p + kLevelOffWidth, e.width_px);
    put64(p + kLevelOffHeight, e.height_px);
    put32(p + kLevelOffTilesX, e.tiles_x);
    put32(p + kLevelOffTilesY, e.tiles_y);
    put32(p + kLevelOffPagesX, e.pages_x);
    put32(p + kLevelOffPagesY, e.pages_y);
    put64(p + kLevelOffPayloadOffset, e.payload_offset);
    put64(p + kLevelOffPayloadBytes, e.payload_bytes);
    put64(p + kLevelOffDirectoryOffset, e.directory_offset);
    put64(p + kLevelOffDirectoryBytes, e.directory_bytes);
  }
  sealBlock(&table);
  return table;
}

Decoded decodeLevelTable(std::span<const uint8_t> table, std::vector<LevelEntry>* out) {
  size_t count = 0;
  if (!entryCount(table, kLevelEntryBytes, &count)) return Decoded::kBadSize;
  if (!blockChecksumOk(table)) return Decoded::kBadChecksum;
  out->resize(count);
  for (size_t l = 0; l < count; ++l) {
    const uint8_t* p = table.data() + l * kLevelEntryBytes;
    LevelEntry& e = (*out)[l];
    e.width_px = get64(p + kLevelOffWidth);
    e.height_px = get64(p + kLevelOffHeight);
    e.tiles_x = get32(p + kLevelOffTilesX);
    e.tiles_y = get32(p + kLevelOffTilesY);
    e.pages_x = get32(p + kLevelOffPagesX);
    e.pages_y = get32(p + kLevelOffPagesY);
    e.payload_offset = get64(p + kLevelOffPayloadOffset);
    e.payload_bytes = get64(p + kLevelOffPayloadBytes);
    e.directory_offset = get64(p + kLevelOffDirectoryOffset);
    e.directory_bytes = get64(p + kLevelOffDirectoryBytes);
  }
  return Decoded::kOk;
}

// ---- Page directory ----

std::vector<uint8_t> encodePageDirectory(std::span<const PageDirEntry> pages) {
  std::vector<uint8_t> directory(pageDirectoryBytes(pages.size()));
  for (size_t i = 0; i < pages.size(); ++i) {
    uint8_t* p = directory.data() + i * kPageEntryBytes;
    const PageDirEntry& e = pages[i];
    put64(p + kPageOffOffset, e.offset);
    put32(p + kPageOffBytes, e.bytes);
    put32(p + kPageOffFlags, e.flags);
    put64(p + kPageOffConstantValue, e.constant_value);
    put64(p + kPageOffChecksum, e.checksum);
  }
  sealBlock(&directory);
  return directory;
}

Decoded decodePageDirectory(std::span<const uint8_t> directory, std::vector<PageDirEntry>* out) {
  size_t count = 0;
  if (!entryCount(directory, kPageEntryBytes, &count)) return Decoded::kBadSize;
  if (!blockChecksumOk(directory)) return Decoded::kBadChecksum;
  out->resize(count);
  for (size_t i = 0; i < count; ++i) {
    const uint8_t* p = directory.data() + i * kPageEntryBytes;
    PageDirEntry& e = (*out)[i];
    e.offset = get64(p + kPageOffOffset);
    e.bytes = get32(p + kPageOffBytes);
    e.flags = get32(p + kPageOffFlags);
    e.constant_value = get64(p + kPageOffConstantValue);
    e.checksum = get64(p + kPageOffChecksum);
  }
  return Decoded::kOk;
}

// ---- Index page ----

uint64_t encodeIndexPage(std::span<const TileEntry> entries, uint32_t entry_bytes,
                         std::vector<uint8_t>* out) {
  out->assign(entries.size() * entry_bytes, 0);
  for (size_t i = 0; i < entries.size(); ++i) {
    uint8_t* p = out->data() + i * entry_bytes;
    put64(p + kTileOffOffsetOrValue, entries[i].offset_or_value);
    put32(p + kTileOffStoredBytes, entries[i].stored_bytes);
    put32(p + kTileOffChecksum, entries[i].checksum);
    if (entry_bytes == kElevationTileEntryBytes) {
      putF32(p + kTileOffMinHeight, entries[i].min_height);
      putF32(p + kTileOffMaxHeight, entries[i].max_height);
      putF32(p + kTileOffError, entries[i].error);
    }
  }
  return checksum64(out->data(), out->size());
}

Decoded decodeIndexPage(std::span<const uint8_t> page, uint64_t checksum, uint32_t entry_bytes,
                        std::vector<TileEntry>* out) {
  if (entry_bytes != kTileEntryBytes && entry_bytes != kElevationTileEntryBytes) {
    return Decoded::kBadSize;
  }
  if (page.size() % entry_bytes != 0) return Decoded::kBadSize;
  if (checksum64(page.data(), page.size()) != checksum) return Decoded::kBadChecksum;
  const size_t count = page.size() / entry_bytes;
  out->resize(count);
  for (size_t i = 0; i < count; ++i) {
    const uint8_t* p = page.data() + i * entry_bytes;
    TileEntry& e = (*out)[i];
    e.offset_or_value = get64(p + kTileOffOffsetOrValue);
    e.stored_bytes = get32(p + kTileOffStoredBytes);
    e.checksum = get32(p + kTileOffChecksum);
    if (entry_bytes == kElevationTileEntryBytes) {
      if (get32(p + kTileOffReserved) != 0) return Decoded::kBadSize;
      e.min_height = getF32(p + kTileOffMinHeight);
      e.max_height = getF32(p + kTileOffMaxHeight);
      e.error = getF32(p + kTileOffError);
    }
  }
  return Decoded::kOk;
}

// ---- Metadata block ----

std::vector<uint8_t> encodeMetadata(const double transform[6], const std::string& crs,
                                    const ElevationInfo* elevation, const ShardInfo* shard) {
  std::vector<uint8_t> block(metadataBytes(crs.size(), elevation != nullptr, shard != nullptr));
  for (size_t i = 0; i < 6; ++i) putF64(block.data() + kMetaOffTransform + 8 * i, transform[i]);
  put32(block.data() + kMetaOffCrsBytes, static_cast<uint32_t>(crs.size()));
  std::memcpy(block.data() + kMetaOffCrs, crs.data(), crs.size());
  if (elevation != nullptr) {
    uint8_t* p = block.data() + kMetaOffCrs + crs.size();
    putF64(p + kElevOffScale, elevation->scale);
    putF64(p + kElevOffOffset, elevation->offset);
    putF64(p + kElevOffNodata, elevation->has_nodata ? elevation->nodata : 0.0);
    put32(p + kElevOffFlags, (elevation->has_nodata ? kElevFlagHasNodata : 0u) |
                                 (elevation->units_assumed ? kElevFlagUnitsAssumed : 0u) |
                                 (elevation->quantised ? kElevFlagQuantised : 0u));
    put32(p + kElevOffUnits, static_cast<uint32_t>(elevation->units));
    put64(p + kElevOffFilled, elevation->filled_samples);
    putF64(p + kElevOffMaxError, elevation->max_error);
    putF64(p + kElevOffMinHeight, elevation->min_height);
    putF64(p + kElevOffMaxHeight, elevation->max_height);
  }
  if (shard != nullptr) {
    uint8_t* p = block.data() + kMetaOffCrs + crs.size() + (elevation ? kElevationRecordBytes : 0);
    put32(p + kShardOffIndex, shard->index);
    put32(p + kShardOffCount, shard->count);
    put64(p + kShardOffFullWidth, shard->full_width_px);
    put64(p + kShardOffFullHeight, shard->full_height_px);
    put64(p + kShardOffX0, shard->x0_px);
    put64(p + kShardOffY0, shard->y0_px);
    put32(p + kShardOffOwnedLevels, shard->owned_levels);
    put32(p + kShardOffReserved0, 0);
    put64(p + kShardOffFingerprint, shard->fingerprint);
    put64(p + kShardOffReserved1, 0);
  }
  sealBlock(&block);
  return block;
}

Decoded decodeMetadata(std::span<const uint8_t> block, GeoReference* out,
                       ElevationInfo* elevation, ShardInfo* shard) {
  if (block.size() < kMetadataFixedBytes) return Decoded::kBadSize;
  if (!blockChecksumOk(block)) return Decoded::kBadChecksum;
  const uint32_t crs_bytes = get32(block.data() + kMetaOffCrsBytes);
  if (metadataBytes(crs_bytes, elevation != nullptr, shard != nullptr) != block.size()) {
    return Decoded::kBadSize;
  }
  for (size_t i = 0; i < 6; ++i) out->transform[i] = getF64(block.data() + kMetaOffTransform + 8 * i);
  out->crs.assign(reinterpret_cast<const char*>(block.data() + kMetaOffCrs), crs_bytes);
  if (elevation != nullptr) {
    const uint8_t* p = block.data() + kMetaOffCrs + crs_bytes;
    const uint32_t flags = get32(p + kElevOffFlags);
    const uint32_t units = get32(p + kElevOffUnits);
    if ((flags & ~kElevKnownFlags) != 0 || !isValidHeightUnits(units)) return Decoded::kBadSize;
    *elevation = ElevationInfo{};
    elevation->present = true;
    elevation->scale = getF64(p + kElevOffScale);
    elevation->offset = getF64(p + kElevOffOffset);
    elevation->has_nodata = (flags & kElevFlagHasNodata) != 0;
    elevation->nodata = getF64(p + kElevOffNodata);
    elevation->units = static_cast<HeightUnits>(units);
    elevation->units_assumed = (flags & kElevFlagUnitsAssumed) != 0;
    elevation->quantised = (flags & kElevFlagQuantised) != 0;
    elevation->filled_samples = get64(p + kElevOffFilled);
    elevation->max_error = getF64(p + kElevOffMaxError);
    elevation->min_height = getF64(p + kElevOffMinHeight);
    elevation->max_height = getF64(p + kElevOffMaxHeight);
  }
  if (shard != nullptr) {
    const uint8_t* p =
        block.data() + kMetaOffCrs + crs_bytes + (elevation ? kElevationRecordBytes : 0);
    if (get32(p + kShardOffReserved0) != 0 || get64(p + kShardOffReserved1) != 0) {
      return Decoded::kBadSize;
    }
    *shard = ShardInfo{};
    shard->present = true;
    shard->index = get32(p + kShardOffIndex);
    shard->count = get32(p + kShardOffCount);
    shard->full_width_px = get64(p + kShardOffFullWidth);
    shard->full_height_px = get64(p + kShardOffFullHeight);
    shard->x0_px = get64(p + kShardOffX0);
    shard->y0_px = get64(p + kShardOffY0);
    shard->owned_levels = get32(p + kShardOffOwnedLevels);
    shard->fingerprint = get64(p + kShardOffFingerprint);
  }
  return Decoded::kOk;
}

}  // namespace clipstream::format
