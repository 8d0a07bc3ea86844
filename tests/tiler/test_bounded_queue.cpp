// The tiler pipeline's queue between stages (tiler/src/bounded_queue.h): the
// order it keeps, what close() and abort() leave to the consumers, and that
// a producer blocked on a full queue is released.
#include "bounded_queue.h"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

namespace clipstream {
namespace {

TEST(BoundedQueue, DeliversEveryItemInOrderThroughASmallQueue) {
  BoundedQueue<int> queue(2);
  constexpr int kItems = 1000;
  std::thread producer([&] {
    for (int i = 0; i < kItems; ++i) ASSERT_TRUE(queue.push(int(i)));
    queue.close();
  });
  std::vector<int> got;
  int item = 0;
  while (queue.pop(&item)) got.push_back(item);
  producer.join();
  ASSERT_EQ(got.size(), size_t(kItems));
  for (int i = 0; i < kItems; ++i) ASSERT_EQ(got[size_t(i)], i);
}

TEST(BoundedQueue, CloseLetsTheConsumerDrainAndRefusesMore) {
  BoundedQueue<int> queue(4);
  ASSERT_TRUE(queue.push(1));
  ASSERT_TRUE(queue.push(2));
  queue.close();
  EXPECT_FALSE(queue.push(3));
  int item = 0;
  ASSERT_TRUE(queue.pop(&item));
  EXPECT_EQ(item, 1);
  ASSERT_TRUE(queue.pop(&item));
  EXPECT_EQ(item, 2);
  EXPECT_FALSE(queue.pop(&item));  // closed and empty: the consumer stops
}

TEST(BoundedQueue, AbortDropsWhatIsQueued) {
  BoundedQueue<int> queue(4);
  ASSERT_TRUE(queue.push(1));
  ASSERT_TRUE(queue.push(2));
  queue.abort();
  int item = 0;
  EXPECT_FALSE(queue.pop(&item));
  EXPECT_FALSE(queue.push(3));
}

TEST(BoundedQueue, AProducerOnAFullQueueIsReleasedByAbortAndByAPop) {
  // The queue holds one item; the producer's second push can only return
  // once a pop made room, its third only when the queue is aborted.
  BoundedQueue<int> queue(1);
  std::atomic<int> pushed{0};
  std::thread producer([&] {
    EXPECT_TRUE(queue.push(10));
    pushed = 1;
    EXPECT_TRUE(queue.push(20));
    pushed = 2;
    queue.push(30);
    pushed = 3;
  });
  int item = 0;
  ASSERT_TRUE(queue.pop(&item));  // makes room for 20
  EXPECT_EQ(item, 10);
  ASSERT_TRUE(queue.pop(&item));  // waits for 20; then 30 fills the queue again
  EXPECT_EQ(item, 20);
  queue.abort();  // the producer may be blocked on 30 or have queued it: either way it returns
  producer.join();
  EXPECT_EQ(pushed.load(), 3);
  EXPECT_FALSE(queue.pop(&item));  // aborted: 30, if queued, is dropped
}

}  // namespace
}  // namespace clipstream
