// Trace lines written and read (one definition of each line format), and
// offline replay against three cache policies.
#include <clipstream/streamer/trace.h>

#include "eviction.h"
#include "lookahead.h"

#include <sys/stat.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <list>
#include <set>
#include <sstream>
#include <string_view>
#include <type_traits>
#include <unordered_map>

namespace clipstream {

static_assert(std::string_view(kTraceHeader).starts_with(kTraceMagic),
              "the header line starts with the magic");
static_assert(std::string_view(kTraceHeader).substr(std::string_view(kTraceMagic).size(), 2) ==
                  "2:" && kTraceVersion == 2,
              "the header line names kTraceVersion");

namespace {

// The line formats as readTrace() names them in its messages.
constexpr const char* kTileLineFormat = "'frame level x y'";
constexpr const char* kWindowLineFormat = "'w|p frame level x0 y0 x1 y1 kind'";
constexpr const char* kTimeLineFormat = "'t frame seconds 0|1 width height'";

void appendFields(std::string* out) { *out += '\n'; }

// " a b c...\n": every field preceded by one space, then the newline.
template <typename T, typename... Rest>
void appendFields(std::string* out, T value, Rest... rest) {
  *out += ' ';
  if constexpr (std::is_same_v<T, const char*>) {
    *out += value;
  } else {
    *out += std::to_string(value);
  }
  appendFields(out, rest...);
}

}  // namespace

void appendTraceLine(const TraceEvent& e, std::string* out) {
  switch (e.window) {
    case kTraceTimeTag: {
      // Exact time: the replay re-plans the path hint at it.
      char time_text[32];
      std::snprintf(time_text, sizeof time_text, "%.17g", std::isfinite(e.time_s) ? e.time_s : 0.0);
      *out += kTraceTimeTag;
      appendFields(out, e.frame, static_cast<const char*>(time_text), unsigned(e.kind),
                   e.viewport.width_px, e.viewport.height_px);
      return;
    }
    case kTraceWindowTag:
    case kTracePredictedTag:
      *out += e.window;
      appendFields(out, e.frame, e.key.level, e.rect.x0, e.rect.y0, e.rect.x1, e.rect.y1,
                   unsigned(e.kind));
      return;
    default:
      // A tile entry starts with its frame, a leave with its tag.
      if (e.leave) {
        *out += kTraceLeaveTag;
        *out += ' ';
      }
      *out += std::to_string(e.frame);
      appendFields(out, e.key.level, e.key.x, e.key.y);
      return;
  }
}

Status readTrace(const std::string& path, std::vector<TraceEvent>* events) {
  events->clear();
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    return Status::error(ErrorCode::kIo, "trace " + path + " is not a regular file");
  }
  if (uint64_t(st.st_size) > kMaxTraceFileBytes) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "trace " + path + " is " + std::to_string(uint64_t(st.st_size) >> 20) +
                             " MiB, larger than any trace read here (" +
                             std::to_string(kMaxTraceFileBytes >> 20) + " MiB at most)");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Status::error(errno == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                         "cannot open trace " + path + ": " + std::strerror(errno));
  }
  // Shown in messages: at most 80 bytes of the line, control bytes as '?'.
  auto bad = [&](uint64_t line_no, const std::string& expected, const std::string& line) {
    return Status::error(ErrorCode::kInvalidArgument, path + ":" + std::to_string(line_no) +
                                                          ": expected " + expected + ", got '" +
                                                          printableText(line, 80) + "'");
  };
  std::string line;
  uint64_t line_no = 0;
  // The first bytes name the format: checked before reading a line, so a
  // huge file of another kind is refused at once, not read whole.
  {
    char head[20] = {};
    in.read(head, sizeof head);
    const std::string got(head, size_t(in.gcount()));
    const std::string magic = kTraceMagic;
    if (got.empty()) {
      if (in.bad()) return Status::error(ErrorCode::kIo, "error reading trace " + path);
      return Status::error(ErrorCode::kInvalidArgument, path + " is empty, not a clipstream trace");
    }
    if (got != magic.substr(0, got.size()) || got.size() < magic.size())
      return bad(1, "the header '" + magic + std::to_string(kTraceVersion) + "...'", got);
    in.clear();
    in.seekg(0);
  }
  // The first line names the format: an empty file or another file is not a trace.
  if (!std::getline(in, line)) {
    if (in.bad()) return Status::error(ErrorCode::kIo, "error reading trace " + path);
    return Status::error(ErrorCode::kInvalidArgument, path + " is empty, not a clipstream trace");
  }
  ++line_no;
  const std::string magic = kTraceMagic;
  const std::string version = std::to_string(kTraceVersion);
  if (line.compare(0, magic.size(), magic) != 0) {
    return bad(line_no, "the header '" + magic + version + "...'", line);
  }
  if (line.compare(0, magic.size() + version.size() + 1, magic + version + ":") != 0) {
    return Status::error(ErrorCode::kUnsupported,
                         path + ": trace format '" + printableText(line, 24) + "' is not v" +
                             std::to_string(kTraceVersion));
  }
  while (std::getline(in, line)) {
    ++line_no;
    // Every line the streamer writes ends in a newline: a last line without
    // one is a trace cut short (a crash, a full disk).
    if (in.eof()) {
      return Status::error(ErrorCode::kTruncated,
                           path + ":" + std::to_string(line_no) +
                               ": the trace ends in the middle of a line (truncated)");
    }
    if (line.empty() || line[0] == kTraceCommentTag) continue;
    std::istringstream fields(line);
    TraceEvent e;
    if (line[0] == kTraceWindowTag || line[0] == kTracePredictedTag) {
      e.window = line[0];
      fields.get();
      uint64_t level = 0;
      int kind = 0;
      if (!(fields >> e.frame >> level >> e.rect.x0 >> e.rect.y0 >> e.rect.x1 >> e.rect.y1 >> kind) ||
          level > 63 || kind < 0 || kind > 2) {
        return bad(line_no, kWindowLineFormat, line);
      }
      e.key.level = uint32_t(level);
      e.kind = uint8_t(kind);
      events->push_back(e);
      continue;
    }
    if (line[0] == kTraceTimeTag) {
      e.window = kTraceTimeTag;
      fields.get();
      int used = 0;
      uint64_t width = 0, height = 0;
      if (!(fields >> e.frame >> e.time_s >> used >> width >> height) || !std::isfinite(e.time_s) ||
          used < 0 || used > 1 || width > UINT32_MAX || height > UINT32_MAX) {
        return bad(line_no, kTimeLineFormat, line);
      }
      e.kind = uint8_t(used);
      e.viewport = {uint32_t(width), uint32_t(height)};
      events->push_back(e);
      continue;
    }
    if (line[0] == kTraceLeaveTag) {
      e.leave = true;
      fields.get();
    }
    uint64_t level = 0, x = 0, y = 0;
    if (!(fields >> e.frame >> level >> x >> y) || level > 63 || x > UINT32_MAX || y > UINT32_MAX) {
      return bad(line_no, kTileLineFormat, line);
    }
    e.key = {uint32_t(level), uint32_t(x), uint32_t(y)};
    events->push_back(e);
  }
  if (in.bad()) return Status::error(ErrorCode::kIo, "error reading trace " + path);
  return okStatus();
}

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

// Which tiles the GPU holds as the trace goes: a tile is handed over at its
// access (every access is taken to be handed over at once, as in the rest
// of the replay) and stays until a plan change finds it neither wanted nor
// in its needed window (the streamer's rule, streamer.cpp rebuild()). So an
// entry of a tile that left the wanted set but not its window is served by
// the GPU: not an access. This depends on the trace alone, not on a policy.
// A plan change is its frame's lines; one without window lines keeps the
// windows it had. Call step(i) for every event in order.
class GpuResidency {
 public:
  GpuResidency(const std::vector<TraceEvent>& events, const std::vector<uint32_t>& id_of, size_t n_ids)
      : m_events(events), m_id_of(id_of), m_on_gpu(n_ids, 0), m_wanted(n_ids, 0), m_listed(n_ids, 0),
        m_key_of(n_ids) {}

  // Takes event i; true when it is an entry the GPU serves.
  bool step(size_t i) {
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
    const uint32_t id = m_id_of[i];
    m_key_of[id] = e.key;
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
  bool onGpu(uint32_t id) const { return m_on_gpu[id] != 0; }

 private:
  static constexpr uint64_t kNone = UINT64_MAX;
  bool inNeededWindow(const TileKey& k) const {
    if (k.level >= m_windows.kinds.size()) return false;
    const uint8_t kind = m_windows.kinds[k.level];
    return kind == PlanWindows::kPyramid ||
           (kind == PlanWindows::kNeeded && m_windows.rects[k.level].contains(k.x, k.y));
  }
  void closePlanChange() {
    std::vector<uint32_t> kept;
    for (uint32_t id : m_left) {
      if (m_on_gpu[id] && !m_wanted[id] && inNeededWindow(m_key_of[id])) {
        kept.push_back(id);
        continue;
      }
      if (!m_wanted[id]) m_on_gpu[id] = 0;  // else back in the wanted set: stays
      m_listed[id] = 0;
    }
    m_left.swap(kept);
  }

  const std::vector<TraceEvent>& m_events;
  const std::vector<uint32_t>& m_id_of;
  std::vector<uint8_t> m_on_gpu, m_wanted, m_listed;  // m_listed: in m_left
  std::vector<TileKey> m_key_of;
  std::vector<uint32_t> m_left;  // ids that left the wanted set while on the GPU
  PlanWindows m_windows;
  uint64_t m_open_frame = kNone;
  bool m_fresh_windows = false;  // the next window line starts a new set
};

}  // namespace

ReplayResult replayTrace(const std::vector<TraceEvent>& events, uint64_t capacity_tiles,
                         const ReplayHint* hint) {
  ReplayResult result;
  result.capacity_tiles = capacity_tiles;
  // Dense ids for keys.
  std::unordered_map<TileKey, uint32_t, TileKeyHash> ids;
  std::vector<uint32_t> id_of(events.size());
  std::vector<uint32_t> level_of;
  for (size_t i = 0; i < events.size(); ++i) {
    if (events[i].window) continue;
    auto [it, added] = ids.emplace(events[i].key, uint32_t(ids.size()));
    if (added) level_of.push_back(events[i].key.level);
    id_of[i] = it->second;
  }
  result.distinct_tiles = ids.size();
  const size_t n_ids = ids.size();
  constexpr uint64_t kNever = UINT64_MAX;

  // Entries the GPU serves are not accesses (GpuResidency).
  std::vector<uint8_t> access(events.size(), 0);
  {
    GpuResidency gpu(events, id_of, n_ids);
    for (size_t i = 0; i < events.size(); ++i) {
      const bool served = gpu.step(i);
      if (!events[i].isAccess()) continue;
      if (served) result.gpu_reentries++;
      else access[i] = 1, result.accesses++;
    }
  }

  // Next access (not leave) of the same tile, for OPT.
  std::vector<uint64_t> next_use(events.size(), kNever);
  {
    std::vector<uint64_t> seen(n_ids, kNever);
    for (size_t i = events.size(); i-- > 0;) {
      if (!access[i]) continue;
      next_use[i] = seen[id_of[i]];
      seen[id_of[i]] = i;
    }
  }
  if (capacity_tiles == 0) return result;

  // OPT: evict the tile used farthest in the future; bypass when the
  // newcomer itself is used farthest.
  {
    std::set<std::pair<uint64_t, uint32_t>> by_next;  // (next use, id)
    std::vector<uint64_t> cached_next(n_ids, 0);
    std::vector<uint8_t> in_cache(n_ids, 0);
    for (size_t i = 0; i < events.size(); ++i) {
      if (!access[i]) continue;
      const uint32_t id = id_of[i];
      if (in_cache[id]) {
        result.hits_opt++;
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
  }

  // LRU.
  {
    std::list<uint32_t> order;  // front = most recent
    std::vector<std::list<uint32_t>::iterator> where(n_ids);
    std::vector<uint8_t> in_cache(n_ids, 0);
    for (size_t i = 0; i < events.size(); ++i) {
      if (!access[i]) continue;
      const uint32_t id = id_of[i];
      if (in_cache[id]) {
        result.hits_lru++;
        order.erase(where[id]);
      } else if (order.size() >= capacity_tiles) {
        in_cache[order.back()] = 0;
        order.pop_back();
      }
      in_cache[id] = 1;
      order.push_front(id);
      where[id] = order.begin();
    }
  }

  // Plan-aware: the streamer's policy over the recorded windows, both modes,
  // and kGpuFirst with the path hint when there is one.
  enum class Run { kProtectGpu, kGpuFirst, kHinted };
  for (Run run : {Run::kProtectGpu, Run::kGpuFirst, Run::kHinted}) {
    if (run == Run::kHinted && (!hint || !hint->path.camera_at)) continue;
    const EvictionMode mode = run == Run::kProtectGpu ? EvictionMode::kProtectGpu : EvictionMode::kGpuFirst;
    uint64_t& hits = run == Run::kProtectGpu ? result.hits_plan
                     : run == Run::kGpuFirst ? result.hits_gpu_first
                                             : result.hits_hinted;
    std::vector<TileKey> key_of(n_ids);
    for (const auto& [key, id] : ids) key_of[id] = key;
    PlanWindows current, predicted, building_w, building_p;
    uint64_t building_frame = UINT64_MAX;
    bool dirty = false;
    PathLookahead lookahead;
    std::shared_ptr<const LookaheadSnapshot> ahead;
    double building_time = 0.0;
    Viewport building_viewport{0, 0};
    bool building_hint_used = false;
    // (score, stamp, id): victims are taken from the end, in the streamer's
    // order (evictsBefore).
    using Slot = std::tuple<double, uint64_t, uint32_t>;
    auto order = [](const Slot& a, const Slot& b) {
      if (std::get<0>(a) != std::get<0>(b) || std::get<1>(a) != std::get<1>(b))
        return evictsBefore(std::get<0>(b), std::get<1>(b), std::get<0>(a), std::get<1>(a));
      return std::get<2>(a) < std::get<2>(b);
    };
    std::set<Slot, decltype(order)> candidates(order);
    std::vector<uint8_t> in_cache(n_ids, 0), wanted(n_ids, 0);
    std::vector<uint64_t> stamp(n_ids, 0);
    std::vector<double> score(n_ids, 0.0);
    std::vector<uint32_t> cached_ids;
    uint64_t cached = 0;
    auto slotOf = [&](uint32_t id) { return Slot{score[id], stamp[id], id}; };
    // Every access is handed to the GPU at once, so a cached tile is either
    // on the GPU (wanted) or not wanted: all are scored but pyramid tiles
    // under kProtectGpu (streamer.cpp, buildVictimLists).
    auto scored = [&](uint32_t id) { return scoredOnGpu(key_of[id], current, mode); };
    GpuResidency gpu(events, id_of, n_ids);
    // The tiles this plan change brings in are pinned until their entry, as
    // the streamer pins wanted tiles that are in RAM but not yet on the GPU:
    // an entry is not evicted for an earlier one of the same plan change.
    std::vector<uint8_t> entering(n_ids, 0);
    std::vector<uint32_t> entering_ids;
    auto enroll = [&](uint32_t id) {
      if (!scored(id) || entering[id]) return;
      score[id] = evictionScoreAhead(key_of[id], current, predicted, mode, gpu.onGpu(id), ahead.get());
      candidates.insert(slotOf(id));
    };
    auto rescore = [&](size_t seq) {
      for (uint32_t id : entering_ids) entering[id] = 0;
      entering_ids.clear();
      for (size_t j = seq; j < events.size() && events[j].frame == events[seq].frame; ++j)
        if (access[j] && !entering[id_of[j]]) entering[id_of[j]] = 1, entering_ids.push_back(id_of[j]);
      candidates.clear();
      std::vector<uint32_t> live;
      for (uint32_t id : cached_ids) {
        if (!in_cache[id]) continue;
        live.push_back(id);
        if (wanted[id]) stamp[id] = seq;
        enroll(id);
      }
      cached_ids.swap(live);
    };
    for (size_t i = 0; i < events.size(); ++i) {
      const TraceEvent& e = events[i];
      (void)gpu.step(i);  // access[] already says which entries it serves
      if (e.window) {
        if (e.frame != building_frame) {
          building_frame = e.frame;
          building_w = {};
          building_p = {};
          building_hint_used = false;
        }
        if (e.window == 't') {
          building_time = e.time_s;
          building_viewport = e.viewport;
          building_hint_used = e.kind != 0;
          continue;
        }
        placeWindow(e.window == 'w' ? &building_w : &building_p, e);
        dirty = true;
        continue;
      }
      if (dirty) {
        current = building_w;
        current.finish();
        predicted = building_p;
        if (!predicted.empty()) predicted.finish();
        ahead = nullptr;
        if (run == Run::kHinted && building_hint_used) {
          lookahead.advance(hint->geometry, building_viewport, hint->planner, hint->path, building_time);
          ahead = lookahead.snapshot();
        }
        rescore(i);
        dirty = false;
      }
      const uint32_t id = id_of[i];
      if (e.leave || !access[i]) {  // a leave, or an entry the GPU serves: only the stamp moves
        if (in_cache[id] && scored(id)) {
          candidates.erase(slotOf(id));
          stamp[id] = i;
          candidates.insert(slotOf(id));
        } else {
          stamp[id] = i;
        }
        wanted[id] = e.leave ? 0 : 1;
        continue;
      }
      wanted[id] = 1;
      entering[id] = 0;
      if (in_cache[id]) {
        hits++;
        if (scored(id)) candidates.erase(slotOf(id));
        stamp[id] = i;
        enroll(id);
        continue;
      }
      stamp[id] = i;
      if (cached >= capacity_tiles) {
        if (candidates.empty()) continue;  // only unscored pyramid tiles cached: bypass
        auto victim = std::prev(candidates.end());
        in_cache[std::get<2>(*victim)] = 0;
        candidates.erase(victim);
        cached--;
      }
      in_cache[id] = 1;
      cached++;
      cached_ids.push_back(id);
      enroll(id);
    }
  }
  return result;
}

}  // namespace clipstream
