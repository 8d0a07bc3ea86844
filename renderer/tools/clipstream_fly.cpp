// clipstream-fly: headless flythrough with per-frame statistics.
// Usage and output formats: docs/renderer.md.
#include <clipstream/renderer/fly.h>

#include <CLI/CLI.hpp>

#include <iostream>

int main(int argc, char** argv) {
  using namespace clipstream;
  CLI::App app{"Headless clipmap flythrough: renders a flight path over a tile store and "
               "writes per-frame statistics (CSV, JSON) and PNG frames."};
  FlyOptions o;
  std::string size = "1280x720", buffering = bufferingName(o.buffering);
  app.add_option("store", o.store_path, "Tile store file (omit with --procedural)");
  app.add_option("--path", o.path, "Built-in path (pass, dive, orbit, teleport, zoom) or JSON file");
  app.add_option("--frames", o.frames, "Frames to render (default: the whole path)");
  app.add_option("--size", size, "Viewport WIDTHxHEIGHT");
  app.add_option("--speed", o.speed, "Path seconds per simulated second")->check(CLI::PositiveNumber);
  app.add_option("--cache-mb", o.cache_mb, "Streamer RAM budget in MiB");
  app.add_option("--upload-tiles", o.upload_tiles, "GPU tile uploads per frame");
  app.add_option("--io-threads", o.io_threads, "Loader threads (0 = cores)");
  app.add_option("--out", o.out_dir, "Output directory");
  app.add_option("--save-frames", o.save_every, "Save every Nth frame as PNG (0 = none)");
  app.add_option("--procedural", o.procedural_px, "Use a procedural texture of this side (texels)");
  app.add_option("--buffering", buffering, "single, double-upload or double-copy");
  app.add_flag("--overlay", o.overlay, "Tint by level, mark missing/throttled tiles");
  CLI11_PARSE(app, argc, argv);

  if (o.store_path.empty() && o.procedural_px == 0) {
    std::cerr << "clipstream-fly: give a STORE or --procedural SIDE\n";
    return 2;
  }
  Status s = parseViewport(size, &o.viewport);
  if (s) s = parseBuffering(buffering, &o.buffering);
  if (s) s = runFly(o, std::cout);
  if (!s) {
    std::cerr << "clipstream-fly: " << s.toString() << "\n";
    return 1;
  }
  return 0;
}
