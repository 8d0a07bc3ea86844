// Request traces: what the streamer asked for, frame by frame, and offline
// replay of a trace against cache policies (Belady OPT, LRU, ours).
//
// Thread-safe: plain functions over caller-owned data.
//
// File format (text, one event per line, '#' starts a comment line):
//   "F L X Y"    tile (L, X, Y) entered the wanted set at frame F: an access
//   "- F L X Y"  the tile left the wanted set at frame F
//   "w F L X0 Y0 X1 Y1 K"  level L's window [X0,X1) x [Y0,Y1) from frame F on;
//                K = 0 not needed, 1 needed, 2 pyramid (whole level)
//   "p F L X0 Y0 X1 Y1 K"  the same for the predicted (prefetch) plan
//   "t F T H W V"  the plan change at frame F happened at update() time T
//                (seconds) with a W x V viewport; H = 1 when the streamer
//                used its path hint
// The time line and window lines of a plan change come before its tile
// lines. Traces without time lines (older ones) replay the same, without
// the hinted policy.
// An access is a hit when the tile is decoded in RAM at that moment; tiles
// that stay wanted are on the GPU and cost nothing more, so only entries
// are accesses. Nor is an entry that the GPU serves: a tile that left the
// wanted set but not its needed window since it was last handed over keeps
// its GPU slot and is drawn again without a read (a GPU re-entry).
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/streamer.h>

#include <cstdint>
#include <string>
#include <vector>

namespace clipstream {

// The format, named once. The first line is kTraceHeader; every other line
// starts with its tag (a tile entry has none: it starts with the frame).
inline constexpr const char* kTraceMagic = "# clipstream trace v";  // then the version
inline constexpr int kTraceVersion = 2;
inline constexpr const char* kTraceHeader =
"# clipstream trace v2: 'frame level x y' = tile entered the wanted set, "
    "'- frame level x y' = it left; 'w'/'p' window and 't' time lines as in trace.h";
inline constexpr char kTraceLeaveTag = '-';      // "- F L X Y"
inline constexpr char kTraceWindowTag = 'w';     // "w F L X0 Y0 X1 Y1 K"
inline constexpr char kTracePredictedTag = 'p';  // "p F L X0 Y0 X1 Y1 K"
inline constexpr char kTraceTimeTag = 't';       // "t F T H W V"
inline constexpr char kTraceCommentTag = '#';

struct TraceEvent {
  uint64_t frame = 0;
  TileKey key;         // tile events; window events use key.level only
  bool leave = false;
  char window = 0;     // 0: tile event, else its tag: kTraceWindowTag, kTracePredictedTag, kTraceTimeTag
  TileRect rect;       // window events
  uint8_t kind = 0;    // window events: 0 not needed, 1 needed, 2 pyramid; time events: hint used
  double time_s = 0.0; // time events
  Viewport viewport{0, 0};  // time events

  bool isAccess() const { return window == 0 && !leave; }
};

// Appends `event` to `out` as one trace line, newline included: the line
// readTrace() parses back into the same event. Time events keep time_s
// exactly (17 significant digits); a non-finite time is written as 0.
// Events that no line can hold (a level above 63, a kind above 2) are the
// caller's mistake.
void appendTraceLine(const TraceEvent& event, std::string* out);

// The largest trace readTrace() reads: its events take a few times the
// file in memory (a 1,000-frame flight at 1280x720 writes 1.1 MB).
inline constexpr uint64_t kMaxTraceFileBytes = uint64_t(2) << 30;

// Reads a trace file (a regular file starting with the v2 header line).
// kNotFound / kIo if it cannot be read or is not a regular file;
// kInvalidArgument if it is larger than kMaxTraceFileBytes;
// kInvalidArgument if it is empty, has no header, or a line does not parse
// (naming the line; its text shown with control bytes as '?');
// kUnsupported for another trace version; kTruncated if the last line has no
// newline (a trace cut short).
Status readTrace(const std::string& path, std::vector<TraceEvent>* events);

struct ReplayResult {
  uint64_t accesses = 0;        // tile entries the GPU does not serve
  uint64_t gpu_reentries = 0;   // tile entries the GPU serves (not accesses)
  uint64_t distinct_tiles = 0;
  uint64_t capacity_tiles = 0;
  uint64_t hits_opt = 0;   // Belady's optimal replacement (with bypass)
  uint64_t hits_lru = 0;   // least recently used
  uint64_t hits_plan = 0;       // the streamer's policy, EvictionMode::kProtectGpu
  uint64_t hits_gpu_first = 0;  // the streamer's policy, EvictionMode::kGpuFirst (default)
  uint64_t hits_hinted = 0;     // kGpuFirst with the path hint (only when replayed with one)
};

// What the streamer that recorded a trace knew of the camera's future: its
// path hint (one for the whole trace) and the inputs of its planner. The
// replay plans the hinted path as the streamer did, at the recorded times
// and viewports.
struct ReplayHint {
  PathHint path;
  PyramidGeometry geometry;
  PlannerConfig planner;
};

// Replays accesses against a cache of capacity_tiles tiles under each policy.
// The plan-aware policy is the streamer's (eviction.h): it sees the window
// lines as the streamer sees its plans and evicts the highest plan-distance
// score first (ties as in eviction.h). Every access is taken to be handed to
// the GPU at once, so with kGpuFirst pyramid tiles are candidates (first);
// with kProtectGpu they are never evicted, and a newcomer is dropped when
// only pyramid tiles are cached. With a hint, hits_hinted replays kGpuFirst
// with the hinted path's predicted returns at every plan change whose time
// line says the streamer used the hint (lookahead.h).
ReplayResult replayTrace(const std::vector<TraceEvent>& events, uint64_t capacity_tiles,
                         const ReplayHint* hint = nullptr);

}  // namespace clipstream
