// libFuzzer driver for request traces (readTrace, what `clipstream-trace`
// reads): a mutated trace file; one that parses is replayed against a small
// cache under every policy, and its lines written back parse to the same
// events. Seeds: a trace of every line kind, from appendTraceLine().
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./trace_fuzz -runs=0   # write seeds
//   ./trace_fuzz -max_total_time=300 -timeout=10 corpus
#include "fuzz_util.h"

#include <clipstream/streamer/trace.h>

#include <string>
#include <vector>

using namespace clipstream;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = fuzz::seedDir()) {
    std::string text = std::string(kTraceHeader) + "\n";
    for (uint64_t frame = 0; frame < 4; ++frame) {
      TraceEvent time;
      time.frame = frame;
      time.window = kTraceTimeTag;
      time.time_s = double(frame) / 60.0;
      time.viewport = {320, 180};
      appendTraceLine(time, &text);
      TraceEvent window;
      window.frame = frame;
      window.window = frame % 2 ? kTracePredictedTag : kTraceWindowTag;
      window.key.level = uint32_t(frame);
      window.rect = {int64_t(frame), 0, int64_t(frame) + 3, 2};
      window.kind = uint8_t(frame % 3);
      appendTraceLine(window, &text);
      for (uint32_t x = 0; x < 3; ++x) {
        TraceEvent tile;
        tile.frame = frame;
        tile.key = {uint32_t(frame % 2), x + uint32_t(frame), 1};
        tile.leave = x == 2 && frame > 1;
        appendTraceLine(tile, &text);
      }
    }
    fuzz::writeFile(std::string(dir) + "/trace", text);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = fuzz::scratchPath("trace");
  fuzz::writeFile(path, data, size);
  std::vector<TraceEvent> events;
  if (!readTrace(path, &events)) return 0;
  if (events.size() > 20000) return 0;  // keep each input fast
  for (uint64_t capacity : {1, 4, 64}) (void)replayTrace(events, capacity);
  std::string text = std::string(kTraceHeader) + "\n";
  for (const TraceEvent& e : events) appendTraceLine(e, &text);
  fuzz::writeFile(path, text);
  std::vector<TraceEvent> again;
  if (!readTrace(path, &again) || again.size() != events.size()) std::abort();
  return 0;
}
