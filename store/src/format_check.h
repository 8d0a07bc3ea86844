// Private: the rules between the fields and regions of a tile store
// (docs/tile-store.md sections 5 to 8, 10 and 11), as pure functions over
// bytes already read. format.h decodes each record and checks what the
// record's own bytes say; these check that the decoded values form a store:
// every header field, the region equations, each level table entry against
// the pyramid rule, each page directory and index page entry against its
// region, and the metadata records against the header.
//
// The reader reads, these judge: no file, network or clock is touched, so
// the same checks run in unit tests (tests/store/test_format_check.cpp) and
// under a fuzzer on bare buffers (tests/fuzz/format_check_fuzz.cpp). Called
// in the order below they are the checks TileStoreReader::open() makes, in
// its order; checkIndexPage() is the one it makes on a page's first use.
//
// A failure is a Status whose code and message name the record and the
// problem ("level table entry 2: payload region out of place") but not the
// store: the reader puts its path in front. A caller that breaks a
// precondition written below gets kInvalidArgument, never undefined
// behaviour.
//
// Thread-safe: pure functions over caller-owned buffers.
#pragma once

#include "format.h"

#include <clipstream/store/tile_store.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace clipstream::format {

// A header that passed checkHeader(): its fields and what they mean.
struct CheckedHeader {
  Header fields;               // every field as stored
  PyramidGeometry geometry;    // from the size, tile size and pixel format
  StoreEncoding encoding;      // compression, zstd level, predictor, filter, linear light
  bool elevation = false;      // kFlagElevation: heights, 32-byte tile entries, elevation record
  bool shard = false;          // kFlagShard: a partial store with a shard record
  bool geo_present = false;    // kFlagGeoPresent
  uint32_t entry_bytes = kTileEntryBytes;  // tileEntryBytes(elevation)
  size_t max_stored_bytes = 0;  // largest payload one tile may store (maxStoredBytes())
};

// Checks a header (section 5), in the order the specification gives: size,
// magic, version, checksum, the exact file size, every field, the geometry,
// the region equations and the metadata block's size range.
// `actual_bytes` is the file's size; `prefix` is its first
// min(actual_bytes, kHeaderBytes) bytes, or no bytes at all when
// actual_bytes < kMagicEndBytes (the reader reads nothing then).
// Codes: kTruncated, kBadMagic, kBadVersion, kBadHeader, kUnsupported.
Status checkHeader(std::span<const uint8_t> prefix, uint64_t actual_bytes, CheckedHeader* out);

// The index as the level table lays it out: one entry per level, each
// checked against the pyramid rule and the regions, and the index pages
// region [pages_begin, pages_end) before the page directories.
struct IndexLayout {
  std::vector<LevelEntry> levels;  // level 0 first
  uint64_t pages_begin = 0;
  uint64_t pages_end = 0;
};

// Decodes and checks the level table (section 6): its checksum, each
// entry's size, tile and page grid against `header`'s geometry, the payload
// regions back to back from the header's end to the index, and the page
// directories' sizes, which must fit at the end of the index region.
// `table` is the header's level_table_bytes bytes at level_table_offset.
// Code: kCorruptIndex.
Status checkLevelTable(std::span<const uint8_t> table, const CheckedHeader& header,
                       IndexLayout* out);

// Where level `level`'s page directory must start: right after the index
// pages and the directories of the levels before it. kCorruptIndex when the
// level table puts it anywhere else. Checked before the directory is read.
Status checkDirectoryPlace(const IndexLayout& layout, uint32_t level, uint64_t* offset);

// Decodes and checks level `level`'s page directory (section 7): its
// checksum and, for every page, its flags, a constant page's value, and an
// index page's size and place inside [pages_begin, pages_end).
// `directory` is layout.levels[level].directory_bytes bytes read at the
// offset checkDirectoryPlace() gave. Code: kCorruptIndex.
Status checkPageDirectory(std::span<const uint8_t> directory, const CheckedHeader& header,
                          const IndexLayout& layout, uint32_t level,
                          std::vector<PageDirEntry>* out);

// Decodes and checks the metadata block (section 10) into out->geo,
// out->elevation and out->shard (the other fields of *out are left alone):
// its checksum and length, and the elevation and shard records the header's
// flags announce, against the header. `block` is the header's
// metadata_bytes bytes at metadata_offset. Code: kBadHeader.
Status checkMetadata(std::span<const uint8_t> block, const CheckedHeader& header, StoreInfo* out);

// Decodes and checks index page (px, py) of level `level` (section 8), read
// on first use: its bytes against `checksum` (from its directory entry),
// and every tile entry's payload bounds inside the level's `payload_bytes`,
// a constant entry's value, and an elevation entry's height bounds.
// Code: kCorruptIndex, naming the page and, for a bad entry, the tile.
Status checkIndexPage(std::span<const uint8_t> page, const CheckedHeader& header, uint32_t level,
                      uint32_t px, uint32_t py, uint64_t checksum, uint64_t payload_bytes,
                      std::vector<TileEntry>* out);

}  // namespace clipstream::format
