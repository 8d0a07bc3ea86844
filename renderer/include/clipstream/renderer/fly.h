// The headless flythrough behind clipstream-fly: a flight path, the
// streamer and the clipmap renderer in one deterministic frame loop, with
// per-frame statistics written as CSV and JSON and chosen frames as PNG.
//
// Thread rule: runFly() owns its GL context and runs the frame loop on the
// calling thread; the streamer's workers read tiles and a FrameWriter
// thread encodes PNGs. Nothing in a frame waits on I/O.
#pragma once

#include <clipstream/renderer/renderer.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
#include <iosfwd>
#include <string>

namespace clipstream {

struct FlyOptions {
  std::string store_path;          // tile store; empty when procedural_px > 0
  uint64_t procedural_px = 0;      // > 0: procedural texture of this side instead
  std::string path = "orbit";      // built-in name or JSON file
  uint32_t frames = 0;             // 0 = the whole path at --speed
  Viewport viewport{1280, 720};
  double speed = 1.0;              // path seconds per simulated second
  uint64_t cache_mb = 256;         // streamer RAM budget
  uint32_t upload_tiles = 16;      // GPU uploads per frame
  unsigned io_threads = 0;         // 0 = cores
  std::string out_dir = "fly-out";
  uint32_t save_every = 0;         // 0 = no PNGs; N = every Nth frame (and the last)
  Buffering buffering = Buffering::kDoubleUploadTwice;
  bool overlay = false;
  bool quiet = false;              // no summary table
};

// Runs the flythrough. Frame i shows path time i * speed / 60 s whatever
// the real render time (simulated pacing: results are deterministic).
// Writes OUT/frames.csv, OUT/frames.json, OUT/frame_NNNNN.png and prints a
// summary table to `log`. Returns the first error (bad store, no GL
// context, unwritable output); per-tile failures are counted, not errors.
Status runFly(const FlyOptions& options, std::ostream& log);

// "1280x720" -> viewport. kInvalidArgument otherwise.
Status parseViewport(const std::string& text, Viewport* out);
// "single" | "double-upload" | "double-copy".
Status parseBuffering(const std::string& text, Buffering* out);

}  // namespace clipstream
