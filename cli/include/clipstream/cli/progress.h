// A one-line progress bar on stderr for the command-line programs
// (clipstream-tile, clipstream-info): percentage, bar, rate and ETA. The
// libraries never draw: they report progress through callbacks
// (TilerOptions::progress, TileStoreReader::verifyAll) and a program feeds
// those to a bar.
//
// Thread-safe: update(), add() and finish() may be called from any thread;
// drawing is serialised internally and skipped (never waited for) when
// another thread is already drawing.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace clipstream::cli {

// True when stderr is a terminal.
bool stderrIsTty();

// Whether programs should draw progress by default: CLIPSTREAM_PROGRESS=0
// or =1 in the environment decides; otherwise only when stderr is a TTY.
bool progressEnabledByDefault();

class ProgressBar {
 public:
  // `label` prefixes the line; `total` is the number of units of work
  // (0 = unknown: no percentage or ETA); `unit` names them in the rate
  // ("tiles" -> "1234 tiles/s"). The bar draws only when `enabled` is true
  // (pass progressEnabledByDefault() unless the user asked for quiet).
  ProgressBar(std::string label, uint64_t total, bool enabled, std::string unit = "tiles");
  // Calls finish() if it has not run.
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  // Sets the amount done so far (monotonic: smaller values are ignored).
  // Redraws at most about 10 times a second; cheap to call per unit.
  void update(uint64_t done);
  // Adds `delta` units to the amount done; for many workers sharing a bar.
  void add(uint64_t delta);
  // Draws the final state and ends the line. Later calls do nothing.
  void finish();

  uint64_t done() const { return m_done.load(std::memory_order_relaxed); }
  bool enabled() const { return m_enabled; }

 private:
  void draw(bool final_draw);

  const std::string m_label;
  const std::string m_unit;
  const uint64_t m_total;
  const bool m_enabled;
  const std::chrono::steady_clock::time_point m_start;
  std::atomic<uint64_t> m_done{0};
  std::atomic<bool> m_finished{false};
  std::mutex m_draw_mutex;  // guards m_last_draw and the stderr line
  std::chrono::steady_clock::time_point m_last_draw;
};

}  // namespace clipstream::cli
