// Cameras several test suites fly. Header-only: a binary that includes it
// links clipstream::streamer (camera.h) itself.
//
// Thread rule: plain values and pure functions; any thread.
#pragma once

#include <clipstream/streamer/camera.h>

#include <numbers>

namespace clipstream::test {

inline constexpr double kPi = std::numbers::pi;

// Straight above ground point (x, z) at `height` texels, looking down,
// heading 0 (north, -z, is up on screen).
inline Camera lookingDown(double x, double z, double height) {
  Camera c;
  c.position = {x, height, z};
  c.heading_rad = 0.0;
  c.pitch_rad = -kPi / 2;
  return c;
}

// Low and oblique over the first 2048 x 2048 texels: near tiles at level 0,
// the horizon's at coarse levels, so one frame spans many levels.
inline Camera obliqueCamera() {
  Camera c;
  c.position = {1000.5, 60.0, 1100.25};
  c.heading_rad = 0.3;
  c.pitch_rad = -0.6;
  return c;
}

}  // namespace clipstream::test
