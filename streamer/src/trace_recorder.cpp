#include "trace_recorder.h"

#include <clipstream/streamer/trace.h>

namespace clipstream {
namespace {

// Text buffered before it is appended to the file.
constexpr size_t kTraceBlockBytes = size_t(1) << 20;

}  // namespace

void TraceRecorder::open(const std::string& path) {
  OutputOptions options;
  options.existing = ExistingOutput::kReplaceRegular;
  m_status = OutputFile::create(path, options, &m_file);
  m_active = m_status.ok();
  if (m_active) {
    m_text = kTraceHeader;
    m_text += '\n';
  }
}

void TraceRecorder::beginPlan(uint64_t frame, double time_s, bool hint_used, const Viewport& viewport,
                              const PlanWindows& windows, const PlanWindows& predicted) {
  if (!m_active) return;
  m_frame = frame;
  // Time and viewport first: the replay re-plans the hint with them.
  TraceEvent time_line;
  time_line.window = kTraceTimeTag;
  time_line.frame = frame;
  time_line.time_s = time_s;
  time_line.kind = hint_used ? 1 : 0;
  time_line.viewport = viewport;
  appendTraceLine(time_line, &m_text);
  auto windowLines = [&](char tag, const PlanWindows& w) {
    TraceEvent line;
    line.window = tag;
    line.frame = frame;
    for (size_t l = 0; l < w.rects.size(); ++l) {
      line.key.level = uint32_t(l);
      line.rect = w.rects[l];
      line.kind = w.kinds[l];
      appendTraceLine(line, &m_text);
    }
  };
  windowLines(kTraceWindowTag, windows);
  windowLines(kTracePredictedTag, predicted);
}

void TraceRecorder::tile(const TileKey& key, bool leave) {
  if (!m_active) return;
  TraceEvent line;
  line.frame = m_frame;
  line.key = key;
  line.leave = leave;
  appendTraceLine(line, &m_text);
}

void TraceRecorder::endPlan() {
  if (m_active && m_text.size() >= kTraceBlockBytes) flush(false);
}

void TraceRecorder::finish() { flush(true); }

void TraceRecorder::discard() {
  m_active = false;
  m_text.clear();
  m_file.reset();  // removes the temporary
}

void TraceRecorder::flush(bool publish) {
  if (!m_active) return;
  Status status = m_file->append(m_text);
  m_text.clear();  // keeps its capacity for the next block
  if (status && publish) status = m_file->commit();
  if (!status) m_status = status;
  if (!status || publish) {
    m_active = false;
    m_file.reset();  // without a commit: removes the temporary
  }
}

}  // namespace clipstream
