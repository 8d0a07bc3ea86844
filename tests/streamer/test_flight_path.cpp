// Flight paths: JSON parsing (bad input is a Status, never a crash),
// interpolation through the keyframes, shortest-arc heading, built-ins.
#include <clipstream/streamer/flight_path.h>

#include <clipstream/testing/sanitizers.h>

#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

namespace clipstream {
namespace {

constexpr double kRad = std::numbers::pi / 180.0;

FlightPath threeKeys() {
  FlightPath p;
  p.keyframes = {{0.0, {0, 100, 0}, 0, -30}, {1.0, {100, 50, 0}, 90, -40}, {3.0, {100, 50, 300}, 180, -20}};
  return p;
}

TEST(FlightPath, PassesThroughEveryKeyframe) {
  const FlightPath p = threeKeys();
  for (const Keyframe& k : p.keyframes) {
    const Camera c = p.sample(k.t_s);
    EXPECT_NEAR(c.position.x, k.position.x, 1e-9);
    EXPECT_NEAR(c.position.y, k.position.y, 1e-9);
    EXPECT_NEAR(c.position.z, k.position.z, 1e-9);
    EXPECT_NEAR(c.heading_rad, k.heading_deg * kRad, 1e-9);
    EXPECT_NEAR(c.pitch_rad, k.pitch_deg * kRad, 1e-9);
  }
}

TEST(FlightPath, IsContinuousBetweenKeyframes) {
  const FlightPath p = threeKeys();
  glm::dvec3 prev = p.sample(0.0).position;
  for (double t = 0.001; t <= 3.0; t += 0.001) {
    const glm::dvec3 now = p.sample(t).position;
    EXPECT_LT(glm::length(now - prev), 2.0) << "jump at t=" << t;
    prev = now;
  }
}

TEST(FlightPath, TurnsTheShortWayRound) {
  FlightPath p;
  p.keyframes = {{0.0, {0, 10, 0}, 350, -30}, {1.0, {0, 10, 0}, 10, -30}};
  const double mid_deg = p.sample(0.5).heading_rad / kRad;
  // Through 360 (== 0), not back through 180.
  EXPECT_NEAR(std::fmod(mid_deg + 720.0, 360.0), 0.0, 1.0);
}

TEST(FlightPath, RoundTripsThroughJson) {
  const FlightPath p = threeKeys();
  FlightPath q;
  ASSERT_TRUE(FlightPath::fromJson(p.toJson(), &q).ok());
  ASSERT_EQ(q.keyframes.size(), p.keyframes.size());
  for (double t : {0.0, 0.4, 1.7, 3.0})
    EXPECT_NEAR(glm::length(q.sample(t).position - p.sample(t).position), 0.0, 1e-9);
}

// A long recorded path (400,000 keyframes, 34 MB of JSON) is read holding
// its Keyframes, not a JSON document of it: the whole document took 14
// times the file (a 69 MB path, 987 MB of memory). The child that reads it
// may map only 160 MB more than it has: the file, the Keyframes (18 MB)
// and the parser fit, a document of the file does not.
TEST(FlightPath, ALongPathIsReadWithoutHoldingItsJsonDocument) {
  if (test::kSanitized) GTEST_SKIP() << "an address-space limit means nothing under a sanitizer";
  const std::string path =
      (std::filesystem::temp_directory_path() / ("clipstream_long_path_" + std::to_string(::getpid()) + ".json"))
          .string();
  constexpr size_t kKeys = 400000;
  {
    std::ofstream out(path);
    out << "{\"interpolation\": \"smooth\", \"keyframes\": [";
    char line[160];
    for (size_t i = 0; i < kKeys; ++i) {
      std::snprintf(line, sizeof line,
                    "%s{\"t\": %.3f, \"x\": %.3f, \"y\": 300.0, \"z\": 1000.0, \"heading_deg\": 0.0, "
                    "\"pitch_deg\": -30.0}",
                    i ? ",\n" : "", double(i) * 0.01, 1000.0 + double(i) * 0.01);
      out << line;
    }
    out << "]}\n";
  }
  const uintmax_t file_bytes = std::filesystem::file_size(path);
  ASSERT_GT(file_bytes, uintmax_t(30) << 20);
  const pid_t pid = ::fork();
  if (pid == 0) {
    size_t vm_pages = 0;
    if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
      if (std::fscanf(f, "%zu", &vm_pages) != 1) vm_pages = 0;
      std::fclose(f);
    }
    const rlim_t limit = rlim_t(vm_pages) * rlim_t(::sysconf(_SC_PAGESIZE)) + (rlim_t(160) << 20);
    const rlimit as{limit, limit};
    ::setrlimit(RLIMIT_AS, &as);
    FlightPath p;
    try {
      const Status s = FlightPath::load(path, &p);
      ::_exit(s.ok() && p.keyframes.size() == kKeys ? 0 : 1);
    } catch (...) {
      ::_exit(2);  // std::bad_alloc: the limit was hit
    }
  }
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  std::filesystem::remove(path);
  ASSERT_TRUE(WIFEXITED(status)) << "the reader died of signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: not read whole; 2: out of memory";
}

TEST(FlightPath, RejectsMalformedJsonWithAStatus) {
  FlightPath p;
  const char* bad[] = {
      "",
      "{",
      "[]",
      "{\"keyframes\": 3}",
      "[{\"t\": 0, \"x\": 1, \"y\": 2, \"z\": 3, \"heading_deg\": 0}]",           // no pitch
      "[{\"t\": 0, \"x\": \"a\", \"y\": 2, \"z\": 3, \"heading_deg\": 0, \"pitch_deg\": 0}]",
      "[{\"t\": 1, \"x\": 1, \"y\": 2, \"z\": 3, \"heading_deg\": 0, \"pitch_deg\": 0},"
      " {\"t\": 0.5, \"x\": 1, \"y\": 2, \"z\": 3, \"heading_deg\": 0, \"pitch_deg\": 0}]",  // time goes back
      "{\"interpolation\": \"cubic\", \"keyframes\": []}",
  };
  for (const char* text : bad) {
    const Status s = FlightPath::fromJson(text, &p);
    EXPECT_FALSE(s.ok()) << text;
    EXPECT_EQ(s.code, ErrorCode::kInvalidArgument) << text;
  }
  EXPECT_EQ(FlightPath::load("/nonexistent/path.json", &p).code, ErrorCode::kNotFound);
}

TEST(FlightPath, BuiltinsStayOverTheTextureAndAboveGround) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(uint64_t(1) << 26, uint64_t(1) << 26, 128, PixelFormat::kRGB8, &g));
  for (const std::string& name : FlightPath::builtinNames()) {
    FlightPath p;
    ASSERT_TRUE(FlightPath::builtin(name, g, &p).ok()) << name;
    ASSERT_GT(p.durationS(), 0.0) << name;
    for (double t = 0.0; t <= p.durationS(); t += p.durationS() / 50.0) {
      const Camera c = p.sample(t);
      EXPECT_GE(c.position.y, 1.0) << name << " t=" << t;
      EXPECT_GE(c.position.x, 0.0) << name;
      EXPECT_LE(c.position.x, double(g.width_px)) << name;
      EXPECT_GE(c.position.z, 0.0) << name;
      EXPECT_LE(c.position.z, double(g.height_px)) << name;
    }
  }
  FlightPath p;
  EXPECT_EQ(FlightPath::builtin("loop-the-loop", g, &p).code, ErrorCode::kInvalidArgument);
}

TEST(FlightPath, TeleportJumpsEveryNFrames) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(100000, 100000, 128, PixelFormat::kRGB8, &g));
  FlightPath p;
  ASSERT_TRUE(FlightPath::builtin("teleport", g, &p, /*teleport_frames=*/10).ok());
  const double frame = 1.0 / 60.0;
  // Within a hold the camera is still; across the boundary it jumps.
  EXPECT_EQ(p.sample(1 * frame).position, p.sample(9 * frame).position);
  EXPECT_GT(glm::length(p.sample(10.5 * frame).position - p.sample(9 * frame).position), 100.0);
}

}  // namespace
}  // namespace clipstream
