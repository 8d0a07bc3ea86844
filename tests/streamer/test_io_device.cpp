// The deterministic I/O device on its own (io_device.h): tickets come back
// in issue order at their due frame, whatever order the loaders finish in.
#include "../../streamer/src/io_device.h"  // private: the device under test

#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

namespace clipstream {
namespace {

LayerTile tile(uint32_t x) { return {0, {0, x, 0}}; }

TEST(IoDevice, PublishesInIssueOrderAtTheDueFrameWhateverOrderReadsFinish) {
  std::mutex mutex;
  IoDevice io;
  std::vector<std::shared_ptr<IoTicket>> taken;
  {
    std::lock_guard<std::mutex> lock(mutex);
    io.issue(tile(0), 2, false);
    io.issue(tile(1), 2, true);
    io.issue(tile(2), 3, false);
    ASSERT_TRUE(io.hasWork());
    while (std::shared_ptr<IoTicket> t = io.takeWork()) taken.push_back(t);
    EXPECT_FALSE(io.hasWork());
    EXPECT_EQ(io.outstanding(), 3u);
  }
  ASSERT_EQ(taken.size(), 3u);
  EXPECT_TRUE(taken[1]->reread);

  // A loader finishes the reads last first, the first one only after the
  // render thread has started waiting for it.
  std::thread loader([&] {
    for (size_t i = taken.size(); i-- > 0;) {
      taken[i]->status = okStatus();
      taken[i]->pixels->assign(1, uint8_t(i));
      std::lock_guard<std::mutex> lock(mutex);
      io.finished(*taken[i]);
    }
  });
  std::unique_lock<std::mutex> lock(mutex);
  EXPECT_EQ(io.nextDue(lock, 1, false), nullptr);  // nothing due in frame 1
  std::vector<uint32_t> order;
  while (std::shared_ptr<IoTicket> t = io.nextDue(lock, 2, false)) {
    EXPECT_TRUE(t->done);
    EXPECT_EQ(t->pixels->at(0), t->key.key.x);
    order.push_back(t->key.key.x);
  }
  EXPECT_EQ(order, (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(io.outstanding(), 1u);
  std::shared_ptr<IoTicket> last = io.nextDue(lock, 2, true);  // at shutdown: every ticket
  ASSERT_NE(last, nullptr);
  EXPECT_EQ(last->key.key.x, 2u);
  EXPECT_EQ(io.outstanding(), 0u);
  lock.unlock();
  loader.join();
}

TEST(IoDevice, WaitsForAReadStillInFlight) {
  std::mutex mutex;
  IoDevice io;
  std::shared_ptr<IoTicket> ticket;
  {
    std::lock_guard<std::mutex> lock(mutex);
    io.issue(tile(7), 1, false);
    ticket = io.takeWork();
  }
  bool released = false;
  std::thread loader([&] {
    std::lock_guard<std::mutex> lock(mutex);
    released = true;
    io.finished(*ticket);
  });
  std::unique_lock<std::mutex> lock(mutex);
  const std::shared_ptr<IoTicket> due = io.nextDue(lock, 1, false);
  EXPECT_TRUE(released);  // it returned only once the loader had finished
  EXPECT_EQ(due, ticket);
  lock.unlock();
  loader.join();
}

}  // namespace
}  // namespace clipstream
