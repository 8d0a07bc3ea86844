// The report formats of a measured flight (docs/renderer.md, "Outputs"):
// frames.csv (one row per frame, per-level columns after the totals),
// frames.json (a summary object and every frame), summary.tsv (one header
// line, one value line, for scripts/sweep.sh), the console table, and the
// stability scenarios' JSON line (the sweep's stability table).
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
  uint32_t warmup_frames = 0;
  bool reference = false;
  TileContent reference_tile_format = TileContent::kRgba8;  // the ideal reference's tiles
  bool path_hint = false;
  // The streamer's settings. The reports name the RAM budget (cache_mb, in
  // whole MiB), throttling, prefetch, frustum priority, the plan scope and
  // deterministic I/O (its reads per frame and latency only count with it).
  StreamerConfig streamer;
  uint64_t pngs_written = 0, pngs_dropped = 0;
};

std::string framesCsv(const FlightRun& run, uint32_t levels);
std::string framesJson(const FlightRun& run, const RunDescription& description);
std::string summaryTsv(const FlightRun& run, const RunDescription& description);
void printSummary(std::ostream& out, const FlightRun& run, const RunDescription& description);

// A stability scenario (tests/eval/test_stability.cpp): a flight of
// `moving_frames` then `rest_frames` frames, judged against the reference.
struct ScenarioDescription {
  std::string name;
  uint32_t moving_frames = 0, rest_frames = 0;  // FlightRunOptions::frames, rest_frames
  bool passed = false;                          // every check of the scenario held
};

// Rest frames (after the first `moving_frames`) until the first judged
// frame bit-identical to the reference (max abs error 0); -1: none.
int restFramesToIdentical(const FlightRun& run, uint32_t moving_frames);

// The scenario's line of the stability table (CLIPSTREAM_STABILITY_OUT,
// read by scripts/sweep.sh): RunSummary::toJson()'s keys, the scenario's
// (scenario, moving_frames, rest_frames, rest_frames_to_identical, result
// "pass" or "FAIL") and the run's RAM, RSS, render-thread fetches and
// garbage checks, as one JSON object with sorted keys on one line,
// newline-terminated.
std::string scenarioJsonLine(const FlightRun& run, const ScenarioDescription& scenario);

}  // namespace clipstream
