// The disk cache of a store read over HTTP (RemoteOptions::disk_cache_dir;
// http_store_fixture.h): it serves a second open with the server stopped,
// keeps its cap by evicting the least recently used, drops damaged entries,
// never serves a replaced store's, evicts only what it wrote, never follows
// a symlinked folder, and names a folder it refuses or cannot make.
#include "http_store_fixture.h"

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/synthetic_store.h>

#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace clipstream {
namespace {

using test::cacheFolder;
using test::CacheFolder;
using test::HttpStore;
using test::storeSpec;

// Reads `keys` with `reader` and compares each payload with the local file's.
void expectSamePayloads(const TileStoreReader& reader, const TileStoreReader& local,
                        const std::vector<TileKey>& keys) {
  for (const TileKey& key : keys) {
    RawTile a, b;
    ASSERT_TRUE(local.readRaw(key, &a).ok());
    const Status s = reader.readRaw(key, &b);
    ASSERT_TRUE(s.ok()) << s.toString();
    ASSERT_EQ(a.payload, b.payload) << "level " << key.level << " tile " << key.x << "," << key.y;
  }
}

TEST_F(HttpStore, DiskCacheServesASecondOpenEvenWithTheServerStopped) {
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("cache");  // made by the reader
  options.retries = 0;
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const std::vector<TileKey> keys = allKeys(local->geometry());
  const std::vector<TileKey> cached(keys.begin(), keys.begin() + keys.size() / 2);
  uint64_t first_requests = 0;
  {
    std::unique_ptr<TileStoreReader> remote;
    ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
    expectSamePayloads(*remote, *local, cached);
    const RemoteStats stats = remote->remoteStats();
    EXPECT_EQ(stats.disk_cache_hits, 0u);
    EXPECT_GT(stats.disk_cache_misses, 5u);
    first_requests = stats.requests;
  }
  EXPECT_FALSE(cacheFolder(options.disk_cache_dir).entries.empty());
  // A second open (a new cache instance: the folder is scanned again) reads
  // the same tiles from the folder: no request beyond the open's.
  std::unique_ptr<TileStoreReader> remote;
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
  const uint64_t open_requests = remote->remoteStats().requests;
  EXPECT_LT(open_requests, first_requests);
  expectSamePayloads(*remote, *local, cached);
  RemoteStats stats = remote->remoteStats();
  EXPECT_EQ(stats.requests, open_requests);
  EXPECT_GT(stats.disk_cache_hits, 5u);
  EXPECT_EQ(stats.disk_cache_dropped, 0u);
  // With the server gone, cached tiles are still served; the others fail
  // as unavailable (and would be retried by the streamer).
  m_server->stop();
  expectSamePayloads(*remote, *local, cached);
  size_t unavailable = 0;
  for (size_t i = cached.size(); i < keys.size(); ++i) {
    RawTile raw;
    const Status s = remote->readRaw(keys[i], &raw);
    if (!s) {
      EXPECT_EQ(s.code, ErrorCode::kUnavailable) << s.toString();
      ++unavailable;
    }
  }
  EXPECT_GT(unavailable, 0u);
}

TEST_F(HttpStore, DiskCacheKeepsItsCapByEvictingTheLeastRecentlyUsed) {
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("cache");
  options.disk_cache_bytes = 100 << 10;  // a sixth of the store
  std::unique_ptr<TileStoreReader> local, remote;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
  const std::vector<TileKey> keys = allKeys(local->geometry());
  expectSamePayloads(*remote, *local, keys);
  const CacheFolder folder = cacheFolder(options.disk_cache_dir);
  EXPECT_LE(folder.bytes, options.disk_cache_bytes);
  EXPECT_GT(folder.bytes, options.disk_cache_bytes / 2) << "the cap is used, not emptied";
  // The last tiles read are the ones kept: reading them again is all hits.
  // The first ones beyond the first 64 KiB (which the open keeps in memory)
  // were evicted: read again from the server, with the same bytes.
  std::vector<TileKey> last, first;
  for (size_t i = keys.size(); i-- > 0 && last.size() < 3;) {
    TileLocation location;
    ASSERT_TRUE(local->locate(keys[i], &location).ok());
    if (!location.constant) last.push_back(keys[i]);
  }
  for (size_t i = 0; i < keys.size() && first.size() < 2; ++i) {
    TileLocation location;
    ASSERT_TRUE(local->locate(keys[i], &location).ok());
    if (!location.constant && location.offset >= (64 << 10)) first.push_back(keys[i]);
  }
  const RemoteStats before = remote->remoteStats();
  expectSamePayloads(*remote, *local, last);
  const RemoteStats after = remote->remoteStats();
  EXPECT_EQ(after.requests, before.requests);
  EXPECT_EQ(after.disk_cache_hits - before.disk_cache_hits, 3u);
  expectSamePayloads(*remote, *local, first);
  EXPECT_EQ(remote->remoteStats().requests, after.requests + 2);
  EXPECT_EQ(remote->remoteStats().disk_cache_hits, after.disk_cache_hits);
  EXPECT_LE(cacheFolder(options.disk_cache_dir).bytes, options.disk_cache_bytes);
}

TEST_F(HttpStore, DiskCacheDropsATruncatedOrDamagedEntryAndFetchesItAgain) {
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("cache");
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const std::vector<TileKey> keys = allKeys(local->geometry());
  {
    std::unique_ptr<TileStoreReader> remote;
    ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
    expectSamePayloads(*remote, *local, keys);
  }
  // Damage two tile entries the way a crash or a bad disk would: one cut
  // short, one with a flipped byte in its payload. Two tiles of the last
  // row of level 0, far beyond the first 64 KiB the open keeps in memory.
  const PyramidGeometry& g = local->geometry();
  std::vector<std::string> names;
  for (uint32_t x = g.levels[0].tiles_x; x-- > 0 && names.size() < 2;) {
    TileLocation location;
    ASSERT_TRUE(local->locate({0, x, g.levels[0].tiles_y - 1}, &location).ok());
    if (!location.constant) {
      names.push_back("t0-" + std::to_string(x) + "-" + std::to_string(g.levels[0].tiles_y - 1));
    }
  }
  std::vector<std::string> tiles;
  for (const std::string& name : names) {
    for (const std::string& path : cacheFolder(options.disk_cache_dir).entries) {
      if (std::filesystem::path(path).filename() == name) tiles.push_back(path);
    }
  }
  ASSERT_EQ(tiles.size(), 2u);
  std::vector<uint8_t> bytes = test::readBytes(tiles[0]);
  const size_t whole_size = bytes.size();
  bytes.resize(bytes.size() / 2);
  test::writeBytes(tiles[0], bytes);
  bytes = test::readBytes(tiles[1]);
  bytes[bytes.size() - 10] ^= 0x01;
  test::writeBytes(tiles[1], bytes);

  std::unique_ptr<TileStoreReader> remote;
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
  const uint64_t open_requests = remote->remoteStats().requests;
  expectSamePayloads(*remote, *local, keys);
  const RemoteStats stats = remote->remoteStats();
  EXPECT_EQ(stats.disk_cache_dropped, 2u);
  EXPECT_EQ(stats.requests - open_requests, 2u) << "the two tiles were fetched again";
  // The cut entry is whole again in the folder.
  EXPECT_EQ(test::readBytes(tiles[0]).size(), whole_size);
  std::unique_ptr<TileStoreReader> again;
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &again).ok());
  expectSamePayloads(*again, *local, keys);
  EXPECT_EQ(again->remoteStats().disk_cache_dropped, 0u);
}

TEST_F(HttpStore, DiskCacheNeverServesTheEntriesOfAReplacedStore) {
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("cache");
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const std::vector<TileKey> keys = allKeys(local->geometry());
  {
    std::unique_ptr<TileStoreReader> remote;
    ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
    expectSamePayloads(*remote, *local, keys);
  }
  // Another store of the same shape under the same name: other bytes at
  // the same offsets.
  test::SyntheticStoreSpec other = storeSpec();
  other.constant = test::ConstantTiles::kNone;
  const std::string other_path = m_dir.file("other.cstore");
  ASSERT_TRUE(test::writeSyntheticStore(other_path, other).ok());
  publish(other_path, "store.cstore", 100);
  std::unique_ptr<TileStoreReader> other_local, remote;
  ASSERT_TRUE(TileStoreReader::open(other_path, &other_local).ok());
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
  expectSamePayloads(*remote, *other_local, keys);
  EXPECT_EQ(remote->remoteStats().disk_cache_hits, 0u);
  EXPECT_GT(remote->remoteStats().disk_cache_misses, 0u);
}

// The one store sub-folder (a 32-digit hash) of a cache folder.
std::string storeSubFolder(const std::string& dir) {
  std::string found;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().filename().string().size() == 32) found = e.path().string();
  }
  return found;
}

// Files a user put into the folder (beside the store sub-folders and inside
// one: a large file, a text file, a file named like an entry, a symlink to a
// file elsewhere) survive a run that evicts; the entries stay under the cap.
TEST_F(HttpStore, DiskCacheEvictsOnlyTheEntriesItWrote) {
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("cache");
  options.disk_cache_bytes = 100 << 10;
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const std::vector<TileKey> keys = allKeys(local->geometry());
  {
    std::unique_ptr<TileStoreReader> remote;
    ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
    expectSamePayloads(*remote, *local, keys);
    EXPECT_EQ(remote->remoteStats().disk_cache_folders_refused, 0u);
  }
  const std::string sub = storeSubFolder(options.disk_cache_dir);
  ASSERT_FALSE(sub.empty());
  const std::string outside = m_dir.file("precious.txt");
  const std::vector<std::pair<std::string, std::vector<uint8_t>>> users = {
      {sub + "/big.bin", std::vector<uint8_t>(3 << 20, 7)},
      {sub + "/notes.txt", {'k', 'e', 'e', 'p'}},
      {sub + "/t9-9-9", std::vector<uint8_t>(4096, 1)},  // an entry's name, not its header
      {options.disk_cache_dir + "/beside.txt", {'m', 'i', 'n', 'e'}},
      {outside, {'o', 'u', 't'}},
  };
  for (const auto& [path, bytes] : users) test::writeBytes(path, bytes);
  std::filesystem::create_symlink(outside, sub + "/t8-8-8");
  // A second run reads every tile again (half of them evicted by the first):
  // the scan sees the user's files, the evictions never take them.
  for (int run = 0; run < 2; ++run) {
    std::unique_ptr<TileStoreReader> remote;
    ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
    std::vector<TileKey> order = keys;
    if (run == 1) std::reverse(order.begin(), order.end());
    expectSamePayloads(*remote, *local, order);
  }
  for (const auto& [path, bytes] : users) {
    ASSERT_TRUE(std::filesystem::exists(path)) << path << " was deleted";
    EXPECT_EQ(test::readBytes(path), bytes) << path;
  }
  EXPECT_TRUE(std::filesystem::is_symlink(sub + "/t8-8-8"));
  // The cap holds for what the cache wrote (the files named like entries
  // that are not the user's).
  uint64_t entry_bytes = 0;
  for (const auto& e : std::filesystem::directory_iterator(sub)) {
    const std::string name = e.path().filename().string();
    if (e.is_symlink() || name == "big.bin" || name == "notes.txt" || name == "t9-9-9") continue;
    entry_bytes += e.file_size();
  }
  EXPECT_LE(entry_bytes, options.disk_cache_bytes);
  EXPECT_GT(entry_bytes, options.disk_cache_bytes / 2);
}

// A store sub-folder that is a symlink is never followed: the folder it
// points to keeps its files, nothing is written there, and reads still work
// (from the server).
TEST_F(HttpStore, DiskCacheNeverFollowsASymlinkedStoreFolder) {
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("cache");
  options.disk_cache_bytes = 100 << 10;
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const std::vector<TileKey> keys = allKeys(local->geometry());
  {
    std::unique_ptr<TileStoreReader> remote;
    ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
    expectSamePayloads(*remote, *local, keys);
  }
  const std::string sub = storeSubFolder(options.disk_cache_dir);
  ASSERT_FALSE(sub.empty());
  // The user's folder, holding a copy of the cache's own entries and files
  // of theirs, put where the store's sub-folder was.
  const std::string theirs = m_dir.file("theirs");
  std::filesystem::copy(sub, theirs);
  std::filesystem::remove_all(sub);
  test::writeBytes(theirs + "/big.bin", std::vector<uint8_t>(3 << 20, 7));
  std::filesystem::create_directory_symlink(theirs, sub);
  std::vector<std::string> before;
  for (const auto& e : std::filesystem::directory_iterator(theirs)) before.push_back(e.path());
  std::sort(before.begin(), before.end());
  {
    std::unique_ptr<TileStoreReader> remote;
    ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).ok());
    expectSamePayloads(*remote, *local, keys);
    EXPECT_EQ(remote->remoteStats().disk_cache_hits, 0u) << "entries read through the symlink";
    EXPECT_EQ(remote->remoteStats().disk_cache_folders_refused, 1u) << "the programs would not warn";
  }
  std::vector<std::string> after;
  for (const auto& e : std::filesystem::directory_iterator(theirs)) after.push_back(e.path());
  std::sort(after.begin(), after.end());
  EXPECT_EQ(after, before);
}

// A folder of another user is refused, naming it (run as root, which can
// give a folder away; skipped otherwise).
TEST_F(HttpStore, DiskCacheRefusesAFolderOfAnotherUser) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root to make a folder of another user";
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("someone-elses");
  std::filesystem::create_directory(options.disk_cache_dir);
  ASSERT_EQ(::chown(options.disk_cache_dir.c_str(), 65534, 65534), 0);
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(m_server->url("store.cstore"), options, &remote);
  EXPECT_EQ(s.code, ErrorCode::kIo) << s.toString();
  EXPECT_NE(s.message.find(options.disk_cache_dir), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("belongs to user 65534"), std::string::npos) << s.message;
}

TEST_F(HttpStore, DiskCacheFolderThatCannotBeMadeIsNamed) {
  RemoteOptions options;
  options.disk_cache_dir = m_dir.file("no/such/parent/cache");
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(m_server->url("store.cstore"), options, &remote);
  EXPECT_EQ(s.code, ErrorCode::kNotFound) << s.toString();
  EXPECT_NE(s.message.find(options.disk_cache_dir), std::string::npos) << s.message;
}

}  // namespace
}  // namespace clipstream
