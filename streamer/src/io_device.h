// The deterministic I/O device (StreamerConfig::deterministic_io): reads
// issued on a frame clock. The render thread issues a ticket per read, due
// `latency_frames` frames later; a loader takes the ticket, reads and
// decodes it without touching the cache or the counters, and marks it done;
// the render thread publishes the tickets due by each frame in issue order,
// waiting for a loader to finish one if need be. Every change to the cache,
// the queue and the counters then happens on the render thread at a point
// fixed by the frame count, so a run does not depend on thread timing.
//
// Threads: the device holds no lock of its own. Every method is called with
// the streamer's mutex held (the one passed to nextDue()'s lock): issue()
// and nextDue() by the render thread, takeWork() and finished() by loaders.
// A ticket's result fields are written by the loader that took it, unlocked,
// before finished(); after that only the render thread touches them.
#pragma once

#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <vector>

namespace clipstream {

struct TileDetail;

// One read issued on the simulated clock.
struct IoTicket {
  LayerTile key;
  uint64_t due_frame = 0;  // published in the update() of this frame
  bool reread = false;
  bool done = false;       // set by finished()
  Status status;
  FetchInfo info;
  std::shared_ptr<std::vector<uint8_t>> pixels = std::make_shared<std::vector<uint8_t>>();
  std::shared_ptr<const TileDetail> detail;
};

class IoDevice {
 public:
  // Render thread: a read of `key`, due in frame `due_frame` (never earlier
  // than the tickets issued before it).
  std::shared_ptr<IoTicket> issue(const LayerTile& key, uint64_t due_frame, bool reread);
  // Loaders: a ticket is waiting to be read.
  bool hasWork() const { return !m_work.empty(); }
  // Loaders: the oldest ticket not yet taken; null if none.
  std::shared_ptr<IoTicket> takeWork();
  // Loaders: the ticket's read is complete.
  void finished(IoTicket& ticket);
  // Render thread, `lock` held on the streamer's mutex: the oldest issued
  // ticket if it is due by `frame` (or any, with `all`), after waiting for
  // its read to finish; null when none is due. The ticket is then the
  // caller's to publish.
  std::shared_ptr<IoTicket> nextDue(std::unique_lock<std::mutex>& lock, uint64_t frame, bool all);
  // Issued tickets not yet handed back by nextDue().
  size_t outstanding() const { return m_issued.size(); }

 private:
  std::deque<std::shared_ptr<IoTicket>> m_work;    // not yet taken by a loader, issue order
  std::deque<std::shared_ptr<IoTicket>> m_issued;  // not yet published, issue order
  std::condition_variable m_done_cv;               // signalled whenever a ticket is done
};

}  // namespace clipstream
