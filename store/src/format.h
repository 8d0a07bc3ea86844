// Private: the byte layout of a tile store file and the one encoder and
// decoder of each record (format.cpp). reader.cpp and writer.cpp go through
// these and never touch a field offset themselves. docs/tile-store.md is the
// specification; every constant and offset here must match it (tests/store/
// test_format.cpp checks a real store's bytes against the documented table).
//
// Thread-safe: constants and pure functions over caller-owned buffers.
#pragma once

#include <clipstream/store/tile_store.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

namespace clipstream::format {

static_assert(std::endian::native == std::endian::little,
              "the store codec assumes a little-endian host");

constexpr char kMagic[8] = {'C', 'L', 'I', 'P', 'T', 'I', 'L', 'E'};
// Version 2 added elevation stores (the elevation flag, 32-byte tile
// entries with height bounds, the elevation record in the metadata block,
// pixel formats I16 and F32, the decimate filter). Version 1 stores (colour
// only) are still read; writers write version 2.
constexpr uint32_t kVersion = 2;
constexpr uint32_t kOldestVersion = 1;

// Header: fixed size, followed immediately by level 0's payloads.
constexpr uint32_t kHeaderBytes = 136;
constexpr uint32_t kHeaderChecksumOffset = 128;  // XXH3-64 of bytes [0, 128)

// Header field offsets (docs/tile-store.md section 5).
constexpr size_t kOffMagic = 0;
constexpr size_t kOffVersion = 8;
constexpr size_t kOffHeaderBytes = 12;
constexpr size_t kOffWidth = 16;
constexpr size_t kOffHeight = 24;
constexpr size_t kOffTilePx = 32;
constexpr size_t kOffPixelFormat = 36;
constexpr size_t kOffLevelCount = 40;
constexpr size_t kOffCompression = 44;
constexpr size_t kOffZstdLevel = 48;
constexpr size_t kOffPredictor = 52;
constexpr size_t kOffFilter = 56;
constexpr size_t kOffFlags = 60;
constexpr size_t kOffPageTiles = 64;
constexpr size_t kOffEntryBytes = 68;
constexpr size_t kOffLevelTableOffset = 72;
constexpr size_t kOffLevelTableBytes = 80;
constexpr size_t kOffIndexOffset = 88;
constexpr size_t kOffIndexBytes = 96;
constexpr size_t kOffMetadataOffset = 104;
constexpr size_t kOffMetadataBytes = 112;
constexpr size_t kOffFileBytes = 120;
static_assert(kOffFileBytes + 8 == kHeaderChecksumOffset && kHeaderChecksumOffset + 8 == kHeaderBytes);

// A reader needs this many bytes to check the magic, and this many to read
// the version (checked before the header checksum, section 5).
constexpr size_t kMagicEndBytes = kOffMagic + sizeof(kMagic);
constexpr size_t kVersionEndBytes = kOffVersion + 4;

constexpr uint32_t kFlagLinearLight = 1u << 0;
constexpr uint32_t kFlagGeoPresent = 1u << 1;
constexpr uint32_t kFlagElevation = 1u << 2;  // version 2
// A partial store, one shard of a sharded tiler run (version 2; readers
// that predate it refuse the store as having unknown flags, so a shard is
// never mistaken for a whole store). The shard record follows.
constexpr uint32_t kFlagShard = 1u << 3;
constexpr uint32_t kKnownFlagsV1 = kFlagLinearLight | kFlagGeoPresent;
constexpr uint32_t kKnownFlags = kKnownFlagsV1 | kFlagElevation | kFlagShard;

// Tiles per index page side: a page holds up to 64 x 64 entries (64 KiB),
// small enough to read on demand, large enough that the page directory of a
// 1,048,576^2 texture stays under 1 MiB.
constexpr uint32_t kPageTiles = 64;

constexpr uint32_t kMinTilePx = 16;
constexpr uint32_t kMaxTilePx = 4096;
constexpr uint32_t kMaxLevels = 64;
constexpr uint32_t kMaxCrsBytes = 1u << 20;

// Checksummed blocks (level table, page directories, metadata) end in an
// XXH3-64 of everything before it.
constexpr uint32_t kChecksumBytes = 8;

// Level table entry, one per level (section 6), then the checksum.
constexpr uint32_t kLevelEntryBytes = 64;
constexpr size_t kLevelOffWidth = 0;
constexpr size_t kLevelOffHeight = 8;
constexpr size_t kLevelOffTilesX = 16;
constexpr size_t kLevelOffTilesY = 20;
constexpr size_t kLevelOffPagesX = 24;
constexpr size_t kLevelOffPagesY = 28;
constexpr size_t kLevelOffPayloadOffset = 32;
constexpr size_t kLevelOffPayloadBytes = 40;
constexpr size_t kLevelOffDirectoryOffset = 48;
constexpr size_t kLevelOffDirectoryBytes = 56;
static_assert(kLevelOffDirectoryBytes + 8 == kLevelEntryBytes);

// Page directory entry, one per page of a level (section 7), then the checksum.
constexpr uint32_t kPageEntryBytes = 32;
constexpr size_t kPageOffOffset = 0;
constexpr size_t kPageOffBytes = 8;
constexpr size_t kPageOffFlags = 12;
constexpr size_t kPageOffConstantValue = 16;
constexpr size_t kPageOffChecksum = 24;
static_assert(kPageOffChecksum + 8 == kPageEntryBytes);
constexpr uint32_t kPageFlagConstant = 1u << 0;

// Tile entry inside an index page (section 8); the page has no checksum of
// its own, its directory entry carries it. Elevation stores append the
// tile's height bounds and geometric error (f32, in height units) and a
// reserved zero word.
constexpr uint32_t kTileEntryBytes = 16;
constexpr size_t kTileOffOffsetOrValue = 0;
constexpr size_t kTileOffStoredBytes = 8;
constexpr size_t kTileOffChecksum = 12;
static_assert(kTileOffChecksum + 4 == kTileEntryBytes);
constexpr uint32_t kElevationTileEntryBytes = 32;
constexpr size_t kTileOffMinHeight = 16;
constexpr size_t kTileOffMaxHeight = 20;
constexpr size_t kTileOffError = 24;
constexpr size_t kTileOffReserved = 28;
static_assert(kTileOffReserved + 4 == kElevationTileEntryBytes);
inline uint32_t tileEntryBytes(bool elevation) {
  return elevation ? kElevationTileEntryBytes : kTileEntryBytes;
}

// Metadata block (section 10): 6 f64 transform, u32 CRS length, CRS bytes,
// then the checksum.
constexpr size_t kMetaOffTransform = 0;
constexpr size_t kMetaOffCrsBytes = 48;
constexpr size_t kMetaOffCrs = 52;
constexpr uint32_t kMetadataFixedBytes = kMetaOffCrs + kChecksumBytes;
// Elevation record (version 2, elevation stores only): follows the CRS
// bytes, before the checksum. Offsets are relative to the record.
constexpr uint32_t kElevationRecordBytes = 64;
constexpr size_t kElevOffScale = 0;         // f64: height = offset + scale * sample
constexpr size_t kElevOffOffset = 8;        // f64
constexpr size_t kElevOffNodata = 16;       // f64: the input's no-data value
constexpr size_t kElevOffFlags = 24;        // u32: kElevFlag*
constexpr size_t kElevOffUnits = 28;        // u32: HeightUnits
constexpr size_t kElevOffFilled = 32;       // u64: level-0 samples filled
constexpr size_t kElevOffMaxError = 40;     // f64: largest |stored - input| at level 0
constexpr size_t kElevOffMinHeight = 48;    // f64: lowest stored height
constexpr size_t kElevOffMaxHeight = 56;    // f64: highest stored height
static_assert(kElevOffMaxHeight + 8 == kElevationRecordBytes);
// Shard record (partial stores only): follows the elevation record, or the
// CRS bytes when there is none, before the checksum. Offsets relative to it.
constexpr uint32_t kShardRecordBytes = 64;
constexpr size_t kShardOffIndex = 0;         // u32: this shard, 1..count
constexpr size_t kShardOffCount = 4;         // u32: shards of the run
constexpr size_t kShardOffFullWidth = 8;     // u64: level-0 size of the whole image
constexpr size_t kShardOffFullHeight = 16;   // u64
constexpr size_t kShardOffX0 = 24;           // u64: this store's level-0 origin in it
constexpr size_t kShardOffY0 = 32;           // u64
constexpr size_t kShardOffOwnedLevels = 40;  // u32: levels 0..owned-1 are the whole store's tiles
constexpr size_t kShardOffReserved0 = 44;    // u32: 0
constexpr size_t kShardOffFingerprint = 48;  // u64: input and options of the run
constexpr size_t kShardOffReserved1 = 56;    // u64: 0
static_assert(kShardOffReserved1 + 8 == kShardRecordBytes);
constexpr uint32_t kElevFlagHasNodata = 1u << 0;
constexpr uint32_t kElevFlagUnitsAssumed = 1u << 1;
constexpr uint32_t kElevFlagQuantised = 1u << 2;
constexpr uint32_t kElevKnownFlags = kElevFlagHasNodata | kElevFlagUnitsAssumed | kElevFlagQuantised;

inline void put32(uint8_t* p, uint32_t v) { std::memcpy(p, &v, 4); }
inline void put64(uint8_t* p, uint64_t v) { std::memcpy(p, &v, 8); }
inline void putF64(uint8_t* p, double v) { std::memcpy(p, &v, 8); }
inline uint32_t get32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}
inline uint64_t get64(const uint8_t* p) {
  uint64_t v;
  std::memcpy(&v, p, 8);
  return v;
}
inline double getF64(const uint8_t* p) {
  double v;
  std::memcpy(&v, p, 8);
  return v;
}
inline void putF32(uint8_t* p, float v) { std::memcpy(p, &v, 4); }
inline float getF32(const uint8_t* p) {
  float v;
  std::memcpy(&v, p, 4);
  return v;
}

// 64-bit checksum used for header, level table, directories, pages and
// metadata; tile payloads use its low 32 bits.
uint64_t checksum64(const void* data, size_t bytes);
inline uint32_t tileChecksum(const void* data, size_t bytes) {
  return static_cast<uint32_t>(checksum64(data, bytes));
}

// ---- Records ----
// Each record has one encoder and one decoder. Decoders check only what the
// bytes themselves say (checksums, sizes); the rules between fields and
// regions are format_check.h's (section 11), which the reader calls. Every
// field is the raw stored value.

// The header fields after the magic, as stored.
struct Header {
  uint32_t format_version = kVersion;
  uint32_t header_bytes = kHeaderBytes;
  uint64_t width_px = 0;
  uint64_t height_px = 0;
  uint32_t tile_px = 0;
  uint32_t pixel_format = 0;
  uint32_t level_count = 0;
  uint32_t compression = 0;
  int32_t zstd_level = 0;
  uint32_t predictor = 0;
  uint32_t filter = 0;
  uint32_t flags = 0;
  uint32_t page_tiles = kPageTiles;
  uint32_t tile_entry_bytes = kTileEntryBytes;
  uint64_t level_table_offset = 0;
  uint64_t level_table_bytes = 0;
  uint64_t index_offset = 0;
  uint64_t index_bytes = 0;
  uint64_t metadata_offset = 0;
  uint64_t metadata_bytes = 0;
  uint64_t file_bytes = 0;

  friend bool operator==(const Header&, const Header&) = default;
};

// Writes the kHeaderBytes-byte header to `out`: magic, every field, checksum.
void encodeHeader(const Header& header, uint8_t* out);
// The checks a reader makes before trusting anything else, in the order
// section 5 gives: the magic (needs kMagicEndBytes bytes), the version
// (needs kVersionEndBytes), the checksum (needs kHeaderBytes).
bool hasMagic(const uint8_t* bytes);
uint32_t decodeVersion(const uint8_t* bytes);
bool headerChecksumOk(const uint8_t* header);
// Reads every field of a kHeaderBytes-byte header (no check of any value).
void decodeHeader(const uint8_t* header, Header* out);

// What a decoder of a checksummed block found.
enum class Decoded {
  kOk,
  kBadChecksum,  // the stored checksum does not match the bytes
  kBadSize,      // the block's size does not fit its own fields
};

struct LevelEntry {
  uint64_t width_px = 0;
  uint64_t height_px = 0;
  uint32_t tiles_x = 0;
  uint32_t tiles_y = 0;
  uint32_t pages_x = 0;
  uint32_t pages_y = 0;
  uint64_t payload_offset = 0;    // absolute
  uint64_t payload_bytes = 0;
  uint64_t directory_offset = 0;  // absolute
  uint64_t directory_bytes = 0;

  friend bool operator==(const LevelEntry&, const LevelEntry&) = default;
};

// Size of the level table for `level_count` levels: entries plus checksum.
inline uint64_t levelTableBytes(uint64_t level_count) {
  return level_count * kLevelEntryBytes + kChecksumBytes;
}
// The whole level table: entries, level 0 first, then their checksum.
std::vector<uint8_t> encodeLevelTable(std::span<const LevelEntry> levels);
// kBadSize unless the table is N entries plus a checksum.
Decoded decodeLevelTable(std::span<const uint8_t> table, std::vector<LevelEntry>* out);

struct PageDirEntry {
  uint64_t offset = 0;  // absolute offset of the index page; 0 for a constant page
  uint32_t bytes = 0;
  uint32_t flags = 0;   // kPageFlagConstant
  uint64_t constant_value = 0;
  uint64_t checksum = 0;  // of the index page's bytes

  friend bool operator==(const PageDirEntry&, const PageDirEntry&) = default;
};

inline uint64_t pageDirectoryBytes(uint64_t page_count) {
  return page_count * kPageEntryBytes + kChecksumBytes;
}
// One level's page directory: entries row-major by page, then their checksum.
std::vector<uint8_t> encodePageDirectory(std::span<const PageDirEntry> pages);
// kBadSize unless the directory is N entries plus a checksum.
Decoded decodePageDirectory(std::span<const uint8_t> directory, std::vector<PageDirEntry>* out);

// A tile's index entry: stored_bytes 0 is a constant tile whose value (the
// first bpp bytes, rest 0) is in offset_or_value; otherwise offset_or_value
// is relative to the level's payload region. The height fields exist in
// elevation stores only (0 elsewhere).
struct TileEntry {
  uint64_t offset_or_value = 0;
  uint32_t stored_bytes = 0;
  uint32_t checksum = 0;  // checksum32 of the stored payload; 0 when constant
  float min_height = 0.0f;
  float max_height = 0.0f;
  float error = 0.0f;

  friend bool operator==(const TileEntry&, const TileEntry&) = default;
};

// One index page: entries row-major inside the page, each `entry_bytes`
// (tileEntryBytes()). Returns the page's checksum, which goes in its
// directory entry.
uint64_t encodeIndexPage(std::span<const TileEntry> entries, uint32_t entry_bytes,
                         std::vector<uint8_t>* out);
// kBadChecksum when the bytes do not match `checksum` (from the directory),
// kBadSize unless they are whole entries (a non-zero reserved word of an
// elevation entry is kBadSize too).
Decoded decodeIndexPage(std::span<const uint8_t> page, uint64_t checksum, uint32_t entry_bytes,
                        std::vector<TileEntry>* out);

inline uint64_t metadataBytes(uint64_t crs_bytes, bool elevation = false, bool shard = false) {
  return kMetadataFixedBytes + crs_bytes + (elevation ? kElevationRecordBytes : 0) +
         (shard ? kShardRecordBytes : 0);
}
// The metadata block of `transform` and `crs` (at most kMaxCrsBytes; the
// caller checks), then the elevation record when `elevation` is given, then
// the shard record when `shard` is given, checksum included.
std::vector<uint8_t> encodeMetadata(const double transform[6], const std::string& crs,
                                    const ElevationInfo* elevation = nullptr,
                                    const ShardInfo* shard = nullptr);
// Fills transform and crs (not `present`: that is a header flag), and
// *elevation / *shard when not null (the header flags say the records are
// there). kBadSize when the block is shorter than kMetadataFixedBytes or its
// CRS length (plus the records) does not match its size, or the elevation
// record has unknown flags or units, or a reserved word of the shard record
// is not 0. The shard record's values are the reader's to check.
Decoded decodeMetadata(std::span<const uint8_t> block, GeoReference* out,
                       ElevationInfo* elevation = nullptr, ShardInfo* shard = nullptr);

// ---- Geometry helpers ----

// Largest stored payload a reader accepts for one tile: the zstd bound of a
// raw tile (or the raw size when uncompressed).
size_t maxStoredBytes(size_t tile_bytes, Compression compression);

// Number of tiles covered by page (px, py) of a level (edge pages are
// clipped to the level's tile grid).
// Computed in 64 bits: tiles_x may be as large as 2^32 - 1, where the 32-bit
// sum tiles + 63 would wrap to a page count of 0.
inline uint32_t pagesAlong(uint32_t tiles) {
  return static_cast<uint32_t>((uint64_t(tiles) + kPageTiles - 1) / kPageTiles);
}
inline uint32_t pageSpan(uint32_t tiles, uint32_t page) {
  const uint32_t begin = page * kPageTiles;
  const uint32_t end = std::min<uint64_t>(uint64_t(begin) + kPageTiles, tiles);
  return end - begin;
}

// Key text used in messages: "level 3 tile (4, 7)".
std::string keyText(const TileKey& key);

}  // namespace clipstream::format
