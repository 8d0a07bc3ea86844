// Writes the streamer's request trace (trace.h's format) for one layer:
// per plan change, the time and viewport, the windows of the plan and of
// the predicted plan, and the tiles that entered and left the wanted set.
// Text is buffered and appended to the output in blocks; the file appears
// under its name only at finish() (store/output_file.h), so a run that
// stops early leaves nothing half-written.
//
// Render thread only (the streamer's update() and shutdown()).
#pragma once

#include "eviction.h"

#include <clipstream/store/types.h>
#include <clipstream/util/output_file.h>
#include <clipstream/streamer/planner.h>

#include <cstdint>
#include <memory>
#include <string>

namespace clipstream {

class TraceRecorder {
 public:
  // Starts a trace to `path` (an existing regular file is replaced at
  // finish()). On failure status() says why and nothing is recorded.
  void open(const std::string& path);
  // Recording: opened, and neither failed nor finished nor discarded.
  bool active() const { return m_active; }
  // Ok, or why the trace could not be written.
  const Status& status() const { return m_status; }

  // One plan change: its time line, then its windows.
  void beginPlan(uint64_t frame, double time_s, bool hint_used, const Viewport& viewport,
                 const PlanWindows& windows, const PlanWindows& predicted);
  // A tile that entered (leave false) or left the wanted set in that change.
  void tile(const TileKey& key, bool leave);
  // The change is complete: a full block goes to the file.
  void endPlan();

  // Appends what is buffered and publishes the file.
  void finish();
  // Drops the trace: the temporary is removed, nothing is published.
  void discard();

 private:
  void flush(bool publish);

  bool m_active = false;
  uint64_t m_frame = 0;
  std::string m_text;
  std::unique_ptr<OutputFile> m_file;
  Status m_status;
};

}  // namespace clipstream
