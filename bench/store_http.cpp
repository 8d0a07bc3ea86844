// Stores over HTTP: time to sharp after a teleport and tiles per second as a
// function of the round-trip time and the requests in flight, with the
// request count and the bytes the server sent; beside it, GDAL reading the
// same tile windows of a COG of the same image through /vsicurl/.
//
// A real nginx serves both files from a temporary folder on 127.0.0.1; a
// delaying proxy in this process adds the round trip to every request
// (tests/net, DelayProxy). The streamer runs without a renderer: each
// "frame" is update() + takeReady() every millisecond until settled() (every
// tile the plan needs handed off). Requests and bytes are counted from the
// nginx access log. The camera looks straight down from 200 texels over a
// 1280x720 viewport at a fixed list of places; prefetch is off (a teleport
// cannot be predicted).
//
// Usage: bench_store_http STORE.cstore [COG.tif] [--rtt 0,20,50,100]
//                         [--connections 1,4,8,16,32,64] [--teleports 4] [--no-coalesce]
// --no-coalesce: one range request per tile (RemoteOptions::batch_tiles = 1).
// COG: made with gdal_translate -of COG (docs/benchmarks.md); the GDAL rows
// need /usr/bin/python3 with GDAL (python3-gdal) and bench/gdal_read_windows.py.
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/testing/net.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

using namespace clipstream;
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
constexpr double kHeight = 200.0;            // camera height above ground, texels
constexpr double kSettleTimeoutS = 300.0;    // a configuration that takes longer is reported as such
const Viewport kViewport{1280, 720};

double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::vector<double> parseList(const std::string& text) {
  std::vector<double> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) out.push_back(std::atof(item.c_str()));
  return out;
}

Camera lookingDown(double x, double z) {
  Camera c;
  c.position = {x, kHeight, z};
  c.heading_rad = 0.0;
  c.pitch_rad = -1.5707963267948966;
  return c;
}

// Places as fractions of the image, visited in order after the start.
const double kPlaces[][2] = {{0.25, 0.25}, {0.75, 0.70}, {0.30, 0.80}, {0.70, 0.20},
                             {0.50, 0.15}, {0.15, 0.55}, {0.85, 0.45}, {0.40, 0.40}};

struct Teleport {
  double seconds = 0.0;
  uint64_t tiles = 0;
  std::string windows;  // the stack levels' windows, for the GDAL script
};

// Update and hand off until the plan is met; false on timeout.
bool settle(Streamer& streamer, const Camera& camera, Clock::time_point epoch) {
  const Clock::time_point start = Clock::now();
  for (;;) {
    streamer.update(camera, kViewport, secondsSince(epoch));
    streamer.takeReady(SIZE_MAX);
    if (streamer.settled()) return true;
    if (secondsSince(start) > kSettleTimeoutS) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

std::string planWindows(const ClipmapPlan& plan) {
  std::string out;
  for (const ClipLevelPlan& level : plan.stack) {
    if (!level.needed || level.window.empty()) continue;
    out += std::to_string(level.level) + ":" + std::to_string(level.window.x0) + ":" +
           std::to_string(level.window.y0) + ":" + std::to_string(level.window.x1) + ":" +
           std::to_string(level.window.y1) + ";";
  }
  return out;
}

struct LogTotals {
  uint64_t requests = 0, bytes = 0;
};

LogTotals logSince(const test::NginxServer& server, size_t from) {
  // nginx writes a line just after the answer: give the last ones time.
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const std::vector<test::LoggedRequest> log = server.requests();
  LogTotals totals;
  for (size_t i = from; i < log.size(); ++i) {
    totals.requests++;
    totals.bytes += log[i].body_bytes;
  }
  return totals;
}

}  // namespace

int main(int argc, char** argv) {
  std::string store_path, cog_path;
  std::vector<double> rtts = {0, 20, 50, 100};
  std::vector<double> connections = {1, 4, 8, 16, 32, 64};
  size_t teleports = 4;
  bool coalesce = true;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--rtt" && i + 1 < argc) {
      rtts = parseList(argv[++i]);
    } else if (arg == "--connections" && i + 1 < argc) {
      connections = parseList(argv[++i]);
    } else if (arg == "--no-coalesce") {
      coalesce = false;
    } else if (arg == "--teleports" && i + 1 < argc) {
      teleports = std::clamp<size_t>(std::strtoul(argv[++i], nullptr, 10), 1, std::size(kPlaces));
    } else if (store_path.empty()) {
      store_path = arg;
    } else if (cog_path.empty()) {
      cog_path = arg;
    } else {
      std::fprintf(stderr, "usage: %s STORE.cstore [COG.tif] [--rtt LIST] [--connections LIST] "
                           "[--teleports N] [--no-coalesce]\n", argv[0]);
      return 2;
    }
  }
  if (store_path.empty()) {
    std::fprintf(stderr, "usage: %s STORE.cstore [COG.tif] [--rtt LIST] [--connections LIST] "
                         "[--teleports N] [--no-coalesce]\n", argv[0]);
    return 2;
  }

  // The server's folder: copies, so nginx (running as this user) reads them.
  char dir_template[] = "/tmp/clipstream-bench-http-XXXXXX";
  if (::mkdtemp(dir_template) == nullptr) {
    std::perror("mkdtemp");
    return 1;
  }
  const fs::path work = dir_template;
  fs::create_directories(work / "www");
  fs::copy_file(store_path, work / "www/store.cstore");
  if (!cog_path.empty()) fs::copy_file(cog_path, work / "www/cog.tif");
  std::unique_ptr<test::NginxServer> server;
  Status s = test::NginxServer::start(work.string(), (work / "www").string(), &server);
  if (!s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  std::unique_ptr<TileStoreReader> local;
  if (Status open = TileStoreReader::open(store_path, &local); !open) {
    std::fprintf(stderr, "%s\n", open.toString().c_str());
    return 1;
  }
  const PyramidGeometry geometry = local->geometry();
  const uint64_t store_bytes = local->info().file_bytes;
  local.reset();
  std::printf("# store %s: %llux%llu %s, tile %u, %u levels, %.1f MiB; %zu teleports, camera %g "
              "texels up, viewport %ux%u, prefetch off, coalescing %s\n",
              store_path.c_str(), (unsigned long long)geometry.width_px,
              (unsigned long long)geometry.height_px, pixelFormatName(geometry.format),
              geometry.tile_px, geometry.levelCount(), store_bytes / 1048576.0, teleports, kHeight,
              kViewport.width_px, kViewport.height_px, coalesce ? "on" : "off");
  std::printf("reader\trtt_ms\tin_flight\topen_ms\topen_requests\tsharp_median_s\tsharp_max_s\t"
              "tiles\ttiles_per_s\trequests\trequests_per_tile\tMiB\n");

  auto place = [&](size_t i) {
    return lookingDown(kPlaces[i][0] * double(geometry.width_px),
                       kPlaces[i][1] * double(geometry.height_px));
  };
  const Camera start_camera =
      lookingDown(0.5 * double(geometry.width_px), 0.5 * double(geometry.height_px));

  for (const double rtt : rtts) {
    std::unique_ptr<test::DelayProxy> proxy;
    if (Status ps = test::DelayProxy::start(server->port(), rtt, &proxy); !ps) {
      std::fprintf(stderr, "%s\n", ps.toString().c_str());
      return 1;
    }
    std::vector<std::string> windows(teleports);
    for (const double count : connections) {
      RemoteOptions remote;
      remote.connections = unsigned(count);
      if (!coalesce) remote.batch_tiles = 1;
      size_t log_from = server->requests().size();
      const Clock::time_point open_start = Clock::now();
      Status open_status;
      std::shared_ptr<TileSource> source =
          openStoreSource(proxy->url("store.cstore"), remote, &open_status);
      if (!source) {
        std::fprintf(stderr, "%s\n", open_status.toString().c_str());
        return 1;
      }
      const double open_ms = secondsSince(open_start) * 1000.0;
      const LogTotals open_log = logSince(*server, log_from);
      StreamerConfig config;
      config.prefetch = false;
      Streamer streamer(source, config);
      const Clock::time_point epoch = Clock::now();
      if (!settle(streamer, start_camera, epoch)) {
        std::fprintf(stderr, "start place did not settle in %g s\n", kSettleTimeoutS);
        return 1;
      }
      log_from = server->requests().size();
      std::vector<double> seconds;
      uint64_t tiles = 0;
      bool timed_out = false;
      for (size_t t = 0; t < teleports; ++t) {
        const uint64_t loads_before = streamer.stats().total.loads;
        const Clock::time_point teleport_start = Clock::now();
        if (!settle(streamer, place(t), epoch)) timed_out = true;
        seconds.push_back(secondsSince(teleport_start));
        tiles += streamer.stats().total.loads - loads_before;
        windows[t] = planWindows(streamer.plan());
      }
      const LogTotals log = logSince(*server, log_from);
      streamer.shutdown();
      std::vector<double> sorted = seconds;
      std::sort(sorted.begin(), sorted.end());
      double total_s = 0.0;
      for (double v : seconds) total_s += v;
      std::printf("clipstream\t%g\t%u\t%.1f\t%llu\t%.3f\t%.3f%s\t%llu\t%.0f\t%llu\t%.2f\t%.2f\n",
                  rtt, remote.connections, open_ms, (unsigned long long)open_log.requests,
                  sorted[sorted.size() / 2], sorted.back(), timed_out ? " (timeout)" : "",
                  (unsigned long long)tiles, total_s > 0 ? double(tiles) / total_s : 0.0,
                  (unsigned long long)log.requests,
                  tiles ? double(log.requests) / double(tiles) : 0.0, log.bytes / 1048576.0);
      std::fflush(stdout);
    }
    // GDAL over the same proxy: the stack windows of each teleport.
    if (!cog_path.empty()) {
      const fs::path script = CLIPSTREAM_GDAL_SCRIPT;
      std::string command =
          "GDAL_DISABLE_READDIR_ON_OPEN=EMPTY_DIR CPL_VSIL_CURL_ALLOWED_EXTENSIONS=.tif "
          "/usr/bin/python3 " + script.string() + " /vsicurl/" + proxy->url("cog.tif");
      for (const std::string& w : windows) command += " '" + w + "'";
      const size_t log_from = server->requests().size();
      const Clock::time_point gdal_start = Clock::now();
      FILE* pipe = ::popen(command.c_str(), "r");
      std::vector<double> seconds;
      if (pipe != nullptr) {
        int index = 0;
        double value = 0.0;
        while (std::fscanf(pipe, "%d %lf", &index, &value) == 2) seconds.push_back(value);
        ::pclose(pipe);
      }
      const double all_s = secondsSince(gdal_start);
      const LogTotals log = logSince(*server, log_from);
      if (seconds.size() != windows.size()) {
        std::printf("gdal\t%g\t-\t-\t-\t(failed: %s)\n", rtt, command.c_str());
        continue;
      }
      std::vector<double> sorted = seconds;
      std::sort(sorted.begin(), sorted.end());
      double read_s = 0.0;
      for (double v : seconds) read_s += v;
      // GDAL's open is the process's run time less the reads (includes the
      // interpreter start, a few tens of milliseconds).
      std::printf("gdal_vsicurl\t%g\t-\t%.1f\t-\t%.3f\t%.3f\t-\t-\t%llu\t-\t%.2f\n", rtt,
                  (all_s - read_s) * 1000.0, sorted[sorted.size() / 2], sorted.back(),
                  (unsigned long long)log.requests, log.bytes / 1048576.0);
      std::fflush(stdout);
    }
  }
  server.reset();
  std::error_code ec;
  fs::remove_all(work, ec);
  return 0;
}
