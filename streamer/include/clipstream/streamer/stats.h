// Streaming statistics: per level and overall, as a struct and as JSON.
// Thread-safe: plain data (a snapshot taken under the streamer's lock, so
// its counters are mutually consistent).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace clipstream {

struct LevelCounters {
  uint64_t requests = 0;        // tiles asked of the loader
  uint64_t ram_hits = 0;        // tile entering the wanted set found decoded in RAM
  uint64_t ram_misses = 0;      // tile entering the wanted set had to be read
  uint64_t gpu_reentries = 0;   // tile entering the wanted set still on the GPU (it had
                                // not left its needed window): neither a RAM hit nor a miss
  uint64_t gpu_handoffs = 0;    // tiles given to the renderer
  uint64_t cancellations = 0;   // queued requests dropped by a newer plan
  uint64_t evictions = 0;
  uint64_t redundant_reads = 0; // reads of a tile that had been read before
  uint64_t bytes_read = 0;      // payload bytes from the source
  uint64_t failures = 0;
  uint64_t loads = 0;           // successful reads inserted into the RAM cache
  uint64_t budget_skips = 0;    // requests dropped because no worse-ranked tile could be evicted
  // Every request ends in exactly one of loads, failures, cancellations,
  // budget_skips, or is still queued / in flight (see StreamerStats).
};

// One layer of a scene (Streamer with several layers).
struct LayerStats {
  std::vector<LevelCounters> levels;  // index = the layer's level
  LevelCounters total;
  uint64_t ram_bytes = 0;    // this layer's entries, including accounted overhead
  uint64_t ram_entries = 0;
  uint32_t max_texture_lod = 0;  // last handed off
};

struct StreamerStats {
  // index = level; with several layers, the sum over layers of that level
  // (each layer's own figures are in `layers`).
  std::vector<LevelCounters> levels;
  LevelCounters total;                // every layer
  std::vector<LayerStats> layers;     // index = layer; one for a one-source streamer
  uint64_t ram_bytes = 0;             // current, including accounted overhead
  uint64_t ram_budget_bytes = 0;
  uint64_t ram_peak_bytes = 0;
  uint64_t queue_depth = 0;
  uint64_t in_flight = 0;
  // The throttle's allowance is spent: the queued reads wait for the next
  // hand-off (takeReady()), however long the caller waits.
  bool reads_held = false;
  double decode_ms_total = 0.0;
  double queue_latency_p50_ms = 0.0;
  double queue_latency_p99_ms = 0.0;
  uint32_t max_texture_lod = 0;       // layer 0's
  uint64_t ram_entries = 0;           // decoded tiles (and placeholders) in RAM
  uint64_t entry_overhead_bytes = 0;  // per-entry overhead counted with each payload
  uint64_t path_hint_frames = 0;          // update() calls that used the path hint
  uint64_t path_hint_ignored_frames = 0;  // update() calls whose hint disagreed with the camera
  uint32_t loader_threads = 0;  // loader threads started (at most kMaxIoThreads)

  // One JSON object: {"total": {...}, "levels": [{...}, ...], "ram_bytes": ...,
  // "layers": [{"total": {...}, "levels": [...], "ram_bytes": ...}, ...]}
  // with the field names above. Always valid JSON (non-finite numbers as 0).
  std::string toJson() const;
};

}  // namespace clipstream
