#include "loader_pool.h"

#include <clipstream/streamer/streamer.h>

#include <algorithm>
#include <cstdlib>
#include <system_error>

namespace clipstream {

unsigned loaderThreadCount(unsigned configured, unsigned suggested, unsigned cores) {
  const unsigned threads = configured ? configured : suggested ? suggested : cores;
  return std::clamp(threads, 1u, kMaxIoThreads);
}

unsigned LoaderPool::start(unsigned count, const std::function<void()>& body) {
  for (unsigned i = 0; i < count; ++i) {
    try {
      m_threads.emplace_back(body);
    } catch (const std::system_error&) {
      break;  // the system's thread limit: run with the loaders that started
    }
  }
  return size();
}

void LoaderPool::join() {
  for (std::thread& t : m_threads)
    if (t.joinable()) t.join();
  m_threads.clear();
}

size_t batchLimit(size_t source_max_batch) { return std::clamp<size_t>(source_max_batch, 1, kMaxBatchTiles); }

uint32_t batchSide(size_t max_batch) {
  uint32_t side = 1;
  while (size_t(side) * 2 * side * 2 <= max_batch) side *= 2;
  return side;
}

bool inBatch(const TileKey& first, const TileKey& t, size_t max_batch, BatchShape shape) {
  if (shape == BatchShape::kSquare) {
    const uint32_t side = batchSide(max_batch);
    return t.x / side == first.x / side && t.y / side == first.y / side;
  }
  return t.y == first.y && std::abs(int64_t(t.x) - int64_t(first.x)) < int64_t(max_batch);
}

void ReadBatch::read(TileSource& source) {
  const size_t n = keys.size();
  pixels.resize(n);
  m_outs.resize(n);
  statuses.assign(n, okStatus());
  infos.assign(n, FetchInfo{});
  for (size_t i = 0; i < n; ++i) {
    pixels[i] = std::make_shared<std::vector<uint8_t>>();
    m_outs[i] = pixels[i].get();
  }
  if (n == 1) {
    statuses[0] = source.fetchWithInfo(keys[0], m_outs[0], &infos[0]);
  } else if (n > 1) {
    source.fetchBatch(keys, m_outs, statuses, infos);
  }
}

}  // namespace clipstream
