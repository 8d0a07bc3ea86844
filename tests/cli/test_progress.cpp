// ProgressBar: thread-safe counting and the environment override.
#include <clipstream/cli/progress.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <thread>
#include <vector>

namespace clipstream::cli {
namespace {

TEST(ProgressBar, CountsExactlyUnderManyThreads) {
  ProgressBar bar("test", 8 * 10000, false, "items");
  std::atomic<bool> go{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&] {
      while (!go.load()) std::this_thread::yield();
      for (int i = 0; i < 10000; ++i) bar.add(1);
    });
  }
  go.store(true);
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(bar.done(), 80000u);
  bar.update(5);  // smaller values never move it back
  EXPECT_EQ(bar.done(), 80000u);
  bar.finish();
  bar.finish();
}

TEST(ProgressBar, EnvironmentOverridesTerminalDetection) {
  ::setenv("CLIPSTREAM_PROGRESS", "0", 1);
  EXPECT_FALSE(progressEnabledByDefault());
  ::setenv("CLIPSTREAM_PROGRESS", "1", 1);
  EXPECT_TRUE(progressEnabledByDefault());
  ::unsetenv("CLIPSTREAM_PROGRESS");
  EXPECT_EQ(progressEnabledByDefault(), stderrIsTty());
}

TEST(ProgressBar, DrawsPercentRateAndEndsTheLine) {
  // Drawn to stderr, which gtest lets us capture.
  ::testing::internal::CaptureStderr();
  {
    ProgressBar bar("verify", 200, true, "tiles");
    bar.update(100);
    bar.update(200);
  }
  const std::string text = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(text.find("verify"), std::string::npos) << text;
  EXPECT_NE(text.find("100%"), std::string::npos) << text;
  EXPECT_NE(text.find("tiles/s"), std::string::npos) << text;
  EXPECT_EQ(text.back(), '\n');
}

}  // namespace
}  // namespace clipstream::cli
