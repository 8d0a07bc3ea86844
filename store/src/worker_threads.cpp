// runWorkers() (worker_threads.h): start, wait with progress, join.
#include "worker_threads.h"

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

namespace clipstream {

void runWorkers(unsigned threads, const std::function<void()>& worker,
                const std::function<void()>& report) {
  std::mutex done_mutex;  // pairs with done_cv; guards `running`
  std::condition_variable done_cv;
  unsigned running = 0;
  std::vector<std::thread> pool;
  for (unsigned i = 0; i < threads; ++i) {
    {
      std::lock_guard<std::mutex> lock(done_mutex);
      ++running;
    }
    try {
      pool.emplace_back([&] {
        worker();
        std::lock_guard<std::mutex> lock(done_mutex);
        if (--running == 0) done_cv.notify_all();
      });
    } catch (const std::system_error&) {
      // The system's thread limit: work with the threads that started.
      std::lock_guard<std::mutex> lock(done_mutex);
      --running;
      break;
    }
  }
  if (pool.empty()) worker();  // no thread at all: work on this one
  {
    std::unique_lock<std::mutex> lock(done_mutex);
    while (running > 0) {
      if (report) {
        lock.unlock();
        report();
        lock.lock();
      }
      done_cv.wait_for(lock, std::chrono::milliseconds(100), [&] { return running == 0; });
    }
  }
  for (std::thread& thread : pool) thread.join();
  if (report) report();
}

}  // namespace clipstream
