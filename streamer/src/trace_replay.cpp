// Offline replay of a request trace against three cache policies (Belady
// OPT, LRU, the streamer's plan-aware one): replayTrace() and its steps
// (trace_replay.h).
#include "trace_replay.h"

#include "lookahead.h"

#include <list>
#include <memory>
#include <set>
#include <tuple>
#include <unordered_map>

namespace clipstream {
namespace {

// Puts a window line's level rect and kind into *w.
void placeWindow(PlanWindows* w, const TraceEvent& e) {
  if (w->rects.size() <= e.key.level) {
    w->rects.resize(e.key.level + 1);
    w->kinds.resize(e.key.level + 1, PlanWindows::kNotNeeded);
  }
  w->rects[e.key.level] = e.rect;
  w->kinds[e.key.level] = e.kind;
}

}  // namespace

TraceTiles numberTraceTiles(const std::vector<TraceEvent>& events) {
  TraceTiles tiles;
  tiles.id_of.assign(events.size(), 0);
  std::unordered_map<TileKey, uint32_t, TileKeyHash> ids;
  for (size_t i = 0; i < events.size(); ++i) {
    if (events[i].window) continue;
    auto [it, added] = ids.emplace(events[i].key, uint32_t(ids.size()));
    if (added) tiles.key_of.push_back(events[i].key);
    tiles.id_of[i] = it->second;
  }
  return tiles;
}

GpuResidency::GpuResidency(const std::vector<TraceEvent>& events, const TraceTiles& tiles)
    : m_events(events), m_tiles(tiles), m_on_gpu(tiles.key_of.size(), 0),
      m_wanted(tiles.key_of.size(), 0), m_listed(tiles.key_of.size(), 0) {}

bool GpuResidency::step(size_t i) {
  const TraceEvent& e = m_events[i];
  if (e.frame != m_open_frame) {
    if (m_open_frame != kNone) closePlanChange();
    m_open_frame = e.frame;
    m_fresh_windows = true;
  }
  if (e.window) {
    if (e.window != kTraceWindowTag) return false;
    if (m_fresh_windows) m_windows = {}, m_fresh_windows = false;
    placeWindow(&m_windows, e);
    return false;
  }
  const uint32_t id = m_tiles.id_of[i];
  if (e.leave) {
    m_wanted[id] = 0;
    if (m_on_gpu[id] && !m_listed[id]) m_listed[id] = 1, m_left.push_back(id);
    return false;
  }
  // An entry with no leave before it (a hand-written trace) is an access.
  const bool served = m_on_gpu[id] && !m_wanted[id];
  m_wanted[id] = 1;
  m_on_gpu[id] = 1;
  return served;
}

bool GpuResidency::inNeededWindow(const TileKey& k) const {
  if (k.level >= m_windows.kinds.size()) return false;
  const uint8_t kind = m_windows.kinds[k.level];
  return kind == PlanWindows::kPyramid ||
         (kind == PlanWindows::kNeeded && m_windows.rects[k.level].contains(k.x, k.y));
}

void GpuResidency::closePlanChange() {
  std::vector<uint32_t> kept;
  for (uint32_t id : m_left) {
    if (m_on_gpu[id] && !m_wanted[id] && inNeededWindow(m_tiles.key_of[id])) {
      kept.push_back(id);
      continue;
    }
    if (!m_wanted[id]) m_on_gpu[id] = 0;  // else back in the wanted set: stays
    m_listed[id] = 0;
  }
  m_left.swap(kept);
}

std::vector<uint8_t> markAccesses(const std::vector<TraceEvent>& events, const TraceTiles& tiles,
                                  ReplayResult* result) {
  std::vector<uint8_t> access(events.size(), 0);
  GpuResidency gpu(events, tiles);
  for (size_t i = 0; i < events.size(); ++i) {
    const bool served = gpu.step(i);
    if (!events[i].isAccess()) continue;
    if (served) result->gpu_reentries++;
    else access[i] = 1, result->accesses++;
  }
  return access;
}

uint64_t replayOpt(const TraceTiles& tiles, const std::vector<uint8_t>& access, uint64_t capacity_tiles) {
  constexpr uint64_t kNever = UINT64_MAX;
  const size_t n_ids = tiles.key_of.size();
  // Next access of the same tile, per access.
  std::vector<uint64_t> next_use(access.size(), kNever);
  {
    std::vector<uint64_t> seen(n_ids, kNever);
    for (size_t i = access.size(); i-- > 0;) {
      if (!access[i]) continue;
      next_use[i] = seen[tiles.id_of[i]];
      seen[tiles.id_of[i]] = i;
    }
  }
  uint64_t hits = 0;
  std::set<std::pair<uint64_t, uint32_t>> by_next;  // (next use, id)
  std::vector<uint64_t> cached_next(n_ids, 0);
  std::vector<uint8_t> in_cache(n_ids, 0);
  for (size_t i = 0; i < access.size(); ++i) {
    if (!access[i]) continue;
    const uint32_t id = tiles.id_of[i];
    if (in_cache[id]) {
      hits++;
      by_next.erase({cached_next[id], id});
    } else if (by_next.size() >= capacity_tiles) {
      auto last = std::prev(by_next.end());
      if (last->first <= next_use[i]) continue;  // bypass
      in_cache[last->second] = 0;
      by_next.erase(last);
    }
    in_cache[id] = 1;
    cached_next[id] = next_use[i];
    by_next.insert({next_use[i], id});
  }
  return hits;
}

uint64_t replayLru(const TraceTiles& tiles, const std::vector<uint8_t>& access, uint64_t capacity_tiles) {
  const size_t n_ids = tiles.key_of.size();
  uint64_t hits = 0;
  std::list<uint32_t> order;  // front = most recent
  std::vector<std::list<uint32_t>::iterator> where(n_ids);
  std::vector<uint8_t> in_cache(n_ids, 0);
  for (size_t i = 0; i < access.size(); ++i) {
    if (!access[i]) continue;
    const uint32_t id = tiles.id_of[i];
    if (in_cache[id]) {
      hits++;
      order.erase(where[id]);
    } else if (order.size() >= capacity_tiles) {
      in_cache[order.back()] = 0;
      order.pop_back();
    }
    in_cache[id] = 1;
    order.push_front(id);
    where[id] = order.begin();
  }
  return hits;
}

namespace {

// The plan the window and time lines of the trace record, gathered line by
// line: a frame's first window or time line starts a new plan change; the
// plan it names takes effect at the frame's first tile line, and only when
// the frame had window lines (a frame without them keeps the plan it had).
// Used by one thread at a time (its replay's).
class RecordedPlan {
 public:
  // Takes a window, predicted-window or time line.
  void take(const TraceEvent& e) {
    if (e.frame != m_frame) {
      m_frame = e.frame;
      m_windows = {};
      m_predicted = {};
      m_hint_used = false;
    }
    if (e.window == kTraceTimeTag) {
      m_time_s = e.time_s;
      m_viewport = e.viewport;
      m_hint_used = e.kind != 0;
      return;
    }
    placeWindow(e.window == kTraceWindowTag ? &m_windows : &m_predicted, e);
    m_changed = true;
  }
  // True when window lines came since the last takeChange().
  bool changed() const { return m_changed; }
  // The plan of the last window lines, finished (eviction.h); clears changed().
  void takeChange(PlanWindows* current, PlanWindows* predicted) {
    *current = m_windows;
    current->finish();
    *predicted = m_predicted;
    if (!predicted->empty()) predicted->finish();
    m_changed = false;
  }
  // The time line of the plan change: when and at which viewport the
  // streamer planned, and whether it used its path hint.
  double timeS() const { return m_time_s; }
  const Viewport& viewport() const { return m_viewport; }
  bool hintUsed() const { return m_hint_used; }

 private:
  PlanWindows m_windows, m_predicted;
  uint64_t m_frame = UINT64_MAX;
  bool m_changed = false;
  double m_time_s = 0.0;
  Viewport m_viewport{0, 0};
  bool m_hint_used = false;
};

// The streamer's RAM cache under its eviction policy, fed the trace event
// by event: replayPlanAware() runs one. Every access is handed to the GPU
// at once, so a cached tile is either on the GPU (wanted) or not wanted:
// all are scored but pyramid tiles under kProtectGpu (streamer.cpp,
// buildVictimLists). Victims come from the end of the candidates, in the
// streamer's order (evictsBefore). Used by one thread at a time; the
// events, tiles, access marks and hint must outlive it.
class PlanAwareCache {
 public:
  PlanAwareCache(const std::vector<TraceEvent>& events, const TraceTiles& tiles,
                 const std::vector<uint8_t>& access, uint64_t capacity_tiles, EvictionMode mode,
                 const ReplayHint* hint)
      : m_events(events), m_tiles(tiles), m_access(access), m_capacity_tiles(capacity_tiles),
        m_mode(mode), m_hint(hint), m_gpu(events, tiles), m_in_cache(tiles.key_of.size(), 0),
        m_wanted(tiles.key_of.size(), 0), m_entering(tiles.key_of.size(), 0),
        m_stamp(tiles.key_of.size(), 0), m_score(tiles.key_of.size(), 0.0) {}

  // Replays every event; returns the hits.
  uint64_t run() {
    for (size_t i = 0; i < m_events.size(); ++i) {
      (void)m_gpu.step(i);  // m_access already says which entries it serves
      if (m_events[i].window) {
        m_plan.take(m_events[i]);
        continue;
      }
      if (m_plan.changed()) applyPlanChange(i);
      takeTileEvent(i);
    }
    return m_hits;
  }

 private:
  using Slot = std::tuple<double, uint64_t, uint32_t>;  // (score, stamp, id)
  // Victims last: the set's end holds the tile evicted first.
  struct VictimLast {
    bool operator()(const Slot& a, const Slot& b) const {
      if (std::get<0>(a) != std::get<0>(b) || std::get<1>(a) != std::get<1>(b))
        return evictsBefore(std::get<0>(b), std::get<1>(b), std::get<0>(a), std::get<1>(a));
      return std::get<2>(a) < std::get<2>(b);
    }
  };

  Slot slotOf(uint32_t id) const { return Slot{m_score[id], m_stamp[id], id}; }
  bool scored(uint32_t id) const { return scoredOnGpu(m_tiles.key_of[id], m_current, m_mode); }

  // Makes the recorded plan current at event i (the frame's first tile
  // line), with the hinted path's plans when the streamer used the hint.
  void applyPlanChange(size_t i) {
    m_plan.takeChange(&m_current, &m_predicted);
    m_ahead = nullptr;
    if (m_hint && m_plan.hintUsed()) {
      m_lookahead.advance(m_hint->geometry, m_plan.viewport(), m_hint->planner, m_hint->path, m_plan.timeS());
      m_ahead = m_lookahead.snapshot();
    }
    rescore(i);
  }

  // Scores a cached tile under the current plan and makes it a candidate,
  // unless it is unscored or pinned (entering).
  void enroll(uint32_t id) {
    if (!scored(id) || m_entering[id]) return;
    m_score[id] = evictionScoreAhead(m_tiles.key_of[id], m_current, m_predicted, m_mode, m_gpu.onGpu(id),
                                     m_ahead.get());
    m_candidates.insert(slotOf(id));
  }

  // At a plan change starting at event seq: pins the tiles it brings in
  // until their entry, as the streamer pins wanted tiles that are in RAM but
  // not yet on the GPU (an entry is not evicted for an earlier one of the
  // same plan change), and rescores every cached tile.
  void rescore(size_t seq) {
    for (uint32_t id : m_entering_ids) m_entering[id] = 0;
    m_entering_ids.clear();
    for (size_t j = seq; j < m_events.size() && m_events[j].frame == m_events[seq].frame; ++j) {
      const uint32_t id = m_tiles.id_of[j];
      if (m_access[j] && !m_entering[id]) m_entering[id] = 1, m_entering_ids.push_back(id);
    }
    m_candidates.clear();
    std::vector<uint32_t> live;
    for (uint32_t id : m_cached_ids) {
      if (!m_in_cache[id]) continue;
      live.push_back(id);
      if (m_wanted[id]) m_stamp[id] = seq;
      enroll(id);
    }
    m_cached_ids.swap(live);
  }

  // Takes tile event i: a leave or an entry the GPU serves moves the tile's
  // stamp; an access hits, or misses and takes a slot (evicting the last
  // candidate when full, or bypassing when there is none).
  void takeTileEvent(size_t i) {
    const TraceEvent& e = m_events[i];
    const uint32_t id = m_tiles.id_of[i];
    if (e.leave || !m_access[i]) {
      if (m_in_cache[id] && scored(id)) {
        m_candidates.erase(slotOf(id));
        m_stamp[id] = i;
        m_candidates.insert(slotOf(id));
      } else {
        m_stamp[id] = i;
      }
      m_wanted[id] = e.leave ? 0 : 1;
      return;
    }
    m_wanted[id] = 1;
    m_entering[id] = 0;
    if (m_in_cache[id]) {
      m_hits++;
      if (scored(id)) m_candidates.erase(slotOf(id));
      m_stamp[id] = i;
      enroll(id);
      return;
    }
    m_stamp[id] = i;
    if (m_cached >= m_capacity_tiles) {
      if (m_candidates.empty()) return;  // only unscored pyramid tiles cached: bypass
      auto victim = std::prev(m_candidates.end());
      m_in_cache[std::get<2>(*victim)] = 0;
      m_candidates.erase(victim);
      m_cached--;
    }
    m_in_cache[id] = 1;
    m_cached++;
    m_cached_ids.push_back(id);
    enroll(id);
  }

  const std::vector<TraceEvent>& m_events;
  const TraceTiles& m_tiles;
  const std::vector<uint8_t>& m_access;
  const uint64_t m_capacity_tiles;
  const EvictionMode m_mode;
  const ReplayHint* const m_hint;  // null: no hinted plans
  GpuResidency m_gpu;
  RecordedPlan m_plan;
  PlanWindows m_current, m_predicted;
  PathLookahead m_lookahead;
  std::shared_ptr<const LookaheadSnapshot> m_ahead;  // null: no hinted plans this plan change
  std::set<Slot, VictimLast> m_candidates;
  std::vector<uint8_t> m_in_cache, m_wanted, m_entering;
  std::vector<uint64_t> m_stamp;  // trace position the tile was last wanted
  std::vector<double> m_score;
  std::vector<uint32_t> m_cached_ids;  // may hold evicted ids until the next rescore
  std::vector<uint32_t> m_entering_ids;
  uint64_t m_cached = 0;
  uint64_t m_hits = 0;
};

}  // namespace

uint64_t replayPlanAware(const std::vector<TraceEvent>& events, const TraceTiles& tiles,
                         const std::vector<uint8_t>& access, uint64_t capacity_tiles, EvictionMode mode,
                         const ReplayHint* hint) {
  return PlanAwareCache(events, tiles, access, capacity_tiles, mode, hint).run();
}

ReplayResult replayTrace(const std::vector<TraceEvent>& events, uint64_t capacity_tiles,
                         const ReplayHint* hint) {
  ReplayResult result;
  result.capacity_tiles = capacity_tiles;
  const TraceTiles tiles = numberTraceTiles(events);
  result.distinct_tiles = tiles.key_of.size();
  // Entries the GPU serves are not accesses (GpuResidency).
  const std::vector<uint8_t> access = markAccesses(events, tiles, &result);
  if (capacity_tiles == 0) return result;
  result.hits_opt = replayOpt(tiles, access, capacity_tiles);
  result.hits_lru = replayLru(tiles, access, capacity_tiles);
  // Plan-aware: the streamer's policy over the recorded windows, both
  // modes, and kGpuFirst with the path hint when there is one.
  result.hits_plan = replayPlanAware(events, tiles, access, capacity_tiles, EvictionMode::kProtectGpu, nullptr);
  result.hits_gpu_first = replayPlanAware(events, tiles, access, capacity_tiles, EvictionMode::kGpuFirst, nullptr);
  if (hint && hint->path.camera_at)
    result.hits_hinted = replayPlanAware(events, tiles, access, capacity_tiles, EvictionMode::kGpuFirst, hint);
  return result;
}

}  // namespace clipstream
