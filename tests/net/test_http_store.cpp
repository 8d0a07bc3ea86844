// Stores read over HTTP from a real nginx (http_store_fixture.h): the bytes
// equal the local file's, opening reads little, batches coalesce, the
// connection is kept alive, clipstream-info takes a URL, and over https the
// certificate is checked and HTTP/2 multiplexes a batch on one connection.
// The failures are in test_http_failures.cpp, the disk cache in
// test_http_disk_cache.cpp.
#include "http_store_fixture.h"

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/net.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <sys/wait.h>

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace clipstream {
namespace {

using test::cacheFolder;
using test::HttpStore;
using test::LoggedRequest;
using test::NginxServer;
using test::storeSpec;

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
