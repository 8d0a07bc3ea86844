// One line of a trace file parsed back into its event: the inverse of
// appendTraceLine() (trace.h), which readTrace() applies to every line
// after the header. Internal to the streamer library; declared here so the
// tests can check the line formats alone.
//
// Thread rule: pure, safe from any thread.
#pragma once

#include <clipstream/streamer/trace.h>

#include <string>

namespace clipstream {

// Parses `line` (not empty, no newline, not a comment: a tile, leave,
// window, predicted-window or time line) into *event. Returns null on
// success; else the line format it expected, as readTrace() names it in
// its message (e.g. "'frame level x y'"), and *event is left as it was.
// Bad data is a returned format, never an assert.
const char* parseTraceLine(const std::string& line, TraceEvent* event);

}  // namespace clipstream
