// What the HTTP store tests share (test_http_store.cpp, test_http_failures.cpp,
// test_http_disk_cache.cpp): the synthetic store they serve and the
// HttpStore fixture, which writes it into a temporary folder and serves it
// from a real nginx on 127.0.0.1 (configuration and logs in that folder).
//
// Thread rule: a fixture and these helpers belong to the test's thread.
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/net.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <utime.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <ctime>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace clipstream::test {

// A store of 57 tiles over 5 levels, about 600 KiB: larger than the first
// request (64 KiB), so tiles and index pages need requests of their own.
inline SyntheticStoreSpec storeSpec() {
  SyntheticStoreSpec spec;
  spec.width_px = 700;
  spec.height_px = 500;
  spec.tile_px = 64;
  spec.format = PixelFormat::kRGBA8;
  spec.constant = ConstantTiles::kSome;
  return spec;
}

// storeSpec()'s store at www/store.cstore (m_local) in a temporary folder,
// served by nginx (m_server) for the length of one test.
class HttpStore : public ::testing::Test {
 protected:
  void SetUp() override {
    std::filesystem::create_directories(m_dir.file("www"));
    m_local = m_dir.file("www/store.cstore");
    ASSERT_TRUE(writeSyntheticStore(m_local, storeSpec()).ok());
    const Status s = NginxServer::start(m_dir.path().string(), m_dir.file("www"), &m_server);
    ASSERT_TRUE(s.ok()) << s.toString();
  }

  // Every tile of `g`, level by level, row by row.
  std::vector<TileKey> allKeys(const PyramidGeometry& g) const {
    std::vector<TileKey> keys;
    for (uint32_t l = 0; l < g.levelCount(); ++l)
      for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
        for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) keys.push_back({l, x, y});
    return keys;
  }

  // Puts a copy of `from` at www/<name> by rename (what a deployment does),
  // with its modification time `seconds_later` than now, so nginx's ETag
  // (mtime and size) changes even when the bytes do not.
  void publish(const std::string& from, const std::string& name, int seconds_later) {
    const std::string tmp = m_dir.file("www/." + name + ".new");
    std::filesystem::copy_file(from, tmp, std::filesystem::copy_options::overwrite_existing);
    utimbuf times{};
    times.actime = times.modtime = ::time(nullptr) + seconds_later;
    ASSERT_EQ(::utime(tmp.c_str(), &times), 0);
    std::filesystem::rename(tmp, m_dir.file("www/" + name));
  }

  TempDir m_dir{"http-store"};
  std::string m_local;
  std::unique_ptr<NginxServer> m_server;
};

// The files of a disk cache folder: entries only, their total size.
struct CacheFolder {
  std::vector<std::string> entries;  // paths of the entry files
  uint64_t bytes = 0;
};
inline CacheFolder cacheFolder(const std::string& dir) {
  CacheFolder folder;
  std::error_code ec;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir, ec)) {
    if (!e.is_regular_file()) continue;
    folder.entries.push_back(e.path().string());
    folder.bytes += e.file_size();
  }
  std::sort(folder.entries.begin(), folder.entries.end());
  return folder;
}

}  // namespace clipstream::test
