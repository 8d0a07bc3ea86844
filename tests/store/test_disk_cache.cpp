// DiskCache on its own (the HTTP tests use it through a real server): what
// it keeps, what it evicts, what it drops, and what it never touches.
#include "disk_cache.h"

#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <numeric>
#include <vector>

namespace clipstream {
namespace {

namespace fs = std::filesystem;

std::vector<uint8_t> bytesOf(size_t n, uint8_t first) {
  std::vector<uint8_t> v(n);
  std::iota(v.begin(), v.end(), first);
  return v;
}

void writeFile(const fs::path& path, const std::vector<uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

class DiskCacheTest : public ::testing::Test {
 protected:
  // A cache of `entries` entries of kContent bytes (each with its header).
  void open(uint64_t entries) {
    ASSERT_TRUE(DiskCache::open(m_dir.file("cache"), entries * (kContent + 24), &m_cache).ok());
    ASSERT_TRUE(m_cache->usableStoreDir(m_key));
  }
  DiskCache::Lookup get(const std::string& name, std::vector<uint8_t>* out = nullptr) {
    std::vector<uint8_t> ignored;
    return m_cache->get(m_key, name, kContent, out != nullptr ? out : &ignored);
  }
  fs::path entry(const std::string& name) const { return fs::path(m_dir.file("cache")) / m_key / name; }

  static constexpr size_t kContent = 1000;
  test::TempDir m_dir{"disk_cache"};
  const std::string m_key = DiskCache::storeKey("http://127.0.0.1/a.cstore", "\"v1\"");
  std::shared_ptr<DiskCache> m_cache;
};

TEST_F(DiskCacheTest, GivesBackWhatItWasGivenAndMissesTheRest) {
  open(4);
  const std::vector<uint8_t> tile = bytesOf(kContent, 7);
  m_cache->put(m_key, "t0-1-2", tile);
  std::vector<uint8_t> got;
  EXPECT_EQ(get("t0-1-2", &got), DiskCache::Lookup::kHit);
  EXPECT_EQ(got, tile);
  EXPECT_EQ(get("t0-2-1"), DiskCache::Lookup::kMiss);
  // Another version of the same URL is another store.
  EXPECT_NE(DiskCache::storeKey("http://127.0.0.1/a.cstore", "\"v2\""), m_key);
  EXPECT_EQ(m_cache->stats().entries, 1u);
  EXPECT_EQ(m_cache->stats().bytes, kContent + 24);
}

TEST_F(DiskCacheTest, KeepsItsCapByEvictingTheLeastRecentlyUsed) {
  open(3);
  m_cache->put(m_key, "t0-0-0", bytesOf(kContent, 0));
  m_cache->put(m_key, "t0-0-1", bytesOf(kContent, 1));
  m_cache->put(m_key, "t0-0-2", bytesOf(kContent, 2));
  ASSERT_EQ(get("t0-0-0"), DiskCache::Lookup::kHit);  // now the most recent
  m_cache->put(m_key, "t0-0-3", bytesOf(kContent, 3));
  EXPECT_EQ(m_cache->stats().evictions, 1u);
  EXPECT_EQ(m_cache->stats().entries, 3u);
  EXPECT_LE(m_cache->stats().bytes, m_cache->capBytes());
  EXPECT_EQ(get("t0-0-1"), DiskCache::Lookup::kMiss);  // the least recently used
  EXPECT_FALSE(fs::exists(entry("t0-0-1")));
  EXPECT_EQ(get("t0-0-0"), DiskCache::Lookup::kHit);
  EXPECT_EQ(get("t0-0-3"), DiskCache::Lookup::kHit);
}

TEST_F(DiskCacheTest, ATornEntryIsBadAndRemovedADroppedOneMissed) {
  // What a crash mid-write left in the folder, found when the cache opens:
  // shorter than a header.
  fs::create_directories(entry("").parent_path());
  writeFile(entry("t0-0-4"), bytesOf(10, 0));
  open(4);
  EXPECT_EQ(get("t0-0-4"), DiskCache::Lookup::kBad);
  EXPECT_FALSE(fs::exists(entry("t0-0-4")));
  // An entry the caller found wrong (its checksum) is dropped.
  m_cache->put(m_key, "p0-0-0", bytesOf(kContent, 5));
  ASSERT_EQ(get("p0-0-0"), DiskCache::Lookup::kHit);
  m_cache->drop(m_key, "p0-0-0");
  EXPECT_EQ(get("p0-0-0"), DiskCache::Lookup::kMiss);
  EXPECT_FALSE(fs::exists(entry("p0-0-0")));
}

TEST_F(DiskCacheTest, FilesItDidNotWriteAreNeverServedNorRemoved) {
  // In the folder when the cache opens: a name it gives with a header that
  // is not its own, and a name it never gives.
  fs::create_directories(entry("").parent_path());
  const std::vector<uint8_t> foreign = bytesOf(kContent + 24, 200);
  writeFile(entry("t0-0-5"), foreign);
  writeFile(entry("notes.txt"), bytesOf(50, 1));
  open(2);
  EXPECT_NE(get("t0-0-5"), DiskCache::Lookup::kHit);
  // Fill the cache past its cap several times over.
  for (int i = 0; i < 6; ++i) m_cache->put(m_key, "t1-0-" + std::to_string(i), bytesOf(kContent, uint8_t(i)));
  EXPECT_GE(m_cache->stats().evictions, 4u);
  ASSERT_TRUE(fs::exists(entry("t0-0-5")));
  EXPECT_EQ(fs::file_size(entry("t0-0-5")), foreign.size());
  EXPECT_TRUE(fs::exists(entry("notes.txt")));
}

TEST_F(DiskCacheTest, ASymlinkedStoreFolderIsNotUsedAndACapOfZeroIsRefused) {
  open(2);
  const std::string other = DiskCache::storeKey("http://127.0.0.1/b.cstore", "\"v1\"");
  fs::create_directory(m_dir.file("elsewhere"));
  fs::create_directory_symlink(m_dir.file("elsewhere"), fs::path(m_dir.file("cache")) / other);
  EXPECT_FALSE(m_cache->usableStoreDir(other));
  std::shared_ptr<DiskCache> none;
  const Status s = DiskCache::open(m_dir.file("other"), 0, &none);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument) << s.toString();
}

}  // namespace
}  // namespace clipstream
