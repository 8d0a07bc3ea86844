// Stores read over HTTP from a real nginx (started per test on 127.0.0.1,
// configuration and logs in a temporary folder): the bytes equal the local
// file's, opening reads little, and every failure names the URL and the
// HTTP status: 404, 403, 503 with retries, a refused connection, a stalled
// server, a truncated file, a store replaced on the server.
#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/net.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <arpa/inet.h>
#include <sys/wait.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>
#include <utime.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace clipstream {
namespace {

using test::LoggedRequest;
using test::NginxServer;

// A store of 57 tiles over 5 levels, about 600 KiB: larger than the first
// request (64 KiB), so tiles and index pages need requests of their own.
test::SyntheticStoreSpec storeSpec() {
  test::SyntheticStoreSpec spec;
  spec.width_px = 700;
  spec.height_px = 500;
  spec.tile_px = 64;
  spec.format = PixelFormat::kRGBA8;
  spec.constant = test::ConstantTiles::kSome;
  return spec;
}

class HttpStore : public ::testing::Test {
 protected:
  void SetUp() override {
    std::filesystem::create_directories(m_dir.file("www"));
    m_local = m_dir.file("www/store.cstore");
    ASSERT_TRUE(test::writeSyntheticStore(m_local, storeSpec()).ok());
    const Status s = NginxServer::start(m_dir.path().string(), m_dir.file("www"), &m_server);
    ASSERT_TRUE(s.ok()) << s.toString();
  }

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

  test::TempDir m_dir{"http-store"};
  std::string m_local;
  std::unique_ptr<NginxServer> m_server;
};

TEST_F(HttpStore, TilesReadOverHttpEqualTheLocalFile) {
  std::unique_ptr<TileStoreReader> local, remote;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const Status s = TileStoreReader::open(m_server->url("store.cstore"), &remote);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_EQ(remote->info().file_bytes, local->info().file_bytes);
  EXPECT_EQ(remote->geometry().levelCount(), local->geometry().levelCount());
  EXPECT_EQ(remote->suggestedReadThreads(), RemoteOptions{}.connections);
  EXPECT_EQ(local->suggestedReadThreads(), 0u);
  size_t payloads = 0;
  for (const TileKey& key : allKeys(local->geometry())) {
    RawTile a, b;
    ASSERT_TRUE(local->readRaw(key, &a).ok());
    const Status rs = remote->readRaw(key, &b);
    ASSERT_TRUE(rs.ok()) << rs.toString();
    EXPECT_EQ(a.location.offset, b.location.offset);
    EXPECT_EQ(a.location.constant, b.location.constant);
    ASSERT_EQ(a.payload, b.payload) << "level " << key.level << " tile " << key.x << "," << key.y;
    if (!a.payload.empty()) ++payloads;
    std::vector<uint8_t> pixels_a, pixels_b;
    ASSERT_TRUE(local->readTile(key, &pixels_a).ok());
    ASSERT_TRUE(remote->readTile(key, &pixels_b).ok());
    ASSERT_EQ(pixels_a, pixels_b);
  }
  EXPECT_GT(payloads, 10u);
  // Every request asked for a range and got one; all after the first
  // carried the version they expect.
  const RemoteStats stats = remote->remoteStats();
  const std::vector<LoggedRequest> log = m_server->requests(stats.requests);
  ASSERT_FALSE(log.empty());
  for (size_t i = 0; i < log.size(); ++i) {
    EXPECT_EQ(log[i].status, 206) << "request " << i;
    EXPECT_FALSE(log[i].range.empty()) << "request " << i;
    if (i > 0) {
      EXPECT_FALSE(log[i].if_range.empty()) << "request " << i;
    }
  }
  EXPECT_EQ(stats.requests, log.size());
  EXPECT_EQ(stats.failures, 0u);
  EXPECT_EQ(local->remoteStats().requests, 0u);
}

TEST_F(HttpStore, BatchReadCoalescesNeighboursIntoOneRequestWithTheSameBytes) {
  std::unique_ptr<TileStoreReader> local, remote;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), &remote).ok());
  EXPECT_EQ(remote->suggestedBatchTiles(), RemoteOptions{}.batch_tiles);
  EXPECT_EQ(local->suggestedBatchTiles(), 1u);
  // The last row of level 0 (beyond the first 64 KiB the open read).
  const PyramidGeometry& g = local->geometry();
  std::vector<TileKey> keys;
  for (uint32_t x = 0; x < g.levels[0].tiles_x; ++x) keys.push_back({0, x, g.levels[0].tiles_y - 1});
  size_t payloads = 0;
  for (const TileKey& key : keys) {
    TileLocation location;
    ASSERT_TRUE(local->locate(key, &location).ok());
    if (!location.constant) ++payloads;
  }
  ASSERT_GE(payloads, 3u);
  {
    RawTile warm;  // loads the row's index page
    ASSERT_TRUE(remote->readRaw(keys[0], &warm).ok());
  }
  const uint64_t before = remote->remoteStats().requests;
  std::vector<RawTile> raws(keys.size());
  std::vector<Status> statuses(keys.size());
  remote->readRawBatch(keys, raws, statuses);
  for (size_t i = 0; i < keys.size(); ++i) {
    ASSERT_TRUE(statuses[i].ok()) << statuses[i].toString();
    RawTile expected;
    ASSERT_TRUE(local->readRaw(keys[i], &expected).ok());
    EXPECT_EQ(raws[i].payload, expected.payload) << "tile " << i;
  }
  // The row lies together in the file: one request for all its payloads.
  EXPECT_EQ(remote->remoteStats().requests - before, 1u);
  // With coalescing off (a gap of 0 and a cap of one tile), one each.
  RemoteOptions apart;
  apart.coalesce_gap_bytes = 0;
  apart.coalesce_max_bytes = 1;
  std::unique_ptr<TileStoreReader> separate;
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), apart, &separate).ok());
  {
    RawTile warm;
    ASSERT_TRUE(separate->readRaw(keys[0], &warm).ok());
  }
  const uint64_t separate_before = separate->remoteStats().requests;
  separate->readRawBatch(keys, raws, statuses);
  for (const Status& st : statuses) EXPECT_TRUE(st.ok()) << st.toString();
  EXPECT_EQ(separate->remoteStats().requests - separate_before, payloads);
}

TEST_F(HttpStore, BatchReadOfADamagedTileFailsThatTileOnly) {
  // Flip a byte inside one payload of the last row: only that tile fails.
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const PyramidGeometry& g = local->geometry();
  std::vector<TileKey> keys;
  for (uint32_t x = 0; x < g.levels[0].tiles_x; ++x) keys.push_back({0, x, g.levels[0].tiles_y - 1});
  size_t damaged = keys.size();
  TileLocation location;
  for (size_t i = 0; i < keys.size() && damaged == keys.size(); ++i) {
    ASSERT_TRUE(local->locate(keys[i], &location).ok());
    if (!location.constant) damaged = i;
  }
  ASSERT_LT(damaged, keys.size());
  local.reset();
  std::vector<uint8_t> bytes = test::readBytes(m_local);
  bytes[location.offset + location.stored_bytes / 2] ^= 0x40;
  test::writeBytes(m_local, bytes);
  std::unique_ptr<TileStoreReader> remote;
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), &remote).ok());
  std::vector<RawTile> raws(keys.size());
  std::vector<Status> statuses(keys.size());
  remote->readRawBatch(keys, raws, statuses);
  for (size_t i = 0; i < keys.size(); ++i) {
    if (i == damaged) {
      EXPECT_EQ(statuses[i].code, ErrorCode::kCorruptTile) << statuses[i].toString();
    } else {
      EXPECT_TRUE(statuses[i].ok()) << i << ": " << statuses[i].toString();
    }
  }
}

TEST_F(HttpStore, OpeningReadsTheHeaderTableAndDirectoriesOnly) {
  std::unique_ptr<TileStoreReader> remote;
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), &remote).ok());
  const std::vector<LoggedRequest> log = m_server->requests(remote->remoteStats().requests);
  EXPECT_EQ(log.size(), remote->remoteStats().requests);
  // The first 64 KiB (the header), the level table with the metadata, and
  // the page directories: one request each, none for payloads or pages.
  EXPECT_LE(log.size(), 3u);
  uint64_t bytes = 0;
  for (const LoggedRequest& r : log) bytes += r.body_bytes;
  EXPECT_LT(bytes, uint64_t(80) << 10);
  EXPECT_EQ(remote->indexPagesLoaded(), 0u);
  // One tile far into the file: its index page and its payload, no more.
  const PyramidGeometry& g = remote->geometry();
  const TileKey key{0, g.levels[0].tiles_x - 1, g.levels[0].tiles_y - 1};
  RawTile raw;
  ASSERT_TRUE(remote->readRaw(key, &raw).ok());
  ASSERT_FALSE(raw.location.constant);
  EXPECT_GT(raw.location.offset, uint64_t(64) << 10);
  EXPECT_EQ(remote->remoteStats().requests, log.size() + 2);
  EXPECT_EQ(m_server->requests(log.size() + 2).size(), log.size() + 2);
}

TEST_F(HttpStore, MissingStoreNamesTheUrlAndHttp404) {
  std::unique_ptr<TileStoreReader> remote;
  const std::string url = m_server->url("missing.cstore");
  const Status s = TileStoreReader::open(url, &remote);
  EXPECT_EQ(s.code, ErrorCode::kNotFound);
  EXPECT_NE(s.message.find(url), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("HTTP 404"), std::string::npos) << s.message;
  EXPECT_EQ(remote, nullptr);
}

TEST_F(HttpStore, ForbiddenIsAnErrorNamingHttp403) {
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(m_server->url("forbidden.cstore"), &remote);
  EXPECT_EQ(s.code, ErrorCode::kIo);
  EXPECT_NE(s.message.find("HTTP 403"), std::string::npos) << s.message;
  // A retry would have been sent before open() returned, so it is logged
  // before the requests of a later open (nginx logs each when answered).
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), &remote).ok());
  const size_t later = remote->remoteStats().requests;
  const std::vector<LoggedRequest> log = m_server->requests(1 + later);
  EXPECT_EQ(log.size(), 1 + later) << "a 403 is not retried";
  EXPECT_EQ(std::count_if(log.begin(), log.end(), [](const LoggedRequest& r) { return r.uri == "/forbidden.cstore"; }),
            1);
}

TEST_F(HttpStore, ServerErrorsAreRetriedThenReportedUnavailable) {
  RemoteOptions options;
  options.retries = 3;
  options.retry_base_ms = 10;
  std::unique_ptr<TileStoreReader> remote;
  const std::string url = m_server->url("failing.cstore");
  const Status s = TileStoreReader::open(url, options, &remote);
  EXPECT_EQ(s.code, ErrorCode::kUnavailable);
  EXPECT_NE(s.message.find("HTTP 503"), std::string::npos) << s.message;
  EXPECT_NE(s.message.find(url), std::string::npos) << s.message;
  EXPECT_EQ(m_server->requests(4).size(), 4u) << "one request and three retries";
}

TEST_F(HttpStore, RefusedConnectionIsUnavailable) {
  const std::string url = m_server->url("store.cstore");
  m_server->stop();
  RemoteOptions options;
  options.retry_base_ms = 10;
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(url, options, &remote);
  EXPECT_EQ(s.code, ErrorCode::kUnavailable);
  EXPECT_NE(s.message.find(url), std::string::npos) << s.message;
}

TEST_F(HttpStore, StalledServerTimesOut) {
  // A socket that listens but never answers: the kernel completes the
  // connection, no byte ever comes back.
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(addr);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  ASSERT_EQ(::listen(fd, 8), 0);
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len), 0);
  const std::string url = "http://127.0.0.1:" + std::to_string(ntohs(addr.sin_port)) + "/s.cstore";
  RemoteOptions options;
  options.stall_timeout_ms = 1000;
  options.retries = 0;
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(url, options, &remote);
  ::close(fd);
  EXPECT_EQ(s.code, ErrorCode::kUnavailable);
  EXPECT_NE(s.message.find(url), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("imed out"), std::string::npos) << s.message;
}

TEST_F(HttpStore, TruncatedFileOnTheServerIsReported) {
  const std::vector<uint8_t> bytes = test::readBytes(m_local);
  test::writeBytes(m_dir.file("www/half.cstore"),
                   std::vector<uint8_t>(bytes.begin(), bytes.begin() + bytes.size() / 2));
  std::unique_ptr<TileStoreReader> remote;
  const std::string url = m_server->url("half.cstore");
  const Status s = TileStoreReader::open(url, &remote);
  EXPECT_EQ(s.code, ErrorCode::kTruncated) << s.toString();
  EXPECT_NE(s.message.find(url), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("the header says"), std::string::npos) << s.message;
}

TEST_F(HttpStore, EmptyFileOnTheServerIsReported) {
  test::writeBytes(m_dir.file("www/empty.cstore"), {});
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(m_server->url("empty.cstore"), &remote);
  EXPECT_EQ(s.code, ErrorCode::kTruncated) << s.toString();
}

// The same bytes under a new modification time: nginx's ETag changes, so
// the server holds "another version" and every later read must refuse it.
TEST_F(HttpStore, StoreReplacedOnTheServerIsDetectedAndNeverMixed) {
  std::unique_ptr<TileStoreReader> local, remote;
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), &remote).ok());
  const std::vector<TileKey> keys = allKeys(local->geometry());
  const size_t half = keys.size() / 2;
  for (size_t i = 0; i < half; ++i) {
    std::vector<uint8_t> a, b;
    ASSERT_TRUE(local->readTile(keys[i], &a).ok());
    ASSERT_TRUE(remote->readTile(keys[i], &b).ok());
    ASSERT_EQ(a, b);
  }
  publish(m_local, "store.cstore", 100);
  size_t failed = 0;
  std::string message;
  for (size_t i = half; i < keys.size(); ++i) {
    RawTile raw;
    const Status s = remote->readRaw(keys[i], &raw);
    if (s) {
      // Only tiles served from what was read before (constant entries of
      // a loaded page, the first 64 KiB) may still succeed: from the old
      // version, equal to the local file.
      RawTile expected;
      ASSERT_TRUE(local->readRaw(keys[i], &expected).ok());
      EXPECT_EQ(raw.payload, expected.payload);
      continue;
    }
    ++failed;
    EXPECT_EQ(s.code, ErrorCode::kIo);
    message = s.message;
  }
  EXPECT_GT(failed, 0u);
  EXPECT_NE(message.find("changed on the server"), std::string::npos) << message;
  EXPECT_NE(message.find(m_server->url("store.cstore")), std::string::npos) << message;
  // The server answered the If-Range with the whole file (200), which was cut.
  bool saw_200 = false;
  for (const LoggedRequest& r : m_server->requests(remote->remoteStats().requests))
    saw_200 |= r.status == 200;
  EXPECT_TRUE(saw_200);
}

TEST_F(HttpStore, StoreReplacedByAnotherStoreIsDetected) {
  std::unique_ptr<TileStoreReader> remote;
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), &remote).ok());
  test::SyntheticStoreSpec other = storeSpec();
  other.constant = test::ConstantTiles::kNone;
  const std::string other_path = m_dir.file("other.cstore");
  ASSERT_TRUE(test::writeSyntheticStore(other_path, other).ok());
  publish(other_path, "store.cstore", 100);
  const PyramidGeometry& g = remote->geometry();
  RawTile raw;
  const Status s = remote->readRaw({0, g.levels[0].tiles_x - 1, g.levels[0].tiles_y - 1}, &raw);
  EXPECT_EQ(s.code, ErrorCode::kIo);
  EXPECT_NE(s.message.find("changed on the server"), std::string::npos) << s.message;
  // Putting the old version back does not make the reader trust it again.
  publish(m_local, "store.cstore", 200);
  EXPECT_FALSE(remote->readRaw({0, 0, 0}, &raw).ok());
}

TEST_F(HttpStore, ConnectionsAreKeptAlive) {
  std::unique_ptr<test::DelayProxy> proxy;
  ASSERT_TRUE(test::DelayProxy::start(m_server->port(), 0.0, &proxy).ok());
  RemoteOptions options;
  options.connections = 1;
  std::unique_ptr<TileStoreReader> remote;
  ASSERT_TRUE(TileStoreReader::open(proxy->url("store.cstore"), options, &remote).ok());
  for (const TileKey& key : allKeys(remote->geometry())) {
    RawTile raw;
    ASSERT_TRUE(remote->readRaw(key, &raw).ok());
  }
  EXPECT_GT(remote->remoteStats().requests, 10u);
  EXPECT_EQ(proxy->connections(), 1u) << "every request on one kept-alive connection";
  EXPECT_EQ(remote->remoteStats().connections, 1u);
  EXPECT_EQ(remote->remoteStats().http2_requests, 0u) << "http:// is HTTP/1.1";
}

TEST_F(HttpStore, AnswerCutMidBodyIsRetriedAndArrivesWhole) {
  std::unique_ptr<test::DelayProxy> proxy;
  ASSERT_TRUE(test::DelayProxy::start(m_server->port(), 0.0, &proxy).ok());
  // The first connection dies 600 bytes into its answer (the headers and
  // part of the first 64 KiB): a retry on a new connection completes it.
  proxy->cutConnections(1, 600);
  RemoteOptions options;
  options.connections = 1;
  options.retry_base_ms = 10;
  std::unique_ptr<TileStoreReader> local, remote;
  const Status s = TileStoreReader::open(proxy->url("store.cstore"), options, &remote);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_EQ(remote->remoteStats().retries, 1u);
  EXPECT_EQ(proxy->connections(), 2u);
  ASSERT_TRUE(TileStoreReader::open(m_local, &local).ok());
  const PyramidGeometry& g = local->geometry();
  const TileKey key{0, g.levels[0].tiles_x - 1, g.levels[0].tiles_y - 1};
  RawTile a, b;
  ASSERT_TRUE(local->readRaw(key, &a).ok());
  ASSERT_TRUE(remote->readRaw(key, &b).ok());
  EXPECT_EQ(a.payload, b.payload);
  // With no retries left, the same cut is a transient failure.
  proxy->cutConnections(1, 600);
  options.retries = 0;
  std::unique_ptr<TileStoreReader> once;
  const Status cut = TileStoreReader::open(proxy->url("store.cstore"), options, &once);
  EXPECT_EQ(cut.code, ErrorCode::kUnavailable) << cut.toString();
  EXPECT_NE(cut.message.find(proxy->url("store.cstore")), std::string::npos) << cut.message;
}

TEST_F(HttpStore, AContentRangeWithoutATotalSizeIsNamedAsSuch) {
  // "bytes 0-65535/*" is allowed by RFC 9110 but gives no file size, which
  // the reader needs (offsets from the end, a changed file told by its size).
  std::unique_ptr<test::DelayProxy> proxy;
  ASSERT_TRUE(test::DelayProxy::start(m_server->port(), 0.0, &proxy).ok());
  const std::string size = std::to_string(std::filesystem::file_size(m_local));
  proxy->rewriteAnswers("/" + size + "\r\n", "/*\r\n");
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(proxy->url("store.cstore"), RemoteOptions{}, &remote);
  EXPECT_EQ(s.code, ErrorCode::kUnsupported) << s.toString();
  EXPECT_NE(s.message.find("gives no total size"), std::string::npos) << s.message;
  EXPECT_EQ(s.message.find("does not match the request"), std::string::npos) << s.message;
}

// ---- Disk cache (RemoteOptions::disk_cache_dir) ----

// The files of a disk cache folder: entries only, their total size.
struct CacheFolder {
  std::vector<std::string> entries;  // paths of the entry files
  uint64_t bytes = 0;
};
CacheFolder cacheFolder(const std::string& dir) {
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

TEST_F(HttpStore, AbsurdConnectionCountIsRefused) {
  RemoteOptions options;
  options.connections = 0;
  std::unique_ptr<TileStoreReader> remote;
  EXPECT_EQ(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).code,
            ErrorCode::kInvalidArgument);
  options.connections = kMaxRemoteConnections + 1;
  EXPECT_EQ(TileStoreReader::open(m_server->url("store.cstore"), options, &remote).code,
            ErrorCode::kInvalidArgument);
  // Nothing was sent: the log holds only what a later, valid open sends.
  ASSERT_TRUE(TileStoreReader::open(m_server->url("store.cstore"), &remote).ok());
  const size_t later = remote->remoteStats().requests;
  EXPECT_EQ(m_server->requests(later).size(), later);
}

// The program, not only the library: clipstream-info takes a URL.
std::pair<int, std::string> runProgram(const std::string& command_line) {
  std::string output;
  FILE* pipe = ::popen(("{ CLIPSTREAM_PROGRESS=0 " + command_line + "; } 2>&1").c_str(), "r");
  if (pipe == nullptr) return {-1, ""};
  char buffer[4096];
  size_t got;
  while ((got = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, got);
  const int status = ::pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

TEST_F(HttpStore, InfoToolVerifiesAStoreByUrlAndNamesA404) {
  const std::string url = m_server->url("store.cstore");
  const auto [code, output] =
      runProgram(std::string("'") + CLIPSTREAM_INFO_EXE + "' --verify '" + url + "'");
  EXPECT_EQ(code, 0) << output;
  EXPECT_NE(output.find(url), std::string::npos) << output;
  EXPECT_NE(output.find("verify: OK"), std::string::npos) << output;
  // --disk-cache keeps what was read; a second run verifies from it.
  const std::string cache = m_dir.file("cache");
  const std::string cached_run = std::string("'") + CLIPSTREAM_INFO_EXE + "' --verify --disk-cache '" +
                                 cache + "' --disk-cache-mb 64 '" + url + "'";
  const auto [first_code, first_output] = runProgram(cached_run);
  EXPECT_EQ(first_code, 0) << first_output;
  EXPECT_GT(cacheFolder(cache).entries.size(), 10u);
  m_server->clearLog();
  const auto [second_code, second_output] = runProgram(cached_run);
  EXPECT_EQ(second_code, 0) << second_output;
  EXPECT_NE(second_output.find("verify: OK"), std::string::npos) << second_output;
  EXPECT_LE(m_server->requests().size(), 3u) << "only the open's requests";
  const std::string missing = m_server->url("missing.cstore");
  const auto [missing_code, missing_output] =
      runProgram(std::string("'") + CLIPSTREAM_INFO_EXE + "' '" + missing + "'");
  EXPECT_EQ(missing_code, 1) << missing_output;
  EXPECT_NE(missing_output.find(missing + ": HTTP 404 Not Found"), std::string::npos)
      << missing_output;
}

TEST_F(HttpStore, MessagesHideCredentialsAndQueryStrings) {
  const std::string url = "http://reader:secret@127.0.0.1:" + std::to_string(m_server->port()) +
                          "/half.cstore?X-Signature=abcdef";
  const std::vector<uint8_t> bytes = test::readBytes(m_local);
  test::writeBytes(m_dir.file("www/half.cstore"),
                   std::vector<uint8_t>(bytes.begin(), bytes.begin() + bytes.size() / 2));
  std::unique_ptr<TileStoreReader> remote;
  const Status s = TileStoreReader::open(url, &remote);
  EXPECT_EQ(s.code, ErrorCode::kTruncated) << s.toString();
  EXPECT_EQ(s.message.find("secret"), std::string::npos) << s.message;
  EXPECT_EQ(s.message.find("abcdef"), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("http://127.0.0.1:" + std::to_string(m_server->port()) +
                           "/half.cstore?..."),
            std::string::npos)
      << s.message;
  EXPECT_EQ(displayStorePath("/data/a.cstore"), "/data/a.cstore");
}

// https: an untrusted certificate fails at once, naming the URL and not
// retried; trusted through RemoteOptions::ca_file, the tiles equal the file's.
TEST(HttpsStore, UntrustedCertificateFailsAndATrustedOneReadsTheSameTiles) {
  test::TempDir dir("https-store");
  std::filesystem::create_directories(dir.file("www"));
  const std::string local_path = dir.file("www/store.cstore");
  ASSERT_TRUE(test::writeSyntheticStore(local_path, storeSpec()).ok());
  std::unique_ptr<NginxServer> server;
  const Status started = NginxServer::start(dir.path().string(), dir.file("www"), &server, true);
  ASSERT_TRUE(started.ok()) << started.toString();
  const std::string url = server->url("store.cstore");
  ASSERT_EQ(url.rfind("https://", 0), 0u);

  std::unique_ptr<TileStoreReader> remote;
  const Status untrusted = TileStoreReader::open(url, &remote);
  EXPECT_EQ(untrusted.code, ErrorCode::kIo) << untrusted.toString();
  EXPECT_NE(untrusted.message.find(url), std::string::npos) << untrusted.message;
  EXPECT_NE(untrusted.message.find("certificate"), std::string::npos) << untrusted.message;
  std::printf("  %s\n", untrusted.message.c_str());

  RemoteOptions trusted;
  trusted.ca_file = server->certificateFile();
  const Status opened = TileStoreReader::open(url, trusted, &remote);
  ASSERT_TRUE(opened.ok()) << opened.toString();
  // The log holds only the trusted open's requests: none after the failed
  // handshake (it would have been answered, and logged, before these).
  const size_t sent = remote->remoteStats().requests;
  EXPECT_EQ(server->requests(sent).size(), sent) << "no HTTP request after a failed handshake";
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(local_path, &local).ok());
  const PyramidGeometry& g = local->geometry();
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    const TileKey key{l, g.levels[l].tiles_x - 1, g.levels[l].tiles_y - 1};
    std::vector<uint8_t> a, b;
    ASSERT_TRUE(local->readTile(key, &a).ok());
    const Status rs = remote->readTile(key, &b);
    ASSERT_TRUE(rs.ok()) << rs.toString();
    EXPECT_EQ(a, b);
  }
}

// HTTP/2 over TLS: nginx offers h2 (ALPN); every request of a batch read
// with coalescing off is in flight at once, all as streams of the one
// connection, and the bytes equal the file's. With RemoteOptions::http2
// off the same server is read over HTTP/1.1.
TEST(HttpsStore, Http2MultiplexesABatchOnOneConnectionWithTheSameBytes) {
  test::TempDir dir("http2-store");
  std::filesystem::create_directories(dir.file("www"));
  const std::string local_path = dir.file("www/store.cstore");
  ASSERT_TRUE(test::writeSyntheticStore(local_path, storeSpec()).ok());
  std::unique_ptr<NginxServer> server;
  const Status started =
      NginxServer::start(dir.path().string(), dir.file("www"), &server, true, true);
  ASSERT_TRUE(started.ok()) << started.toString();
  std::unique_ptr<TileStoreReader> local;
  ASSERT_TRUE(TileStoreReader::open(local_path, &local).ok());
  const PyramidGeometry& g = local->geometry();
  std::vector<TileKey> keys;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) keys.push_back({l, x, y});

  for (const bool http2 : {true, false}) {
    SCOPED_TRACE(http2 ? "HTTP/2" : "HTTP/1.1");
    RemoteOptions options;
    options.ca_file = server->certificateFile();
    options.http2 = http2;
    options.coalesce_gap_bytes = 0;  // one request per payload, all at once
    options.coalesce_max_bytes = 1;
    options.connections = 8;
    server->clearLog();
    std::unique_ptr<TileStoreReader> remote;
    const Status opened = TileStoreReader::open(server->url("store.cstore"), options, &remote);
    ASSERT_TRUE(opened.ok()) << opened.toString();
    std::vector<RawTile> raws(keys.size());
    std::vector<Status> statuses(keys.size());
    remote->readRawBatch(keys, raws, statuses);
    size_t payloads = 0;
    for (size_t i = 0; i < keys.size(); ++i) {
      ASSERT_TRUE(statuses[i].ok()) << statuses[i].toString();
      RawTile expected;
      ASSERT_TRUE(local->readRaw(keys[i], &expected).ok());
      EXPECT_EQ(raws[i].payload, expected.payload) << "tile " << i;
      payloads += expected.payload.empty() ? 0 : 1;
    }
    const RemoteStats stats = remote->remoteStats();
    // Open (3 at most), the index pages, then one request per payload
    // beyond the first 64 KiB.
    EXPECT_GT(stats.requests, 10u);
    EXPECT_EQ(stats.failures, 0u);
    const std::vector<LoggedRequest> log = server->requests(stats.requests);
    ASSERT_EQ(log.size(), stats.requests);
    for (const LoggedRequest& r : log) {
      EXPECT_EQ(r.status, 206);
      EXPECT_EQ(r.protocol, http2 ? "HTTP/2.0" : "HTTP/1.1");
    }
    if (http2) {
      EXPECT_EQ(stats.http2_requests, stats.requests);
      EXPECT_EQ(stats.connections, 1u) << "every stream on one connection";
    } else {
      EXPECT_EQ(stats.http2_requests, 0u);
      EXPECT_GE(stats.connections, 1u);
      EXPECT_LE(stats.connections, options.connections);
    }
    EXPECT_GT(payloads, 10u);
  }
}

TEST(StoreUrl, SchemesAreRecognised) {
  EXPECT_TRUE(isStoreUrl("http://host/a.cstore"));
  EXPECT_TRUE(isStoreUrl("HTTPS://host/a.cstore"));
  EXPECT_FALSE(isStoreUrl("ftp://host/a.cstore"));
  EXPECT_FALSE(isStoreUrl("http:/a.cstore"));
  EXPECT_FALSE(isStoreUrl("./http://x"));
}

}  // namespace
}  // namespace clipstream
