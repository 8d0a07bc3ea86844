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
//                         [--batch N] [--protocols http,https1,h2] [--glide N]
//                         [--disk-cache DIR] [--tsv FILE]
// Prints a tab-separated table; --tsv FILE also writes it into FILE
// (docs/data/store_http*.tsv).
// --no-coalesce: one range request per tile (RemoteOptions::batch_tiles = 1).
// --batch N: RemoteOptions::batch_tiles (tiles the streamer hands a loader).
// --disk-cache DIR: RemoteOptions::disk_cache_dir for every store opened
// (run twice: the first run fills it, the second reads from it).
// --glide N: after the teleports, a flight on the store opened afresh: the
// camera glides across the image (from 20 % to 80 % of its width, at
// mid-height) in N steps, each settled before the next; one more row
// ("glide") with the requests and bytes of the steps after the first (its
// sharp_median_s column is the whole glide's time).
// --protocols: http = cleartext HTTP/1.1 (the default); https1 = TLS with
// HTTP/1.1 only (RemoteOptions::http2 off); h2 = TLS with HTTP/2 (ALPN).
// The TLS rows go to a second nginx with `listen ... ssl http2` and a
// self-signed certificate, through the same kind of proxy.
// COG: made with gdal_translate -of COG (docs/benchmarks.md). With a COG,
// two more kinds of rows: "cog_direct", the same teleports streamed from
// the COG itself (openStoreSource() of its URL: CogReader, no tiling), at
// each connection count over cleartext HTTP; and "gdal_vsicurl", which
// needs /usr/bin/python3 with GDAL (python3-gdal) and
// bench/gdal_read_windows.py.
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/testing/net.h>

#include "tsv_out.h"

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
  std::string windows;  // the stack tiles the plan wants, for the GDAL script
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

// The tiles the plan wants, as windows for the GDAL script: each row's runs
// of wanted tiles of each needed stack level (the whole window where the
// plan wants all of it), so GDAL reads what the streamer was asked for.
std::string planWindows(const ClipmapPlan& plan) {
  std::string out;
  auto add = [&](uint32_t level, int64_t x0, int64_t y0, int64_t x1, int64_t y1) {
    out += std::to_string(level) + ":" + std::to_string(x0) + ":" + std::to_string(y0) + ":" +
           std::to_string(x1) + ":" + std::to_string(y1) + ";";
  };
  for (const ClipLevelPlan& level : plan.stack) {
    if (!level.needed || level.window.empty()) continue;
    if (level.sampled.empty()) {
      add(level.level, level.window.x0, level.window.y0, level.window.x1, level.window.y1);
      continue;
    }
    for (int64_t y = level.window.y0; y < level.window.y1; ++y)
      for (int64_t x = level.window.x0; x < level.window.x1;) {
        if (!level.wants(x, y)) {
          ++x;
          continue;
        }
        int64_t end = x;
        while (end < level.window.x1 && level.wants(end, y)) ++end;
        add(level.level, x, y, end, y + 1);
        x = end;
      }
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

struct Options {
  std::string store_path, cog_path;
  std::vector<double> rtts = {0, 20, 50, 100};
  std::vector<double> connections = {1, 4, 8, 16, 32, 64};
  size_t teleports = 4;
  bool coalesce = true;
  unsigned batch = RemoteOptions{}.batch_tiles;
  size_t glide_steps = 0;
  std::string disk_cache;
  std::vector<std::string> protocols = {"http"};
};

// Reads the command line (less --tsv) into *options; false after printing
// why it cannot.
bool parseOptions(int argc, char** argv, Options* options) {
  Options& o = *options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--rtt" && i + 1 < argc) {
      o.rtts = parseList(argv[++i]);
    } else if (arg == "--connections" && i + 1 < argc) {
      o.connections = parseList(argv[++i]);
    } else if (arg == "--no-coalesce") {
      o.coalesce = false;
    } else if (arg == "--disk-cache" && i + 1 < argc) {
      o.disk_cache = argv[++i];
    } else if (arg == "--glide" && i + 1 < argc) {
      o.glide_steps = std::strtoul(argv[++i], nullptr, 10);
    } else if (arg == "--batch" && i + 1 < argc) {
      o.batch = unsigned(std::clamp<unsigned long>(std::strtoul(argv[++i], nullptr, 10), 1, 64));
    } else if (arg == "--protocols" && i + 1 < argc) {
      o.protocols.clear();
      std::stringstream in(argv[++i]);
      std::string item;
      while (std::getline(in, item, ',')) {
        if (item != "http" && item != "https1" && item != "h2") {
          std::fprintf(stderr, "unknown protocol %s (http, https1, h2)\n", item.c_str());
          return false;
        }
        o.protocols.push_back(item);
      }
    } else if (arg == "--teleports" && i + 1 < argc) {
      o.teleports = std::clamp<size_t>(std::strtoul(argv[++i], nullptr, 10), 1, std::size(kPlaces));
    } else if (o.store_path.empty()) {
      o.store_path = arg;
    } else if (o.cog_path.empty()) {
      o.cog_path = arg;
    } else {
      std::fprintf(stderr, "usage: %s STORE.cstore [COG.tif] [--rtt LIST] [--connections LIST] "
                           "[--teleports N] [--no-coalesce] [--batch N] [--protocols LIST]\n",
                   argv[0]);
      return false;
    }
  }
  if (o.store_path.empty()) {
    std::fprintf(stderr, "usage: %s STORE.cstore [COG.tif] [--rtt LIST] [--connections LIST] "
                         "[--teleports N] [--no-coalesce]\n", argv[0]);
    return false;
  }
  return true;
}

// What one configuration (protocol, round trip, connections) is measured
// against: the server that logs its requests, the URL through the proxy and
// the store's geometry.
struct Target {
  const test::NginxServer* host = nullptr;
  std::string url;
  PyramidGeometry geometry;
};

struct GlideResult {
  LogTotals log;
  uint64_t tiles = 0;
  double seconds = 0.0;
};

// The flight, on a store opened afresh (nothing cached): small steps, each
// settled, as a smooth camera asks; counted after the first. False when the
// store does not open (after printing why).
bool measureGlide(const Target& target, const RemoteOptions& remote, const StreamerConfig& config,
                  size_t glide_steps, Clock::time_point epoch, bool* timed_out,
                  GlideResult* result) {
  Status open_status;
  std::shared_ptr<TileSource> glide_source = openStoreSource(target.url, remote, &open_status);
  if (!glide_source) {
    std::fprintf(stderr, "%s\n", open_status.toString().c_str());
    return false;
  }
  Streamer glider(glide_source, config);
  auto at = [&](size_t step) {
    const double f = 0.2 + 0.6 * double(step) / double(glide_steps);
    return lookingDown(f * double(target.geometry.width_px),
                       0.5 * double(target.geometry.height_px));
  };
  if (!settle(glider, at(0), epoch)) *timed_out = true;
  const size_t glide_from = target.host->requests().size();
  const uint64_t loads_before = glider.stats().total.loads;
  const Clock::time_point glide_start = Clock::now();
  for (size_t step = 1; step <= glide_steps; ++step) {
    if (!settle(glider, at(step), epoch)) *timed_out = true;
  }
  result->seconds = secondsSince(glide_start);
  result->tiles = glider.stats().total.loads - loads_before;
  result->log = logSince(*target.host, glide_from);
  glider.shutdown();
  return true;
}

// One clipstream row (and its glide row, with --glide): open the store, settle
// at the start, time each teleport. Fills windows[t] with the stack tiles the plan wants
// of teleport t for the GDAL rows. False on a fatal error (printed).
bool measureClipstream(const Options& o, const Target& target, const std::string& protocol,
                       double rtt, unsigned connections, const std::string& ca_file,
                       std::vector<std::string>* windows, bench::TsvOut* table,
                       const char* reader = "clipstream") {
  const bool tls = protocol != "http";
  RemoteOptions remote;
  remote.connections = connections;
  remote.batch_tiles = o.coalesce ? o.batch : 1;
  remote.http2 = protocol == "h2";
  remote.disk_cache_dir = o.disk_cache;
  if (tls) remote.ca_file = ca_file;
  const test::NginxServer& host = *target.host;
  size_t log_from = host.requests().size();
  const Clock::time_point open_start = Clock::now();
  Status open_status;
  std::shared_ptr<TileSource> source = openStoreSource(target.url, remote, &open_status);
  if (!source) {
    std::fprintf(stderr, "%s\n", open_status.toString().c_str());
    return false;
  }
  const double open_ms = secondsSince(open_start) * 1000.0;
  const LogTotals open_log = logSince(host, log_from);
  StreamerConfig config;
  config.prefetch = false;
  Streamer streamer(source, config);
  const Clock::time_point epoch = Clock::now();
  const Camera start_camera = lookingDown(0.5 * double(target.geometry.width_px),
                                          0.5 * double(target.geometry.height_px));
  if (!settle(streamer, start_camera, epoch)) {
    std::fprintf(stderr, "start place did not settle in %g s\n", kSettleTimeoutS);
    return false;
  }
  log_from = host.requests().size();
  std::vector<double> seconds;
  uint64_t tiles = 0;
  bool timed_out = false;
  for (size_t t = 0; t < o.teleports; ++t) {
    const Camera place = lookingDown(kPlaces[t][0] * double(target.geometry.width_px),
                                     kPlaces[t][1] * double(target.geometry.height_px));
    const uint64_t loads_before = streamer.stats().total.loads;
    const Clock::time_point teleport_start = Clock::now();
    if (!settle(streamer, place, epoch)) timed_out = true;
    seconds.push_back(secondsSince(teleport_start));
    tiles += streamer.stats().total.loads - loads_before;
    (*windows)[t] = planWindows(streamer.plan());
  }
  const LogTotals log = logSince(host, log_from);
  const uint64_t connections_opened = source->remoteStats().connections;
  streamer.shutdown();
  GlideResult glide;
  if (o.glide_steps > 0 &&
      !measureGlide(target, remote, config, o.glide_steps, epoch, &timed_out, &glide)) {
    return false;
  }
  std::vector<double> sorted = seconds;
  std::sort(sorted.begin(), sorted.end());
  double total_s = 0.0;
  for (double v : seconds) total_s += v;
  table->row("%s\t%s\t%g\t%u\t%llu\t%.1f\t%llu\t%.3f\t%.3f%s\t%llu\t%.0f\t%llu\t%.2f\t"
             "%.2f\n",
             reader, protocol.c_str(), rtt, remote.connections, (unsigned long long)connections_opened,
             open_ms, (unsigned long long)open_log.requests, sorted[sorted.size() / 2],
             sorted.back(), timed_out ? " (timeout)" : "", (unsigned long long)tiles,
             total_s > 0 ? double(tiles) / total_s : 0.0, (unsigned long long)log.requests,
             tiles ? double(log.requests) / double(tiles) : 0.0, log.bytes / 1048576.0);
  if (o.glide_steps > 0) {
    table->row("glide\t%s\t%g\t%u\t-\t-\t-\t%.3f\t-\t%llu\t%.0f\t%llu\t%.2f\t%.2f\n",
               protocol.c_str(), rtt, remote.connections, glide.seconds,
               (unsigned long long)glide.tiles,
               glide.seconds > 0 ? double(glide.tiles) / glide.seconds : 0.0,
               (unsigned long long)glide.log.requests,
               glide.tiles ? double(glide.log.requests) / double(glide.tiles) : 0.0,
               glide.log.bytes / 1048576.0);
  }
  std::fflush(stdout);
  return true;
}

// The GDAL row: GDAL over the same proxy reads the stack tiles the plan wanted at each
// teleport from the COG.
void measureGdal(const test::NginxServer& server, const test::DelayProxy& proxy, double rtt,
                 const std::vector<std::string>& windows, bench::TsvOut* table) {
  const fs::path script = CLIPSTREAM_GDAL_SCRIPT;
  std::string command =
      "GDAL_DISABLE_READDIR_ON_OPEN=EMPTY_DIR CPL_VSIL_CURL_ALLOWED_EXTENSIONS=.tif "
      "/usr/bin/python3 " + script.string() + " /vsicurl/" + proxy.url("cog.tif");
  for (const std::string& w : windows) command += " '" + w + "'";
  const size_t log_from = server.requests().size();
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
  const LogTotals log = logSince(server, log_from);
  if (seconds.size() != windows.size()) {
    table->row("gdal\thttp\t%g\t-\t-\t-\t-\t(failed: %s)\n", rtt, command.c_str());
    return;
  }
  std::vector<double> sorted = seconds;
  std::sort(sorted.begin(), sorted.end());
  double read_s = 0.0;
  for (double v : seconds) read_s += v;
  // GDAL's open is the process's run time less the reads (includes the
  // interpreter start, a few tens of milliseconds).
  table->row("gdal_vsicurl\thttp\t%g\t-\t-\t%.1f\t-\t%.3f\t%.3f\t-\t-\t%llu\t-\t%.2f\n", rtt,
             (all_s - read_s) * 1000.0, sorted[sorted.size() / 2], sorted.back(),
             (unsigned long long)log.requests, log.bytes / 1048576.0);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  Options o;
  if (!parseOptions(argc, argv, &o)) return 2;

  // The server's folder: copies, so nginx (running as this user) reads them.
  char dir_template[] = "/tmp/clipstream-bench-http-XXXXXX";
  if (::mkdtemp(dir_template) == nullptr) {
    std::perror("mkdtemp");
    return 1;
  }
  const fs::path work = dir_template;
  fs::create_directories(work / "www");
  fs::copy_file(o.store_path, work / "www/store.cstore");
  if (!o.cog_path.empty()) fs::copy_file(o.cog_path, work / "www/cog.tif");
  std::unique_ptr<test::NginxServer> server, tls_server;
  Status s = test::NginxServer::start(work.string(), (work / "www").string(), &server);
  const bool tls_wanted =
      std::find(o.protocols.begin(), o.protocols.end(), "http") == o.protocols.end() ||
      o.protocols.size() > 1;
  if (s && tls_wanted) {
    fs::create_directories(work / "tls");
    s = test::NginxServer::start((work / "tls").string(), (work / "www").string(), &tls_server,
                                 true, true);
  }
  if (!s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  std::unique_ptr<TileStoreReader> local;
  if (Status open = TileStoreReader::open(o.store_path, &local); !open) {
    std::fprintf(stderr, "%s\n", open.toString().c_str());
    return 1;
  }
  const PyramidGeometry geometry = local->geometry();
  const uint64_t store_bytes = local->info().file_bytes;
  local.reset();
  std::printf("# store %s: %llux%llu %s, tile %u, %u levels, %.1f MiB; %zu teleports, camera %g "
              "texels up, viewport %ux%u, prefetch off, coalescing %s, batch %u tiles\n",
              o.store_path.c_str(), (unsigned long long)geometry.width_px,
              (unsigned long long)geometry.height_px, pixelFormatName(geometry.format),
              geometry.tile_px, geometry.levelCount(), store_bytes / 1048576.0, o.teleports,
              kHeight, kViewport.width_px, kViewport.height_px, o.coalesce ? "on" : "off",
              o.coalesce ? o.batch : 1u);
  table.row("reader\tprotocol\trtt_ms\tin_flight\tconnections\topen_ms\topen_requests\t"
              "sharp_median_s\tsharp_max_s\ttiles\ttiles_per_s\trequests\trequests_per_tile\t"
              "MiB\n");

  for (const double rtt : o.rtts) {
    std::unique_ptr<test::DelayProxy> proxy, tls_proxy;
    if (Status ps = test::DelayProxy::start(server->port(), rtt, &proxy); !ps) {
      std::fprintf(stderr, "%s\n", ps.toString().c_str());
      return 1;
    }
    if (tls_server) {
      if (Status ps = test::DelayProxy::start(tls_server->port(), rtt, &tls_proxy); !ps) {
        std::fprintf(stderr, "%s\n", ps.toString().c_str());
        return 1;
      }
    }
    std::vector<std::string> windows(o.teleports);
    for (const std::string& protocol : o.protocols) {
      const bool tls = protocol != "http";
      Target target;
      target.host = tls ? tls_server.get() : server.get();
      target.url = tls ? "https://127.0.0.1:" + std::to_string(tls_proxy->port()) + "/store.cstore"
                       : proxy->url("store.cstore");
      target.geometry = geometry;
      const std::string ca_file = tls ? tls_server->certificateFile() : std::string();
      for (const double count : o.connections) {
        if (!measureClipstream(o, target, protocol, rtt, unsigned(count), ca_file, &windows,
                               &table)) {
          return 1;
        }
      }
    }
    if (!o.cog_path.empty()) {
      // The COG streamed directly, as clipstream-fly COG_URL does.
      Target cog;
      cog.host = server.get();
      cog.url = proxy->url("cog.tif");
      cog.geometry = geometry;
      std::vector<std::string> cog_windows(o.teleports);
      for (const double count : o.connections)
        if (!measureClipstream(o, cog, "http", rtt, unsigned(count), "", &cog_windows, &table, "cog_direct"))
          return 1;
      measureGdal(*server, *proxy, rtt, windows, &table);
    }
  }
  server.reset();
  tls_server.reset();
  std::error_code ec;
  fs::remove_all(work, ec);
  return table.commit() ? 0 : 1;
}
