// Private: the byte layout of a tile store file, shared by reader.cpp and
// writer.cpp only. docs/tile-store.md is the specification; every constant
// and offset here must match it.
#pragma once

#include <clipstream/store/tile_store.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <string>

namespace clipstream::format {

static_assert(std::endian::native == std::endian::little,
              "the store codec assumes a little-endian host");

constexpr char kMagic[8] = {'C', 'L', 'I', 'P', 'T', 'I', 'L', 'E'};
constexpr uint32_t kVersion = 1;

// Header: fixed size, followed immediately by level 0's payloads.
constexpr uint32_t kHeaderBytes = 136;
constexpr uint32_t kHeaderChecksumOffset = 128;  // XXH3-64 of bytes [0, 128)

// Header field offsets.
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

constexpr uint32_t kFlagLinearLight = 1u << 0;
constexpr uint32_t kFlagGeoPresent = 1u << 1;
constexpr uint32_t kKnownFlags = kFlagLinearLight | kFlagGeoPresent;

// Tiles per index page side: a page holds up to 64 x 64 entries (64 KiB),
// small enough to read on demand, large enough that the page directory of a
// 1,048,576^2 texture stays under 1 MiB.
constexpr uint32_t kPageTiles = 64;

constexpr uint32_t kMinTilePx = 16;
constexpr uint32_t kMaxTilePx = 4096;
constexpr uint32_t kMaxLevels = 64;
constexpr uint32_t kMaxCrsBytes = 1u << 20;

// Level table entry, one per level, then an XXH3-64 of all entries.
constexpr uint32_t kLevelEntryBytes = 64;
// Page directory entry, one per page of a level, then an XXH3-64.
constexpr uint32_t kPageEntryBytes = 32;
constexpr uint32_t kPageFlagConstant = 1u << 0;
// Tile entry inside an index page.
constexpr uint32_t kTileEntryBytes = 16;
// Metadata block: 6 f64 transform, u32 CRS length, CRS bytes, XXH3-64.
constexpr uint32_t kMetadataFixedBytes = 48 + 4 + 8;

constexpr uint32_t kChecksumBytes = 8;

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

// 64-bit checksum used for header, level table, directories, pages and
// metadata; tile payloads use its low 32 bits.
uint64_t checksum64(const void* data, size_t bytes);
inline uint32_t tileChecksum(const void* data, size_t bytes) {
  return static_cast<uint32_t>(checksum64(data, bytes));
}

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

