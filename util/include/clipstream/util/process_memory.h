// This process's memory, as the kernel counts it: what memory planning (the
// tiler's budget) and run statistics (peak RSS in summaries) measure.
//
// Thread-safe: each call reads /proc/self/status afresh; no state.
#pragma once

#include <cstdint>

namespace clipstream {

// Current resident set size (VmRSS), in bytes; 0 where /proc cannot be read.
uint64_t currentRssBytes();

// Peak resident set size since the process started (VmHWM), in bytes; 0
// where /proc cannot be read.
uint64_t peakRssBytes();

}  // namespace clipstream
