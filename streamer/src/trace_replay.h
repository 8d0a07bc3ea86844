// The steps of replayTrace() (trace.h): the trace's tiles numbered, the
// tiles the GPU holds as the trace goes (which entries are accesses), and
// one replay per cache policy. Internal to the streamer library; the tests
// check each step alone.
//
// Thread rule: the functions are pure over caller-owned data, safe from
// any thread; a GpuResidency is used by one thread at a time.
#pragma once

#include "eviction.h"

#include <clipstream/store/types.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>

#include <cstdint>
#include <vector>

namespace clipstream {

// The tiles of a trace under dense ids, numbered in order of first
// appearance: the replays index plain vectors by id instead of hashing keys.
struct TraceTiles {
  std::vector<uint32_t> id_of;  // per event: its tile's id (0 for window and time events)
  std::vector<TileKey> key_of;  // per id: the tile
};

// Numbers the tiles of the tile events (entries and leaves) of `events`.
TraceTiles numberTraceTiles(const std::vector<TraceEvent>& events);

// Which tiles the GPU holds as the trace goes: a tile is handed over at its
// access (every access is taken to be handed over at once, as in the rest
// of the replay) and stays until a plan change finds it neither wanted nor
// in its needed window (the streamer's rule, streamer.cpp rebuild()). So an
// entry of a tile that left the wanted set but not its window is served by
// the GPU: not an access. This depends on the trace alone, not on a policy.
// A plan change is its frame's lines; one without window lines keeps the
// windows it had. Call step(i) for every event in order. `events` and
// `tiles` must outlive the object. Used by one thread at a time.
class GpuResidency {
 public:
  GpuResidency(const std::vector<TraceEvent>& events, const TraceTiles& tiles);

  // Takes event i; true when it is an entry the GPU serves.
  bool step(size_t i);
  // True when tile `id` is on the GPU after the events taken so far.
  bool onGpu(uint32_t id) const { return m_on_gpu[id] != 0; }

 private:
  static constexpr uint64_t kNone = UINT64_MAX;
  bool inNeededWindow(const TileKey& k) const;
  // Ends the open plan change: a tile that left the wanted set stays on the
  // GPU while it is in a needed window of the plan.
  void closePlanChange();

  const std::vector<TraceEvent>& m_events;
  const TraceTiles& m_tiles;
  std::vector<uint8_t> m_on_gpu, m_wanted, m_listed;  // m_listed: in m_left
  std::vector<uint32_t> m_left;  // ids that left the wanted set while on the GPU
  PlanWindows m_windows;
  uint64_t m_open_frame = kNone;
  bool m_fresh_windows = false;  // the next window line starts a new set
};

// Marks the accesses of `events`: 1 for a tile entry the GPU does not serve
// (GpuResidency), 0 for every other event. Counts them in
// result->accesses and the entries the GPU serves in result->gpu_reentries.
std::vector<uint8_t> markAccesses(const std::vector<TraceEvent>& events, const TraceTiles& tiles,
                                  ReplayResult* result);

// Hits of Belady's OPT over the accesses (`access` from markAccesses()) in
// a cache of capacity_tiles tiles (at least 1): a miss evicts the tile used
// farthest in the future, or bypasses the cache when the newcomer itself is
// used farthest.
uint64_t replayOpt(const TraceTiles& tiles, const std::vector<uint8_t>& access, uint64_t capacity_tiles);

// Hits of least-recently-used replacement over the accesses, as replayOpt().
uint64_t replayLru(const TraceTiles& tiles, const std::vector<uint8_t>& access, uint64_t capacity_tiles);

// Hits of the streamer's policy (eviction.h) in `mode` over the accesses,
// as replayOpt(), with the plans the trace's window lines record. With a
// hint (null: none), every plan change whose time line says the streamer
// used it also scores tiles by the hinted path's predicted returns
// (lookahead.h), planned at the recorded time and viewport.
uint64_t replayPlanAware(const std::vector<TraceEvent>& events, const TraceTiles& tiles,
                         const std::vector<uint8_t>& access, uint64_t capacity_tiles, EvictionMode mode,
                         const ReplayHint* hint);

}  // namespace clipstream
