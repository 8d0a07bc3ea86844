// Shared by the tile-store drivers (store_fuzz, format_check_fuzz): one
// input format, one seed set and one resealer, so a corpus grown by either
// driver seeds the other.
//
// Input: one control byte, then the store bytes. Control bit 0 re-seals the
// mutated bytes (recomputes every checksum it can find and the file size
// field) so mutations reach the checks behind the checksums; without it the
// checksums themselves are attacked.
#pragma once

#include "format.h"
#include "fuzz_util.h"

#include <clipstream/store/tile_store.h>

#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

namespace clipstream::fuzz {

// [offset, offset + bytes) lies inside a buffer of `size` bytes.
inline bool inFile(uint64_t offset, uint64_t bytes, size_t size) {
  return offset <= size && bytes <= size - offset;
}

// Recomputes tile, page, directory, level-table, metadata and header
// checksums wherever the (mutated) offsets still point inside the buffer.
inline void reseal(std::vector<uint8_t>& b) {
  if (b.size() < format::kHeaderBytes) return;
  uint8_t* h = b.data();
  format::put64(h + format::kOffFileBytes, b.size());
  const uint64_t table_offset = format::get64(h + format::kOffLevelTableOffset);
  const uint64_t table_bytes = format::get64(h + format::kOffLevelTableBytes);
  const uint32_t levels = format::get32(h + format::kOffLevelCount);
  // Elevation stores have 32-byte entries; anything else is walked as 16.
  const uint32_t entry_bytes = format::get32(h + format::kOffEntryBytes) ==
                                       format::kElevationTileEntryBytes
                                   ? format::kElevationTileEntryBytes
                                   : format::kTileEntryBytes;
  if (levels <= format::kMaxLevels && table_bytes >= format::kChecksumBytes &&
      inFile(table_offset, table_bytes, b.size())) {
    const uint64_t body = table_bytes - format::kChecksumBytes;
    for (uint64_t l = 0; l < levels && (l + 1) * format::kLevelEntryBytes <= body; ++l) {
      const uint8_t* e = h + table_offset + l * format::kLevelEntryBytes;
      const uint64_t payload_offset = format::get64(e + 32);
      const uint64_t dir_offset = format::get64(e + 48);
      const uint64_t dir_bytes = format::get64(e + 56);
      if (dir_bytes < format::kChecksumBytes || !inFile(dir_offset, dir_bytes, b.size())) continue;
      const uint64_t dir_body = dir_bytes - format::kChecksumBytes;
      for (uint64_t p = 0; p + format::kPageEntryBytes <= dir_body; p += format::kPageEntryBytes) {
        uint8_t* d = h + dir_offset + p;
        const uint64_t page_offset = format::get64(d);
        const uint32_t page_bytes = format::get32(d + 8);
        if (!inFile(page_offset, page_bytes, b.size())) continue;
        for (uint32_t t = 0; t + entry_bytes <= page_bytes; t += entry_bytes) {
          uint8_t* te = h + page_offset + t;
          const uint64_t rel = format::get64(te);
          const uint32_t stored = format::get32(te + 8);
          if (stored == 0 || rel > UINT64_MAX - payload_offset ||
              !inFile(payload_offset + rel, stored, b.size())) {
            continue;
          }
          format::put32(te + 12, format::tileChecksum(h + payload_offset + rel, stored));
        }
        format::put64(d + 24, format::checksum64(h + page_offset, page_bytes));
      }
      format::put64(h + dir_offset + dir_body, format::checksum64(h + dir_offset, dir_body));
    }
    format::put64(h + table_offset + body, format::checksum64(h + table_offset, body));
  }
  const uint64_t meta_offset = format::get64(h + format::kOffMetadataOffset);
  const uint64_t meta_bytes = format::get64(h + format::kOffMetadataBytes);
  if (meta_bytes >= format::kChecksumBytes && inFile(meta_offset, meta_bytes, b.size())) {
    const uint64_t body = meta_bytes - format::kChecksumBytes;
    format::put64(h + meta_offset + body, format::checksum64(h + meta_offset, body));
  }
  format::put64(h + format::kHeaderChecksumOffset,
                format::checksum64(h, format::kHeaderChecksumOffset));
}

// Small stores covering every structure: edge pages, constant tiles and
// pages, every pixel format, both compressions, a georeference, and
// elevation stores (their record and 32-byte entries).
inline void writeSeeds(const std::string& dir) {
  struct Seed {
    uint64_t w, h;
    uint32_t tile;
    PixelFormat format;
    Compression compression;
    Predictor predictor;
  };
  const Seed seeds[] = {
      {150, 70, 16, PixelFormat::kRGB8, Compression::kZstd, Predictor::kLeftDelta},
      {40, 33, 16, PixelFormat::kR16, Compression::kNone, Predictor::kLeftDelta},
      {70, 20, 16, PixelFormat::kRGBA8, Compression::kZstd, Predictor::kNone},
      {16, 16, 16, PixelFormat::kR8, Compression::kNone, Predictor::kNone},
      {100, 60, 16, PixelFormat::kI16, Compression::kZstd, Predictor::kLeftDelta},
      {50, 40, 16, PixelFormat::kF32, Compression::kNone, Predictor::kLeftDelta},
  };
  int n = 0;
  for (const Seed& s : seeds) {
    PyramidGeometry g;
    if (!makePyramidGeometry(s.w, s.h, s.tile, s.format, &g)) std::abort();
    WriterOptions options;
    options.fsync = false;
    options.replace = true;
    options.encoding.compression = s.compression;
    options.encoding.predictor = s.predictor;
    options.geo.present = (n % 2) == 0;
    options.geo.crs = "EPSG:2992";
    if (n == 2) {
      // A partial store: the shard record's checks get fuzzed too.
      options.shard.present = true;
      options.shard.index = 1;
      options.shard.count = 2;
      options.shard.full_width_px = s.w;
      options.shard.full_height_px = s.h * 2;
      options.shard.owned_levels = 1;
      options.shard.fingerprint = 42;
    }
    if (!isColourFormat(s.format)) {
      options.encoding.filter = DownsampleFilter::kDecimate;
      options.elevation.present = true;
      options.elevation.has_nodata = true;
      options.elevation.nodata = -32768;
    }
    const std::string path = dir + "/seed" + std::to_string(n) + ".store";
    std::unique_ptr<TileStoreWriter> writer;
    if (!TileStoreWriter::create(path, g, options, &writer)) std::abort();
    const size_t bpp = bytesPerPixel(g.format);
    for (uint32_t l = 0; l < g.levelCount(); ++l) {
      for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
        for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
          std::vector<uint8_t> pixels(g.tileBytes());
          const bool constant = (x + y + l) % 3 == 0;
          for (size_t i = 0; i < pixels.size(); ++i) {
            pixels[i] = uint8_t(constant ? (i % bpp) * 50 + l : i * 7 + x * 13 + y * 29 + l);
          }
          EncodedTile encoded;
          if (!encodeTile(g, options.encoding, {l, x, y}, pixels, &encoded)) std::abort();
          if (options.elevation.present && !(constant && l == 0)) {
            encoded.location.min_height = -float(l);
            encoded.location.max_height = float(x + y);
            encoded.location.error = float(l);
          } else if (options.elevation.present) {
            // Flat constant tiles: bounds are the value's height (a constant page).
            encoded.location.min_height = encoded.location.max_height =
                float(heightOfSample(g.format, options.elevation, encoded.location.constant_pixel));
          }
          if (!writer->write(std::move(encoded))) {
            std::abort();
          }
        }
      }
    }
    if (!writer->finish()) std::abort();
    std::vector<uint8_t> bytes(1, 0);
    const std::vector<uint8_t> store = fuzz::readFile(path);
    bytes.insert(bytes.end(), store.begin(), store.end());
    ::unlink(path.c_str());
    for (uint8_t control : {0, 1}) {
      bytes[0] = control;
      writeFile(dir + "/seed" + std::to_string(n) + "_" + std::to_string(control), bytes.data(), bytes.size());
    }
    ++n;
  }
}

}  // namespace clipstream::fuzz
