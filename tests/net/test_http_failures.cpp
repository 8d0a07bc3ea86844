// Every failure of a store read over HTTP names the URL and the HTTP
// status (http_store_fixture.h): 404, 403, 503 with retries, a refused
// connection, a stalled server, a truncated or empty file, a store replaced
// on the server, an answer cut mid-body, a Content-Range without a total,
// an absurd connection count; messages hide credentials and query strings.
#include "http_store_fixture.h"

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/net.h>
#include <clipstream/testing/synthetic_store.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

namespace clipstream {
namespace {

using test::HttpStore;
using test::LoggedRequest;
using test::storeSpec;

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

}  // namespace
}  // namespace clipstream
