// Repeatable flights (StreamerConfig::deterministic_io through runFlight and
// clipstream-fly --deterministic): two runs of a flight that streams behind
// the camera give the same pixels and the same per-frame statistics, even
// with other loader counts and read latencies, and the read rate changes
// the flight. Frames are compared by a hash of their pixels (FNV-1a over
// the RGBA8 readback) and by their PSNR against the ideal reference.
#include "test_helpers.h"

#include <clipstream/eval/flight_run.h>
#include <clipstream/eval/metrics.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/streamer/testing/faulty_source.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

namespace clipstream {
namespace {

uint64_t fnv1a(const std::vector<uint8_t>& bytes) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (uint8_t b : bytes) h = (h ^ b) * 0x100000001b3ull;
  return h;
}

// Everything a frame shows or counts that must not depend on timing.
struct FrameFacts {
  uint64_t pixels_hash = 0;
  double psnr_db = 0.0;
  uint32_t tiles_uploaded = 0, max_texture_lod = 0, gpu_hits = 0, gpu_misses = 0;
  uint64_t tiles_loaded = 0, ram_hits = 0, ram_misses = 0, ram_bytes = 0, queue_depth = 0, in_flight = 0;
  bool operator==(const FrameFacts&) const = default;
};

struct Flown {
  std::vector<FrameFacts> frames;
  double psnr_mean_db = 0.0;
};

// The built-in pass over a 2^20 procedural texture at x8, 192x108, a
// reference every frame: fast enough that the loads trail the camera.
Flown fly(uint32_t reads_per_frame, unsigned io_threads, double latency_ms) {
  FlightRunOptions o;
  ProceduralSpec spec;
  spec.width_px = spec.height_px = 1 << 20;
  o.source = makeProceduralSource(spec);
  if (latency_ms > 0.0) {
    // The streamer's reads are slow; the reference reads the plain source.
    FaultSpec fault;
    fault.latency_ms = latency_ms;
    o.reference_source = o.source;
    o.source = makeFaultySource(o.source, fault);
  }
  EXPECT_TRUE(FlightPath::builtin("pass", o.source->geometry(), &o.path).ok());
  o.frames = 48;
  o.warmup_frames = 4;
  o.viewport = {192, 108};
  o.speed = 8.0;
  o.upload_tiles = 6;
  o.streamer.io_threads = io_threads;
  o.streamer.deterministic_io.enabled = true;
  o.streamer.deterministic_io.reads_per_frame = reads_per_frame;
  o.streamer.deterministic_io.latency_frames = 2;
  o.reference_every = 1;
  Flown out;
  std::vector<uint64_t> hashes;
  o.on_frame = [&](const FrameSample&, const OffscreenTarget& target, double*) {
    std::vector<uint8_t> rgba;
    target.readRgba(&rgba);
    hashes.push_back(fnv1a(rgba));
    return okStatus();
  };
  FlightRun run;
  const Status s = runFlight(o, &run);
  EXPECT_TRUE(s.ok()) << s.toString();
  EXPECT_EQ(hashes.size(), run.frames.size());
  for (size_t i = 0; i < run.frames.size() && i < hashes.size(); ++i) {
    const FrameSample& f = run.frames[i].sample;
    FrameFacts facts;
    facts.pixels_hash = hashes[i];
    facts.psnr_db = run.frames[i].accuracy.error.psnr_db;
    facts.tiles_uploaded = f.tiles_uploaded;
    facts.max_texture_lod = f.max_texture_lod;
    facts.gpu_hits = f.total.gpu_hits;
    facts.gpu_misses = f.total.gpu_misses;
    facts.tiles_loaded = f.tiles_loaded;
    facts.ram_hits = f.total.ram_hits;
    facts.ram_misses = f.total.ram_misses;
    facts.ram_bytes = f.ram_bytes;
    facts.queue_depth = f.queue_depth;
    facts.in_flight = f.in_flight;
    out.frames.push_back(facts);
  }
  out.psnr_mean_db = run.summary.psnr_mean_db;
  EXPECT_EQ(run.render_thread_fetches, 0u);
  return out;
}

TEST(DeterministicFlight, TwoRunsGiveTheSamePixelsAndStatisticsEveryFrame) {
  CLIPSTREAM_REQUIRE_GL();
  const Flown a = fly(4, 2, 0.0);
  // Another run with one loader whose every read takes 3 ms longer: in real
  // time that changes which tiles each frame has; here it must not.
  const Flown b = fly(4, 1, 3.0);
  ASSERT_EQ(a.frames.size(), 48u);
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (size_t i = 0; i < a.frames.size(); ++i) EXPECT_EQ(a.frames[i], b.frames[i]) << "frame " << i;
  // The flight streams behind the camera (else any mode would repeat).
  uint32_t trailing = 0;
  for (const FrameFacts& f : a.frames) trailing += f.psnr_db < kIdenticalPsnrDb ? 1 : 0;
  EXPECT_GT(trailing, 10u);
  for (const FrameFacts& f : a.frames) EXPECT_LE(f.tiles_loaded, 4u);
}

TEST(DeterministicFlight, FewerReadsPerFrameShowAnotherBlurrierFlight) {
  CLIPSTREAM_REQUIRE_GL();
  const Flown slow = fly(2, 2, 0.0);
  const Flown fast = fly(16, 2, 0.0);
  EXPECT_NE(slow.frames, fast.frames);
  EXPECT_LT(slow.psnr_mean_db, fast.psnr_mean_db);
  std::printf("  mean PSNR: %.2f dB at 2 reads a frame, %.2f dB at 16\n", slow.psnr_mean_db, fast.psnr_mean_db);
}

std::string readFile(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The flags reach the streamer and the reports: io_mode in summary.tsv, no
// frame loads more than --io-reads-per-frame, and the per-frame CSV's
// counters and PSNR are the same in two runs (frame times are not).
TEST(ClipstreamFlyDeterministic, FlagsReachTheStreamerAndTwoRunsWriteTheSameFrames) {
  CLIPSTREAM_REQUIRE_GL();
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("clipstream_fly_det_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  auto run = [&](const std::string& out, const std::string& extra) {
    const std::string cmd = std::string(CLIPSTREAM_FLY_EXE) +
                            " --procedural 1048576 --path pass --frames 30 --speed 8 --size 160x90 --reference"
                            " --deterministic --io-reads-per-frame 3 --io-latency-frames 2 --out " +
                            (dir / out).string() + extra + " > /dev/null 2>&1";
    return std::system(cmd.c_str());
  };
  ASSERT_EQ(run("a", " --io-threads 2"), 0);
  ASSERT_EQ(run("b", " --io-threads 1 --fault-latency-ms 2"), 0);
  const std::string summary = readFile(dir / "a" / "summary.tsv");
  EXPECT_NE(summary.find("io_mode"), std::string::npos);
  EXPECT_NE(summary.find("\tdeterministic\t3\t2"), std::string::npos) << summary;
  // frames.csv without its timing columns (frame_ms .. readback_ms).
  auto untimed = [&](const std::string& run_dir, uint64_t* most_loaded) {
    std::istringstream csv(readFile(dir / run_dir / "frames.csv"));
    std::string line, out;
    std::vector<std::string> header;
    size_t loaded_col = 0;
    *most_loaded = 0;
    for (bool first = true; std::getline(csv, line); first = false) {
      std::vector<std::string> cells;
      std::stringstream ls(line);
      for (std::string c; std::getline(ls, c, ',');) cells.push_back(c);
      if (first) {
        header = cells;
        for (size_t i = 0; i < header.size(); ++i)
          if (header[i] == "tiles_loaded") loaded_col = i;
      } else if (loaded_col < cells.size()) {
        *most_loaded = std::max<uint64_t>(*most_loaded, std::stoull(cells[loaded_col]));
      }
      for (size_t i = 0; i < cells.size() && i < header.size(); ++i) {
        const std::string& h = header[i];
        if (h == "frame_ms" || h == "streamer_ms" || h == "upload_ms" || h == "draw_ms" || h == "readback_ms")
          continue;
        out += cells[i] + ",";
      }
      out += "\n";
    }
    return out;
  };
  uint64_t most_a = 0, most_b = 0;
  const std::string a = untimed("a", &most_a), b = untimed("b", &most_b);
  EXPECT_GT(a.size(), 1000u);
  EXPECT_EQ(a, b);
  EXPECT_GE(most_a, 1u);
  EXPECT_LE(most_a, 3u);
  // The rate needs the mode: asked for alone it is a command-line mistake.
  const std::string lone = std::string(CLIPSTREAM_FLY_EXE) +
                           " --procedural 1048576 --frames 2 --io-reads-per-frame 3 --out " +
                           (dir / "c").string() + " > /dev/null 2>&1";
  const int rc = std::system(lone.c_str());
  EXPECT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 2) << rc;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace clipstream
