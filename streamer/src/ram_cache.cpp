#include "ram_cache.h"

#include <algorithm>
#include <cassert>

namespace clipstream {

RamCache::RamCache(uint64_t budget_bytes, EvictionMode mode, std::vector<uint64_t> entry_bytes,
                   std::function<void(const LayerTile&)> on_evict)
    : m_budget(budget_bytes), m_mode(mode), m_on_evict(std::move(on_evict)) {
  m_layers.resize(entry_bytes.size());
  for (size_t i = 0; i < entry_bytes.size(); ++i) m_layers[i].entry_bytes = entry_bytes[i];
}

CacheEntry* RamCache::find(const LayerTile& key) {
  auto it = m_map.find(key);
  return it == m_map.end() ? nullptr : &it->second;
}

const CacheEntry* RamCache::find(const LayerTile& key) const {
  auto it = m_map.find(key);
  return it == m_map.end() ? nullptr : &it->second;
}

bool RamCache::scoredWhenOnGpu(const LayerTile& key) const {
  return scoredOnGpu(key.key, m_layers[key.layer].windows, m_mode);
}

// Sorts the eviction candidates once per change (plan rebuild, hand-off),
// so each eviction is amortised O(1) instead of a scan of the cache. Tiles
// of every layer compete in one list, each scored against its own layer's
// windows.
void RamCache::buildVictimLists() {
  struct Candidate {
    double score;
    uint64_t stamp;
    LayerTile key;
  };
  std::vector<Candidate> scored_list;
  m_pinned.clear();
  for (const auto& [key, e] : m_map) {
    if (e.state != EntryState::kReady) continue;  // placeholders are never evicted
    const auto r = m_ranks.find(key);
    if (r == m_ranks.end() || (e.gpu && scoredWhenOnGpu(key))) {
      const Layer& layer = m_layers[key.layer];
      scored_list.push_back({evictionScoreAhead(key.key, layer.windows, layer.predicted_windows, m_mode,
                                                e.gpu, layer.ahead.get()),
                             e.last_wanted_frame, key});
    } else {
      m_pinned.emplace_back(r->second, key);
    }
  }
  std::sort(scored_list.begin(), scored_list.end(), [](const Candidate& x, const Candidate& y) {
    return evictsBefore(x.score, x.stamp, y.score, y.stamp);
  });
  std::sort(m_pinned.begin(), m_pinned.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
  m_victims.clear();
  for (const Candidate& c : scored_list) m_victims.push_back(c.key);
  m_victims_next = 0;
  m_pinned_next = 0;
  m_order_dirty = false;
}

void RamCache::remove(Map::iterator it) {
  Layer& layer = m_layers[it->first.layer];
  m_bytes -= layer.entry_bytes;
  layer.bytes -= layer.entry_bytes;
  layer.entries--;
  m_map.erase(it);
}

void RamCache::evict(Map::iterator it) {
  const LayerTile key = it->first;
  remove(it);
  if (m_on_evict) m_on_evict(key);
}

// The lists are re-checked as they are consumed: an entry may have been
// handed off, evicted or re-ranked since they were sorted.
bool RamCache::reserveRoom(uint32_t incoming_rank, uint64_t incoming_bytes) {
  while (m_bytes + incoming_bytes > m_budget) {
    if (m_order_dirty) buildVictimLists();
    bool evicted = false;
    while (!evicted && m_victims_next < m_victims.size()) {
      const LayerTile key = m_victims[m_victims_next++];
      auto it = m_map.find(key);
      if (it == m_map.end() || it->second.state != EntryState::kReady) continue;
      if (m_ranks.count(key) != 0 && (!it->second.gpu || !scoredWhenOnGpu(key))) continue;  // pinned now
      evict(it);
      evicted = true;
    }
    while (!evicted && m_pinned_next < m_pinned.size()) {
      const auto [worst_rank, key] = m_pinned[m_pinned_next];
      if (worst_rank <= incoming_rank) return false;  // nothing ranks below the newcomer
      ++m_pinned_next;
      auto it = m_map.find(key);
      const auto r = m_ranks.find(key);
      if (it == m_map.end() || it->second.state != EntryState::kReady || r == m_ranks.end() ||
          r->second != worst_rank)
        continue;
      evict(it);
      evicted = true;
    }
    if (!evicted) return false;
  }
  return true;
}

void RamCache::insertPlaceholder(const LayerTile& key) {
  const bool inserted = m_map.emplace(key, CacheEntry{}).second;
  assert(inserted);
  (void)inserted;
  Layer& layer = m_layers[key.layer];
  m_bytes += layer.entry_bytes;
  layer.bytes += layer.entry_bytes;
  layer.entries++;
  m_peak = std::max(m_peak, m_bytes);
}

void RamCache::fill(const LayerTile& key, std::shared_ptr<const std::vector<uint8_t>> pixels, uint64_t frame) {
  CacheEntry& e = m_map.at(key);
  e.state = EntryState::kReady;
  e.rgba = std::move(pixels);
  e.last_wanted_frame = frame;
}

void RamCache::erase(const LayerTile& key) {
  auto it = m_map.find(key);
  if (it != m_map.end()) remove(it);
}

void RamCache::setRanks(Ranks ranks) {
  m_ranks = std::move(ranks);
  m_order_dirty = true;
}

void RamCache::setWindows(uint32_t layer, PlanWindows windows, PlanWindows predicted,
                          std::shared_ptr<const LookaheadSnapshot> ahead) {
  Layer& l = m_layers[layer];
  l.windows = std::move(windows);
  l.predicted_windows = std::move(predicted);
  l.ahead = std::move(ahead);
  m_order_dirty = true;
}

void RamCache::clearAhead() {
  for (Layer& l : m_layers) l.ahead = nullptr;
  m_order_dirty = true;
}

}  // namespace clipstream
