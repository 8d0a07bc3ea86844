// libFuzzer driver for a store read over HTTP as the remote source sees it
// (store/src/http_source.cpp through libcurl): a server on 127.0.0.1 in this
// process answers every request with the mutated bytes, status line,
// headers and body as they are, then closes the connection; the reader opens
// the store by URL and reads every tile. Seeds: the answers a server gives
// (206 with a small store, 200, 404, 416, 503, chunked, a redirect).
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./http_fuzz -runs=0   # write seeds
//   ./http_fuzz -max_total_time=300 -timeout=10 corpus
#include "fuzz_util.h"

#include <clipstream/store/remote.h>
#include <clipstream/store/tile_store.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace clipstream;

std::mutex g_mutex;          // guards g_answer
std::string g_answer;        // what every request gets now
std::atomic<uint16_t> g_port{0};

bool sendAll(int fd, const char* p, size_t n) {
  while (n > 0) {
    const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
    if (w <= 0) return false;
    p += w, n -= size_t(w);
  }
  return true;
}

// Serves forever on a loopback port: reads a request's head (up to 16 KB,
// 2 s), answers with g_answer, closes.
void serve() {
  const int listener = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (listener < 0 || ::bind(listener, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      ::listen(listener, 64) != 0)
    std::abort();
  socklen_t len = sizeof addr;
  ::getsockname(listener, reinterpret_cast<sockaddr*>(&addr), &len);
  g_port.store(ntohs(addr.sin_port));
  for (;;) {
    const int fd = ::accept4(listener, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) continue;
    std::string head;
    char buf[4096];
    while (head.find("\r\n\r\n") == std::string::npos && head.size() < 16384) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 2000) <= 0) break;
      const ssize_t got = ::recv(fd, buf, sizeof buf, 0);
      if (got <= 0) break;
      head.append(buf, size_t(got));
    }
    std::string answer;
    {
      std::lock_guard<std::mutex> lock(g_mutex);
      answer = g_answer;
    }
    sendAll(fd, answer.data(), answer.size());
    ::shutdown(fd, SHUT_WR);
    ::close(fd);
  }
}

// A 20 x 12 grey store, whole (it is shorter than the reader's first read).
std::string smallStore() {
  const std::string path = fuzz::scratchPath("seed.cst");
  PyramidGeometry g;
  if (!makePyramidGeometry(20, 12, 16, PixelFormat::kR8, &g)) std::abort();
  WriterOptions options;
  options.fsync = false;
  options.replace = true;
  std::unique_ptr<TileStoreWriter> writer;
  if (!TileStoreWriter::create(path, g, options, &writer)) std::abort();
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        std::vector<uint8_t> pixels(g.tileBytes());
        for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t(i * 3 + x + y + l);
        EncodedTile encoded;
        if (!encodeTile(g, options.encoding, {l, x, y}, pixels, &encoded)) std::abort();
        if (!writer->write(std::move(encoded))) std::abort();
      }
  if (!writer->finish()) std::abort();
  const std::vector<uint8_t> bytes = fuzz::readFile(path);
  ::unlink(path.c_str());
  return std::string(bytes.begin(), bytes.end());
}

void writeSeeds(const std::string& dir) {
  const std::string store = smallStore();
  const std::string n = std::to_string(store.size());
  const std::string last = std::to_string(store.size() - 1);
  fuzz::writeFile(dir + "/206", "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-" + last + "/" + n +
                                    "\r\nContent-Length: " + n + "\r\nETag: \"v1\"\r\nLast-Modified: Sat, 05 Dec "
                                    "2026 10:00:00 GMT\r\n\r\n" + store);
  fuzz::writeFile(dir + "/206_chunked", "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-" + last + "/" + n +
                                            "\r\nTransfer-Encoding: chunked\r\n\r\n" +
                                            [&] {
                                              char size[16];
                                              std::snprintf(size, sizeof size, "%zx", store.size());
                                              return std::string(size);
                                            }() + "\r\n" + store + "\r\n0\r\n\r\n");
  fuzz::writeFile(dir + "/200", "HTTP/1.1 200 OK\r\nContent-Length: " + n + "\r\n\r\n" + store);
  fuzz::writeFile(dir + "/404", "HTTP/1.1 404 Not Found\r\nContent-Length: 9\r\n\r\nnot found");
  fuzz::writeFile(dir + "/416", "HTTP/1.1 416 Range Not Satisfiable\r\nContent-Range: bytes */0\r\n\r\n");
  fuzz::writeFile(dir + "/503", "HTTP/1.1 503 Service Unavailable\r\nRetry-After: 1\r\nContent-Length: 0\r\n\r\n");
  fuzz::writeFile(dir + "/redirect", "HTTP/1.1 302 Found\r\nLocation: /elsewhere\r\nContent-Length: 0\r\n\r\n");
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // A Location naming another host must fail fast here (no network).
  ::setenv("RES_OPTIONS", "timeout:1 attempts:1", 1);
  std::thread(serve).detach();
  while (g_port.load() == 0) std::this_thread::yield();
  if (const char* dir = fuzz::seedDir()) writeSeeds(dir);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  {
    std::lock_guard<std::mutex> lock(g_mutex);
    g_answer.assign(reinterpret_cast<const char*>(data), size);
  }
  RemoteOptions options;
  options.connections = 1;
  options.http2 = false;
  options.connect_timeout_ms = 500;
  options.stall_timeout_ms = 1000;
  options.retries = 1;
  options.retry_base_ms = 1;
  std::unique_ptr<TileStoreReader> reader;
  const std::string url = "http://127.0.0.1:" + std::to_string(g_port.load()) + "/store.cst";
  if (!TileStoreReader::open(url, options, &reader)) return 0;
  const PyramidGeometry& g = reader->geometry();
  if (g.tileBytes() > (size_t(1) << 20)) return 0;
  std::vector<uint8_t> pixels;
  uint32_t budget = 64;  // requests per input
  for (uint32_t l = 0; l < g.levelCount() && budget > 0; ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y && budget > 0; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x && budget > 0; ++x, --budget)
        (void)reader->readTile({l, x, y}, &pixels);
  return 0;
}
