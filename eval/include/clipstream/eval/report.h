// The report formats of a measured flight (docs/renderer.md, "Outputs"):
// frames.csv (one row per frame, per-level columns after the totals),
// frames.json (a summary object and every frame), summary.tsv (one header
// line, one value line, for scripts/sweep.sh) and the console table.
// Every format uses the same key for the same quantity; sizes in bytes are
// `_bytes`, in MiB `_mib`, rates in [0, 1] `_rate`.
//
// Thread rule: pure functions of their arguments, thread-safe.
#pragma once

#include <clipstream/eval/flight_run.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
#include <iosfwd>
#include <string>

namespace clipstream {

// What the run was asked to do, as the reports name it.
struct RunDescription {
  std::string path;               // built-in name or file
  double speed = 1.0;
  Viewport viewport{0, 0};        // the first viewport
  Buffering buffering = kDefaultBuffering;
  uint32_t upload_tiles = 0;
  uint64_t cache_mb = 0;
  uint32_t warmup_frames = 0;
  bool reference = false;
  TileContent reference_tile_format = TileContent::kRgba8;  // the ideal reference's tiles
  bool throttle = true, prefetch = true, frustum_priority = true, path_hint = false;
  PlanScope plan_scope = PlanScope::kSampled;
  // Deterministic I/O (DeterministicIo); the other two only count with it.
  bool deterministic = false;
  uint32_t io_reads_per_frame = 0, io_latency_frames = 0;
  uint64_t pngs_written = 0, pngs_dropped = 0;
};

std::string framesCsv(const FlightRun& run, uint32_t levels);
std::string framesJson(const FlightRun& run, const RunDescription& description);
std::string summaryTsv(const FlightRun& run, const RunDescription& description);
void printSummary(std::ostream& out, const FlightRun& run, const RunDescription& description);

}  // namespace clipstream
