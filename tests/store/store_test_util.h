// Helpers shared by the store tests: synthetic tiles whose pixels encode
// (level, x, y), and a one-call store writer.
#pragma once

#include <clipstream/store/tile_store.h>

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

namespace clipstream::testutil {

// Every byte is a function of (key, pixel, channel), so any mixed-up tile
// or pixel shows. Tiles where pattern says "constant" are one value whose
// bytes also derive from the key.
inline bool isConstantTile(const TileKey& key) { return (key.x * 7 + key.y * 3 + key.level) % 5 == 0; }

inline std::vector<uint8_t> makeTile(const PyramidGeometry& g, const TileKey& key,
                                     bool allow_constant = true) {
  const uint32_t bpp = bytesPerPixel(g.format);
  std::vector<uint8_t> pixels(g.tileBytes());
  const bool constant = allow_constant && isConstantTile(key);
  for (uint32_t py = 0; py < g.tile_px; ++py) {
    for (uint32_t px = 0; px < g.tile_px; ++px) {
      for (uint32_t c = 0; c < bpp; ++c) {
        uint32_t v = constant ? key.level * 41 + key.x * 13 + key.y * 29 + c * 53
                              : key.level * 41 + key.x * 13 + key.y * 29 + px * 3 + py * 5 +
                                    c * 53 + ((px * py) >> 4);
        pixels[(size_t(py) * g.tile_px + px) * bpp + c] = uint8_t(v ^ (v >> 8));
      }
    }
  }
  return pixels;
}

inline std::filesystem::path tempDir(const std::string& name) {
  auto dir = std::filesystem::temp_directory_path() /
             ("clipstream_store_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// Writes every tile of `g` with makeTile(); returns the finish() status.
inline Status writeStore(const std::string& path, const PyramidGeometry& g,
                         const WriterOptions& options = {}, bool allow_constant = true) {
  std::unique_ptr<TileStoreWriter> writer;
  Status status = TileStoreWriter::create(path, g, options, &writer);
  if (!status) return status;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        EncodedTile encoded;
        status = encodeTile(g, options.encoding, key, makeTile(g, key, allow_constant), &encoded);
        if (!status) return status;
        status = writer->write(std::move(encoded));
        if (!status) return status;
      }
    }
  }
  return writer->finish();
}

inline std::vector<uint8_t> readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), {});
}

inline void writeFile(const std::string& path, const std::vector<uint8_t>& bytes, size_t count) {
  // Unlink first: truncating an existing file makes ext4 flush it on close
  // (auto_da_alloc), which turns thousands of rewrites into seconds of I/O.
  std::filesystem::remove(path);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(count));
}

inline std::vector<std::string> listDir(const std::filesystem::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    names.push_back(entry.path().filename().string());
  }
  return names;
}

}  // namespace clipstream::testutil
