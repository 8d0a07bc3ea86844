// The streamer's loader threads, how many to start, and how a loader groups
// queued tiles into one read of a source (a batch).
//
// Threads: LoaderPool is started and joined by the thread that owns the
// streamer (its constructor and shutdown()); the body runs on each loader.
// The batch functions are pure (thread-safe); ReadBatch belongs to the one
// loader that fills it.
#pragma once

#include <clipstream/streamer/tile_source.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <thread>
#include <vector>

namespace clipstream {

// Loaders for a streamer: `configured` if set (StreamerConfig::io_threads),
// else what the sources suggest (a store over HTTP: one per connection, each
// waiting out its round trips), else one per core; at least 1, at most
// kMaxIoThreads.
unsigned loaderThreadCount(unsigned configured, unsigned suggested, unsigned cores);

class LoaderPool {
 public:
  ~LoaderPool() { join(); }
  // Starts `count` threads running `body`; fewer when the system refuses a
  // thread (its thread limit): the streamer runs with those that started.
  // Returns the number started.
  unsigned start(unsigned count, const std::function<void()>& body);
  // Waits for every loader to return from its body.
  void join();
  unsigned size() const { return unsigned(m_threads.size()); }

 private:
  std::vector<std::thread> m_threads;
};

// Most tiles in one batch, and how many requests at the queue's front are
// searched for them: a bounded scan under the lock; deeper requests rank too
// low to be worth pulling forward.
inline constexpr size_t kMaxBatchTiles = 64;
inline constexpr size_t kBatchScanRequests = 256;

// The batch size used for a source asking for `source_max_batch`
// (TileSource::maxBatch()): between 1 and kMaxBatchTiles.
size_t batchLimit(size_t source_max_batch);
// Side of the aligned square of tiles one batch is drawn from: the largest
// power of two whose square holds at most `max_batch` tiles (4 for 16, 8 for
// 64: one index page). Aligned squares of a power-of-two side lie together
// in a store whose payloads follow a space-filling curve (docs/tile-store.md).
uint32_t batchSide(size_t max_batch);
// Whether `t` goes in the batch of `first` (same level, checked by the
// caller): in its row within max_batch columns (BatchShape::kRow), or in its
// aligned square of batchSide(max_batch) tiles (kSquare), as the source's
// file favours.
bool inBatch(const TileKey& first, const TileKey& t, size_t max_batch, BatchShape shape);

// One loader's read of a batch of tiles from one source: one tile by
// fetchWithInfo(), several by fetchBatch(). The vectors keep their capacity
// from batch to batch.
struct ReadBatch {
  std::vector<TileKey> keys;
  std::vector<std::shared_ptr<std::vector<uint8_t>>> pixels;  // one fresh buffer per tile
  std::vector<Status> statuses;
  std::vector<FetchInfo> infos;

  void read(TileSource& source);

 private:
  std::vector<std::vector<uint8_t>*> m_outs;
};

}  // namespace clipstream
