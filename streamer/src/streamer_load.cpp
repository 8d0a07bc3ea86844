// The streamer's loading half (streamer_impl.h): loaders admit requests
// into the RAM cache, read them unlocked and publish them; with
// deterministic I/O the render thread issues and publishes the reads as
// I/O-device tickets instead; the throttle sets how far the reads may run
// ahead of the uploads.
#include "streamer_impl.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>

namespace clipstream {
namespace {

// Latency samples kept for the p50/p99 estimate: the most recent ones.
constexpr size_t kLatencySamples = 4096;
// Distinct failing tiles logged to stderr before logging goes quiet.
constexpr uint32_t kMaxLoggedFailures = 16;
// Back-off for transient (kUnavailable) failures: the n-th failure of a tile
// waits kRetryBaseS * 2^n, so 1 s, 2 s, 4 s ... capped at kRetryMaxS.
constexpr double kRetryBaseS = 0.5;
constexpr double kRetryMaxS = 30.0;

}  // namespace

// Takes a popped request for loading: counts its wait, cancels it if
// another path loaded it, reserves room and inserts its placeholder.
// Returns false when there is nothing to read. A neighbour (taken along
// with another request) that does not fit the budget is left in the queue
// instead: *no_room tells the caller to stop taking neighbours. Caller
// holds the mutex.
bool Streamer::Impl::admit(const Request& request, bool neighbour, bool* reread, bool* no_room) {
  const LayerTile key = request.key;
  Layer& layer = layers[key.layer];
  LevelCounters& level_counters = layer.counters[key.key.level];
  if (neighbour && !cache->contains(key) && !cache->fitsWithoutEviction(key.layer)) {
    *no_room = true;  // eviction is the popped request's business, not a neighbour's
    return false;
  }
  const double waited_ms =
      std::chrono::duration<double, std::milli>(Clock::now() - request.queued_at).count();
  if (latency_ms.size() < kLatencySamples) {
    latency_ms.push_back(waited_ms);
  } else {
    latency_ms[latency_next] = waited_ms;
    latency_next = (latency_next + 1) % kLatencySamples;
  }
  if (cache->contains(key)) {
    // Queued before another path loaded it; nothing to read.
    level_counters.cancellations++;
    return false;
  }
  if (!cache->reserveRoom(request.rank, layer.entry_bytes)) {
    level_counters.budget_skips++;
    return false;
  }
  // Placeholder first so nobody reads this tile twice, then read unlocked.
  cache->insertPlaceholder(key);
  in_flight++;
  *reread = !ever_read.insert(key).second;
  return true;
}

// Deterministic I/O, a loader with the lock held: reads the oldest ticket
// unlocked and marks it done (the render thread publishes it).
void Streamer::Impl::readTicket(std::unique_lock<std::mutex>& lock, std::vector<float>* floats) {
  const std::shared_ptr<IoTicket> ticket = io.takeWork();
  const Layer& layer = layers[ticket->key.layer];
  lock.unlock();
  ticket->status = layer.spec.source->fetchWithInfo(ticket->key.key, ticket->pixels.get(), &ticket->info);
  ticket->detail = detailOf(layer, ticket->key, ticket->status, *ticket->pixels, floats);
  lock.lock();
  io.finished(*ticket);
}

// A source that reads neighbours in one request (a store over HTTP) gets
// more queued tiles of the popped tile's layer and level, those inBatch()
// of it (loader_pool.h): the source reads what lies together with one range
// request and the rest at the same time. Only the front of the queue is
// searched, so the batch stays among the best-ranked tiles and the scan is
// bounded. Admits each and appends it to *tiles. Caller holds the mutex.
void Streamer::Impl::gatherBatch(const Request& request, std::vector<LayerTile>* tiles,
                                 std::vector<bool>* rereads) {
  const Layer& layer = layers[request.key.layer];
  const size_t max_batch = batchLimit(layer.spec.source->maxBatch());
  if (max_batch <= 1) return;
  const TileKey& first = request.key.key;
  const BatchShape shape = layer.spec.source->batchShape();
  const size_t scan = std::min(queue.size(), kBatchScanRequests);
  std::vector<size_t> taken;
  bool reread = false, no_room = false;
  for (size_t i = 0; i < scan && tiles->size() < max_batch && !no_room; ++i) {
    const LayerTile& t = queue[i].key;
    if (t.layer != request.key.layer || t.key.level != first.level) continue;
    if (!inBatch(first, t.key, max_batch, shape)) continue;
    if (admit(queue[i], true, &reread, &no_room)) {
      tiles->push_back(t);
      rereads->push_back(reread);
    }
    if (!no_room) taken.push_back(i);
  }
  for (size_t j = taken.size(); j-- > 0;) queue.erase(queue.begin() + std::ptrdiff_t(taken[j]));
}

void Streamer::Impl::workerLoop() {
  std::vector<LayerTile> tiles;
  std::vector<bool> rereads;
  ReadBatch batch;
  std::vector<std::shared_ptr<const TileDetail>> details;
  std::vector<float> floats;
  std::unique_lock<std::mutex> lock(mutex);
  for (;;) {
    // With deterministic I/O the queue is the render thread's to issue
    // from; workers take only tickets, and finish them before they stop.
    work_cv.wait(lock, [&] {
      return stopping || io.hasWork() || (!deterministic() && !queue.empty() && read_allowance > 0);
    });
    if (io.hasWork()) {
      readTicket(lock, &floats);
      continue;
    }
    if (stopping) return;
    const Request request = queue.front();
    queue.pop_front();
    tiles.clear();
    rereads.clear();
    bool reread = false, no_room = false;
    if (!admit(request, false, &reread, &no_room)) continue;
    tiles.push_back(request.key);
    rereads.push_back(reread);
    gatherBatch(request, &tiles, &rereads);
    read_allowance -= int64_t(tiles.size());
    Layer& layer = layers[request.key.layer];
    lock.unlock();

    const size_t n = tiles.size();
    batch.keys.resize(n);
    for (size_t i = 0; i < n; ++i) batch.keys[i] = tiles[i].key;
    batch.read(*layer.spec.source);
    details.assign(n, nullptr);
    for (size_t i = 0; i < n; ++i)
      details[i] = detailOf(layer, tiles[i], batch.statuses[i], *batch.pixels[i], &floats);

    lock.lock();
    for (size_t i = 0; i < n; ++i)
      publishLocked(tiles[i], batch.statuses[i], std::move(batch.pixels[i]), batch.infos[i], rereads[i],
                    std::move(details[i]));
  }
}

// The terrain's tiles also refine the planner's bounds: the ranges of their
// cells (their samples, widened by the tile's error from the index, which
// the read has just used). Null for other layers' tiles and failed reads.
// No lock needed: reads only what the constructor fixed.
std::shared_ptr<const TileDetail> Streamer::Impl::detailOf(const Layer& layer, const LayerTile& key,
                                                           const Status& status,
                                                           const std::vector<uint8_t>& pixels,
                                                           std::vector<float>* floats) const {
  if (int(key.layer) != terrain_layer || !status || pixels.size() != layer.tile_bytes) return nullptr;
  TileHeightBounds hb;
  if (!layer.spec.source->tileHeightBounds(key.key, &hb)) return nullptr;
  floats->resize(pixels.size() / sizeof(float));
  std::memcpy(floats->data(), pixels.data(), pixels.size());
  return makeTileDetail(layer.geometry.tile_px, floats->data(), hb.error);
}

// A finished read into the cache (its placeholder becomes the tile) or, when
// it failed, into the failure map. Caller holds the mutex.
void Streamer::Impl::publishLocked(const LayerTile& key, const Status& status,
                                   std::shared_ptr<std::vector<uint8_t>> pixels, const FetchInfo& info,
                                   bool reread, std::shared_ptr<const TileDetail> tile_detail) {
  Layer& layer = layers[key.layer];
  const bool good = status.ok() && pixels->size() == layer.tile_bytes;
  LevelCounters& level_counters = layer.counters[key.key.level];
  in_flight--;
  level_counters.bytes_read += info.bytes_read;
  decode_ms_total += info.decode_ms;
  if (reread) level_counters.redundant_reads++;
  if (good) {
    if (tile_detail) new_detail.emplace_back(key.key, std::move(tile_detail));
    level_counters.loads++;
    cache->fill(key, std::move(pixels), shared_frame);
  } else {
    cache->erase(key);
    level_counters.failures++;
    FailedTile& f = failed[key];
    f.code = status.ok() ? ErrorCode::kCorruptTile : status.code;
    f.count++;
    f.retry_at_s = shared_now_s + std::min(kRetryMaxS, kRetryBaseS * double(1u << std::min(f.count, 16u)));
    if (f.count == 1 && logged_failures < kMaxLoggedFailures) {
      logged_failures++;
      const std::string why = status.ok() ? "tile has the wrong size" : status.toString();
      std::fprintf(stderr, "clipstream: %s: level %u tile (%u, %u) failed: %s%s\n",
                   layer.spec.source->describe().c_str(), key.key.level, key.key.x, key.key.y, why.c_str(),
                   logged_failures == kMaxLoggedFailures ? " (further failures not logged)" : "");
    }
  }
}

// Deterministic I/O, render thread: publishes the issued reads due by this
// frame (all of them with `all`, at shutdown), in issue order, waiting for
// the workers to finish each. The wait is the point of the mode: a slow
// machine takes longer per frame but shows the same frames.
void Streamer::Impl::publishDueReads(bool all) {
  std::unique_lock<std::mutex> lock(mutex);
  while (const std::shared_ptr<IoTicket> ticket = io.nextDue(lock, frame, all)) {
    shared_now_s = now_s;  // retry times of failures count from this frame
    publishLocked(ticket->key, ticket->status, std::move(ticket->pixels), ticket->info, ticket->reread,
                  std::move(ticket->detail));
  }
}

// Deterministic I/O, render thread: this frame's reads. Pops the queue's
// front as a worker would (admit(): cancellation, budget, eviction,
// placeholder) until reads_per_frame reads are issued, each due
// latency_frames frames from now. One tile a read: batching changes how
// fast a store over HTTP is read, not what a frame shows.
void Streamer::Impl::issueReads() {
  const uint32_t reads = std::max(1u, config.deterministic_io.reads_per_frame);
  const uint64_t due = frame + std::max(1u, config.deterministic_io.latency_frames);
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (stopping || loader_threads == 0) return;  // no worker would ever finish a ticket
    for (uint32_t issued = 0; issued < reads && !queue.empty() && read_allowance > 0;) {
      const Request request = queue.front();
      queue.pop_front();
      bool reread = false, no_room = false;
      if (!admit(request, false, &reread, &no_room)) continue;
      io.issue(request.key, due, reread);
      ++issued;
      --read_allowance;
    }
  }
  work_cv.notify_all();
}

// The throttle (docs/decisions.md D61): with an upload budget of
// B tiles a frame, the loaders read no further ahead of the uploads than
// throttle_read_ahead_frames x B wanted tiles, or
// throttle_read_ahead_min_tiles if more, waiting in RAM (or on their
// way) for the GPU. Reads go in load order, coarse levels first, so when
// the uploads cannot keep up the finer levels wait to be read instead of
// being read, decoded and evicted unseen, and every read of a coarse tile
// entering the view finds a loader free. Set once a frame by handOff(),
// under the lock; no budget seen yet, or throttling off: no limit.
void Streamer::Impl::setReadAllowance(uint64_t budget) {
  if (!config.throttle || budget == 0) {
    read_allowance = std::numeric_limits<int64_t>::max();
    return;
  }
  const uint64_t frames = std::max<uint64_t>(config.throttle_read_ahead_frames, 1);
  const uint64_t most = uint64_t(std::numeric_limits<int64_t>::max());
  const uint64_t by_frames = budget > most / frames ? most : budget * frames;
  const uint64_t limit = std::max<uint64_t>(by_frames, config.throttle_read_ahead_min_tiles);
  uint64_t backlog = 0;
  for (const LayerTile& k : pending)
    if (cache->contains(k)) ++backlog;
  read_allowance = backlog >= limit ? 0 : int64_t(limit - backlog);
}

}  // namespace clipstream
