// Private: the bounded FIFO between the tiler's pipeline stages (reader ->
// workers -> writer, pipeline.cpp). Producers block on it when full, so a fast
// stage cannot run ahead of a slow one by more than the queue holds.
//
// Thread-safe: push() and pop() from any number of threads; close() and
// abort() from any thread, once the stage feeding it is done or has failed.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>

namespace clipstream {

// A bounded FIFO that producers block on when full. close() lets consumers
// drain what is queued (push() then returns false); abort() wakes everyone
// and drops the rest (pop() returns false at once).
template <typename T>
class BoundedQueue {
 public:
  explicit BoundedQueue(size_t capacity) : m_capacity(capacity) {}

  bool push(T&& item) {
    std::unique_lock lock(m_mutex);
    m_not_full.wait(lock, [&] { return m_items.size() < m_capacity || m_closed; });
    if (m_closed) return false;
    m_items.push_back(std::move(item));
    m_not_empty.notify_one();
    return true;
  }
  bool pop(T* out) {
    std::unique_lock lock(m_mutex);
    m_not_empty.wait(lock, [&] { return !m_items.empty() || m_closed; });
    if (m_items.empty() || m_aborted) return false;
    *out = std::move(m_items.front());
    m_items.pop_front();
    m_not_full.notify_one();
    return true;
  }
  void close() {
    std::lock_guard lock(m_mutex);
    m_closed = true;
    m_not_empty.notify_all();
    m_not_full.notify_all();
  }
  void abort() {
    std::lock_guard lock(m_mutex);
    m_closed = true;
    m_aborted = true;
    m_items.clear();
    m_not_empty.notify_all();
    m_not_full.notify_all();
  }

 private:
  const size_t m_capacity;
  std::mutex m_mutex;  // guards everything below
  std::condition_variable m_not_full;
  std::condition_variable m_not_empty;
  std::deque<T> m_items;
  bool m_closed = false;
  bool m_aborted = false;
};

}  // namespace clipstream
