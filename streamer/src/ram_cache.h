// The streamer's RAM cache: the tiles read so far, of every layer, under one
// byte budget, and which of them to give up for a newcomer (the plan-distance
// policy of eviction.h, each tile scored against its own layer's windows).
//
// Not thread-safe: the streamer calls every method under its mutex, from the
// render thread or a loader; tests call it from one thread. It holds no
// lock, starts no thread and reads nothing.
//
// An entry is a placeholder (EntryState::kLoading) from the moment a loader
// takes its tile until the read is published (fill()) or fails (erase()).
// Placeholders count against the budget, so a read never overshoots it, and
// are never evicted.
#pragma once

#include "eviction.h"
#include "layer_tile_hash.h"
#include "lookahead.h"

#include <clipstream/streamer/streamer.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

namespace clipstream {

enum class EntryState : uint8_t { kLoading, kReady };

struct CacheEntry {
  EntryState state = EntryState::kLoading;
  bool gpu = false;                 // handed to the renderer, tile still wanted
  uint64_t last_wanted_frame = 0;   // last plan rebuild that wanted this tile
  std::shared_ptr<const std::vector<uint8_t>> rgba;
};

class RamCache {
 public:
  using Map = std::unordered_map<LayerTile, CacheEntry, FastKeyHash>;
  using Ranks = std::unordered_map<LayerTile, uint32_t, FastKeyHash>;

  // entry_bytes[i]: what one entry of layer i is charged (payload and
  // overhead). on_evict, if set, hears of every tile evicted.
  RamCache(uint64_t budget_bytes, EvictionMode mode, std::vector<uint64_t> entry_bytes,
           std::function<void(const LayerTile&)> on_evict = {});

  uint64_t budgetBytes() const { return m_budget; }
  uint64_t bytes() const { return m_bytes; }
  uint64_t peakBytes() const { return m_peak; }
  size_t size() const { return m_map.size(); }
  uint64_t layerBytes(uint32_t layer) const { return m_layers[layer].bytes; }
  uint64_t layerEntries(uint32_t layer) const { return m_layers[layer].entries; }
  uint64_t entryBytes(uint32_t layer) const { return m_layers[layer].entry_bytes; }
  // An entry of `layer` fits beside what is held, without evicting.
  bool fitsWithoutEviction(uint32_t layer) const {
    return m_bytes + m_layers[layer].entry_bytes <= m_budget;
  }

  bool contains(const LayerTile& key) const { return m_map.count(key) != 0; }
  CacheEntry* find(const LayerTile& key);
  const CacheEntry* find(const LayerTile& key) const;
  // Every entry, for the streamer's passes over the whole cache (GPU flags).
  Map& entries() { return m_map; }

  // Makes room for one entry of `incoming_bytes` ranked `incoming_rank`
  // (0: most wanted). Candidates, in order:
  //  1. tiles that are not wanted, or wanted and already on the GPU
  //     (pyramid tiles only with kGpuFirst), by plan-distance score;
  //  2. wanted tiles still waiting for the GPU (and, with kProtectGpu,
  //     pyramid tiles), only for a better-ranked newcomer, worst rank
  //     first, so a budget below the needed set keeps the coarse levels and
  //     the finest levels stay missing instead of thrashing.
  // False when nothing may be evicted for it (what was evicted stays so).
  bool reserveRoom(uint32_t incoming_rank, uint64_t incoming_bytes);
  // A placeholder for `key`, charged to its layer; the caller made room.
  void insertPlaceholder(const LayerTile& key);
  // The placeholder becomes the tile.
  void fill(const LayerTile& key, std::shared_ptr<const std::vector<uint8_t>> pixels, uint64_t frame);
  // Drops an entry (a failed read's placeholder), uncharging its layer.
  void erase(const LayerTile& key);

  // What the plans want: the rank of every wanted and prefetched tile.
  const Ranks& ranks() const { return m_ranks; }
  void setRanks(Ranks ranks);
  // The windows a layer's tiles are scored against (eviction.h); `ahead`:
  // the path hint's windows, or null.
  void setWindows(uint32_t layer, PlanWindows windows, PlanWindows predicted,
                  std::shared_ptr<const LookaheadSnapshot> ahead);
  void clearAhead();
  // Something that orders victims changed (a hand-off, a plan): the lists
  // are rebuilt before the next eviction. Until then they hold the tiles
  // that were ready when they were built: a tile filled since is not a
  // candidate (the streamer invalidates at every hand-off and plan change).
  void invalidateOrder() { m_order_dirty = true; }

 private:
  struct Layer {
    uint64_t entry_bytes = 0;
    uint64_t bytes = 0;
    uint64_t entries = 0;
    PlanWindows windows;            // current plan
    PlanWindows predicted_windows;  // predicted plan (empty without prefetch)
    std::shared_ptr<const LookaheadSnapshot> ahead;
  };

  bool scoredWhenOnGpu(const LayerTile& key) const;
  void buildVictimLists();
  // Drops an entry and uncharges its layer; evict() also tells on_evict.
  void remove(Map::iterator it);
  void evict(Map::iterator it);

  uint64_t m_budget;
  EvictionMode m_mode;
  std::function<void(const LayerTile&)> m_on_evict;
  std::vector<Layer> m_layers;
  Map m_map;
  Ranks m_ranks;
  uint64_t m_bytes = 0;
  uint64_t m_peak = 0;
  // Eviction candidates sorted best victim first, rebuilt at the first
  // eviction after invalidateOrder(); entries are re-checked when popped.
  std::vector<LayerTile> m_victims;
  size_t m_victims_next = 0;
  // Wanted tiles that only a better-ranked newcomer may evict: worst first.
  std::vector<std::pair<uint32_t, LayerTile>> m_pinned;
  size_t m_pinned_next = 0;
  bool m_order_dirty = true;
};

}  // namespace clipstream
