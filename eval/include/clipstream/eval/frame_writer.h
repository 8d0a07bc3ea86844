// Writes frames to PNG on its own thread, so the render thread never waits
// on image encoding or disk.
//
// Thread-safe: submit() may be called from any thread; close() and the
// destructor from the owning thread. Shutdown order: close() stops
// accepting frames, drains the queue, joins the writer; the destructor
// calls it.
#pragma once

#include <clipstream/store/types.h>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace clipstream {

// Frames kept in flight between the render thread and the PNG writer
// thread; a slower disk makes the render thread skip saving, never wait.
inline constexpr uint32_t kMaxQueuedPngFrames = 4;

class FrameWriter {
 public:
  // `max_queued` frames may wait; more are dropped (and counted), never waited for.
  explicit FrameWriter(size_t max_queued);
  ~FrameWriter();
  FrameWriter(const FrameWriter&) = delete;
  FrameWriter& operator=(const FrameWriter&) = delete;

  // Queues RGBA8 pixels (top row first) for `path`. Returns false when the
  // queue is full and the frame was dropped.
  bool submit(std::string path, uint32_t width_px, uint32_t height_px, std::vector<uint8_t> rgba);

  // Drains and joins. Returns the first write error, if any.
  Status close();

  uint64_t written() const;
  uint64_t dropped() const;

 private:
  struct Job {
    std::string path;
    uint32_t width_px = 0, height_px = 0;
    std::vector<uint8_t> rgba;
  };
  void run();

  const size_t m_max_queued;
  mutable std::mutex m_mutex;  // guards everything below
  std::condition_variable m_cv;
  std::deque<Job> m_queue;
  bool m_closing = false;
  uint64_t m_written = 0;
  uint64_t m_dropped = 0;
  Status m_first_error;
  std::thread m_thread;  // started last, after the members it uses
};

// Reads any image OpenImageIO can read as RGBA8 (top row first; missing
// alpha = 255, grey = replicated). kNotFound / kIo / kUnsupported with the
// reader's message. For tests and demos; the product reads tile stores.
Status readImageRgba(const std::string& path, std::vector<uint8_t>* rgba, uint32_t* width_px,
                     uint32_t* height_px);

// Writes one RGBA8 image as PNG (encoded by OpenImageIO in memory) on the
// calling thread, under OutputFile's rule (a regular file at `path` is
// replaced; nothing half-written is ever under `path`). kIo / kNoSpace /
// kInvalidArgument / kAlreadyExists naming the file. Does not sweep stale
// temporaries (OutputOptions::sweep): the caller owns the directory.
Status writePng(const std::string& path, uint32_t width_px, uint32_t height_px,
                const uint8_t* rgba);

}  // namespace clipstream
