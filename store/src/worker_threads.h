// Private: a fixed set of worker threads with progress reported from the
// calling thread (TileStoreReader::verifyAll()).
//
// Thread-safe: a free function; `worker` runs on several threads at once
// and must be safe for that; `report` runs on the calling thread only.
#pragma once

#include <functional>

namespace clipstream {

// Runs `worker` on `threads` threads at once (as many as the system
// starts; on the calling thread when it starts none) and returns when all
// are done. Meanwhile the calling thread only calls `report`, if given,
// every 100 ms and once at the end, so it never runs on a worker and needs
// no locking of its own.
void runWorkers(unsigned threads, const std::function<void()>& worker,
                const std::function<void()>& report);

}  // namespace clipstream
