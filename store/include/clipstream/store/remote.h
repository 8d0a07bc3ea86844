// Reading a tile store over HTTP(S): which paths are URLs, the options of
// the URL byte source (connections, timeouts, retries) and its counters.
// The source itself is private (store/src/http_source.cpp); stores are
// opened through TileStoreReader::open(), which takes a path or a URL.
//
// Thread-safe: plain data and pure functions only.
#pragma once

#include <cstdint>
#include <string>

namespace clipstream {

// True for "http://..." and "https://..." (scheme in any case): such a store
// path is read by HTTP range requests instead of from the local disk.
bool isStoreUrl(const std::string& path);

// A URL as messages and logs show it: without "user:password@" and with
// its query string replaced by "?..." (a presigned object-store URL carries
// its signature there); control bytes shown as '?'. Other paths unchanged.
std::string displayStorePath(const std::string& path);

// Tunables of the URL byte source. The defaults and their reasons are in
// docs/decisions.md (D196-D215); benchmarks in docs/benchmarks.md.
struct RemoteOptions {
  // Range requests in flight at once, and the most connections opened to
  // the server. Over HTTP/1.1 each request in flight holds a kept-alive
  // connection of its own (requests beyond that wait for one); over HTTP/2
  // they are streams multiplexed on one connection. The streamer starts
  // this many loader threads for a URL store unless told otherwise
  // (StreamerConfig::io_threads).
  unsigned connections = 32;
  // Offer HTTP/2 to https:// servers (ALPN); the server decides. false:
  // HTTP/1.1 only. http:// is always HTTP/1.1 (docs/decisions.md D198, D199).
  bool http2 = true;
  // Connecting (TCP + TLS) may take this long before the attempt fails.
  uint32_t connect_timeout_ms = 5000;
  // A transfer that moves no byte for this long is a stall and fails.
  uint32_t stall_timeout_ms = 10000;
  // Transient failures (connection refused or reset, timeouts, HTTP 5xx,
  // 429) are retried this many times, waiting retry_base_ms, then twice
  // that, ... before the read fails with kUnavailable.
  uint32_t retries = 2;
  uint32_t retry_base_ms = 100;
  // https:// servers are verified against the system's certificate
  // authorities, or only against this PEM file when it is set (a private CA).
  std::string ca_file;
  // Coalescing (TileStoreReader::readRawBatch): tiles the streamer wants
  // together are read with one range request when their payloads lie at
  // most coalesce_gap_bytes apart, up to coalesce_max_bytes per request and
  // batch_tiles tiles per batch. A gap of 64 KiB costs about 5 ms at
  // 100 Mbit/s, far less than the round trip a second request would.
  uint32_t batch_tiles = 16;
  uint32_t coalesce_gap_bytes = 64 << 10;
  uint32_t coalesce_max_bytes = 2 << 20;
  // A persistent disk cache below the streamer's RAM cache, off when empty:
  // index pages and tile payloads read from the URL are kept as files in
  // this folder (made if missing; its parent must exist), keyed by the URL
  // and the file's version (strong ETag, else Last-Modified, with the
  // size), so a store replaced on the server never uses the old entries.
  // Every entry is checked against the checksum the store's index records,
  // like the server's bytes; a torn or damaged one is removed and fetched
  // again. Stores without ETag or Last-Modified are not cached. Ignored for
  // local files. One folder may serve many stores and programs.
  std::string disk_cache_dir;
  // The folder's cap: least recently used entries are removed to stay
  // under it. The first store opened with a folder in a process sets it.
  uint64_t disk_cache_bytes = uint64_t(1) << 30;
};

// The shape of a batch of tiles worth reading together: the tiles that lie
// together in a store's file. kRow for a store written row by row (a row
// segment of a level is one stretch), kSquare for one in curve order
// (PayloadOrder::kCurve: an aligned square is one stretch).
enum class BatchShape { kRow, kSquare };

// Most connections a RemoteOptions may ask for (each holds a socket and,
// in the streamer, a loader thread).
inline constexpr unsigned kMaxRemoteConnections = 256;

// What a URL store cost so far. All zero for a local store.
struct RemoteStats {
  uint64_t requests = 0;   // HTTP requests sent, retries included
  uint64_t retries = 0;    // of those, repeats after a transient failure
  uint64_t bytes = 0;      // body bytes received (payloads, index, header)
  uint64_t failures = 0;   // reads that returned an error
  uint64_t http2_requests = 0;  // of the requests, those answered over HTTP/2
  uint64_t connections = 0;     // connections opened (TCP, and TLS for https)
  // Disk cache (RemoteOptions::disk_cache_dir) lookups of this store:
  uint64_t disk_cache_hits = 0;     // served from the folder, checksum verified
  uint64_t disk_cache_misses = 0;   // not there: read from the server, then kept
  uint64_t disk_cache_dropped = 0;  // there but torn or damaged: removed, read again
  // Stores whose sub-folder in the cache folder is a symlink or another
  // user's: never followed nor written, so nothing of them is cached. The
  // programs warn about it.
  uint64_t disk_cache_folders_refused = 0;

  // The sum of two stores' figures (a colour and an elevation store).
  RemoteStats& operator+=(const RemoteStats& o) {
    requests += o.requests;
    retries += o.retries;
    bytes += o.bytes;
    failures += o.failures;
    http2_requests += o.http2_requests;
    connections += o.connections;
    disk_cache_hits += o.disk_cache_hits;
    disk_cache_misses += o.disk_cache_misses;
    disk_cache_dropped += o.disk_cache_dropped;
    disk_cache_folders_refused += o.disk_cache_folders_refused;
    return *this;
  }
};

}  // namespace clipstream
