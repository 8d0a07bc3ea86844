// The camera's motion for prefetch on its own (motion.h): the velocity from
// the recent positions, the history's span, and teleports.
#include "../../streamer/src/motion.h"  // private: the predictor under test

#include <gtest/gtest.h>

#include <vector>

namespace clipstream {
namespace {

Camera at(double x, double y, double z) {
  Camera c;
  c.position = {x, y, z};
  return c;
}

const std::vector<MotionPredictor::JumpLimit> kFarLimit{{{1.0, 1.0}, 1e9}};

TEST(MotionPredictor, NeedsTwoPositionsSpanningATwentiethOfASecond) {
  MotionPredictor m;
  m.record(0.0, {0, 10, 0});
  EXPECT_FALSE(m.predict(at(0, 10, 0), 1.0, kFarLimit));
  m.record(0.01, {1, 10, 0});  // 10 ms: too short to tell a velocity
  EXPECT_FALSE(m.predict(at(1, 10, 0), 1.0, kFarLimit));
  m.record(0.1, {10, 10, 0});
  EXPECT_TRUE(m.predict(at(10, 10, 0), 1.0, kFarLimit));
}

TEST(MotionPredictor, MovesOnAtTheRecordedVelocityAboveTheNearPlane) {
  MotionPredictor m;
  for (int i = 0; i <= 10; ++i) m.record(0.05 * i, {100.0 * 0.05 * i, 50.0 - 200.0 * 0.05 * i, -20.0 * 0.05 * i});
  Camera now = at(50, -50, -10);
  now.near_dist = 0.5;
  now.heading_rad = 0.7;
  const auto ahead = m.predict(now, 2.0, kFarLimit);
  ASSERT_TRUE(ahead);
  EXPECT_NEAR(ahead->position.x, 50 + 200, 1e-9);   // 100 units/s for 2 s
  EXPECT_NEAR(ahead->position.z, -10 - 40, 1e-9);   // -20 units/s
  EXPECT_DOUBLE_EQ(ahead->position.y, 0.5);          // falling: held at the near plane
  EXPECT_EQ(ahead->heading_rad, now.heading_rad);    // orientation kept
}

TEST(MotionPredictor, KeepsHalfASecondOfHistory) {
  MotionPredictor m;
  // Still for a second, then moving: the velocity is that of the last half second.
  for (int i = 0; i <= 20; ++i) m.record(0.05 * i, {0, 10, 0});
  for (int i = 1; i <= 10; ++i) m.record(1.0 + 0.05 * i, {10.0 * 0.05 * i, 10, 0});
  EXPECT_LE(m.historySize(), 12u);
  const auto ahead = m.predict(at(5, 10, 0), 1.0, kFarLimit);
  ASSERT_TRUE(ahead);
  EXPECT_NEAR(ahead->position.x, 5 + 10, 1e-6);
}

TEST(MotionPredictor, AJumpPastTheLimitOfAnyLayerIsATeleportAndForgetsTheHistory) {
  MotionPredictor m;
  for (int i = 0; i <= 5; ++i) m.record(0.05 * i, {double(i), 10, 0});
  m.record(0.3, {1000, 10, 0});  // a 995-unit jump in one frame
  // Layer 0 would call it motion; layer 1 (8 texels a unit) sees 7960 texels.
  const std::vector<MotionPredictor::JumpLimit> limits{{{1.0, 1.0}, 5000.0}, {{8.0, 8.0}, 5000.0}};
  EXPECT_FALSE(m.predict(at(1000, 10, 0), 1.0, limits));
  EXPECT_EQ(m.historySize(), 1u);  // only where the camera is now
  m.record(0.4, {1002, 10, 0});
  const auto ahead = m.predict(at(1002, 10, 0), 1.0, limits);
  ASSERT_TRUE(ahead);
  EXPECT_NEAR(ahead->position.x, 1002 + 20, 1e-6);  // the velocity since the jump
  EXPECT_EQ(MotionPredictor::teleportTexels(1024.0), 2048.0);
}

}  // namespace
}  // namespace clipstream
