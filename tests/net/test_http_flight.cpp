// Flights over HTTP (headless llvmpipe): a store served by a real nginx
// renders the same frames as the local file once the tiles are in, and
// under faults (nginx stopped mid-flight and restarted, the store replaced
// on the server, a server 50 ms away) no frame waits on the network, the
// flight runs to its end and the picture recovers when the server does.
#include "test_helpers.h"

#include <clipstream/eval/flight_run.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/testing/net.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/test_data.h>

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>

namespace clipstream {
namespace {

using test::NginxServer;

const Viewport kViewport{160, 96};
constexpr uint32_t kMovingFrames = 60;
// Path seconds per simulated second: fast enough that the moving frames keep
// asking for new tiles (at 1 the whole flight needs about a hundred).
constexpr double kSpeed = 10.0;
// Rest frames of at least kRestFrameMs each give a slow or recovering
// source real time to catch up: 200 x 20 ms = 4 s.
constexpr uint32_t kRestFrames = 200;
// The outage of the stopped-server flight reaches this far into the rest
// (40 x 20 ms = 0.8 s); the streamer retries a tile 1 s after its first
// failure and 2 s after its second, well within the 3.2 s that remain.
constexpr uint32_t kOutageRestFrames = 40;
constexpr double kRestFrameMs = 20.0;
// Frames at the end of the rest that must equal the local flight's.
constexpr uint32_t kSettledFrames = 10;

struct CapturedFlight {
  FlightRun run;
  std::vector<std::vector<uint8_t>> frames;  // RGBA8 of every recorded frame
};

// Flies `path` over `source`, reading every recorded frame back; `at_frame`
// runs before frame i is kept (on the render thread, between frames).
Status fly(std::shared_ptr<TileSource> source, const FlightPath& path,
           const std::function<void(uint32_t)>& at_frame, bool judge, CapturedFlight* out) {
  FlightRunOptions o;
  o.source = std::move(source);
  o.path = path;
  o.frames = kMovingFrames;
  o.speed = kSpeed;
  o.rest_frames = kRestFrames;
  o.rest_frame_ms = kRestFrameMs;
  o.viewport = kViewport;
  o.sample_tiles = false;
  // The local flight is judged against the reference on its rest frames
  // (proof it converged); the HTTP flights are compared with it instead
  // (the reference would read the failing server synchronously).
  o.reference_every = judge ? 1000000 : 0;
  o.on_frame = [&](const FrameSample& frame, const OffscreenTarget& target, double*) {
    if (at_frame) at_frame(frame.frame);
    target.readRgba(&out->frames.emplace_back());
    return okStatus();
  };
  return runFlight(o, &out->run);
}

class HttpFlight : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    s_dir = new test::TempDir("http-flight");
    std::filesystem::create_directories(s_dir->file("www"));
    s_store = s_dir->file("store.cstore");
    s_other = s_dir->file("other.cstore");
    ProceduralSpec spec;
    spec.width_px = spec.height_px = 4096;
    spec.tile_px = 128;
    ASSERT_TRUE(test::writeStoreFromSource(*makeProceduralSource(spec), s_store).ok());
    spec.seed = 2;  // the "new version": another texture of the same size
    ASSERT_TRUE(test::writeStoreFromSource(*makeProceduralSource(spec), s_other).ok());
  }
  static void TearDownTestSuite() {
    delete s_local;
    s_local = nullptr;
    delete s_dir;
    s_dir = nullptr;
  }

  void SetUp() override {
    CLIPSTREAM_REQUIRE_GL();
    std::filesystem::copy_file(s_store, s_dir->file("www/store.cstore"),
                               std::filesystem::copy_options::overwrite_existing);
    const Status s =
        NginxServer::start(m_work.path().string(), s_dir->file("www"), &m_server);
    ASSERT_TRUE(s.ok()) << s.toString();
    Status open_status;
    const std::shared_ptr<TileSource> local = openStoreSource(s_store, &open_status);
    ASSERT_TRUE(local) << open_status.toString();
    ASSERT_TRUE(FlightPath::builtin("pass", local->geometry(), &m_path).ok());
    if (s_local == nullptr) {
      auto captured = std::make_unique<CapturedFlight>();
      const Status fs = fly(local, m_path, {}, true, captured.get());
      ASSERT_TRUE(fs.ok()) << fs.toString();
      ASSERT_EQ(captured->run.final_max_abs_error, 0) << "the local flight did not converge";
      ASSERT_EQ(captured->run.render_thread_fetches, 0u);
      s_local = captured.release();
    }
  }

  std::shared_ptr<TileSource> openUrl(const std::string& url) {
    Status s;
    std::shared_ptr<TileSource> source = openStoreSource(url, &s);
    EXPECT_TRUE(source) << s.toString();
    return source;
  }

  // The checks every HTTP flight shares: all frames drawn, none waited on
  // the network; with `recovered`, the last frames equal the local ones.
  void checkFlight(const CapturedFlight& http, bool recovered) {
    ASSERT_EQ(http.frames.size(), size_t(kMovingFrames + kRestFrames));
    EXPECT_EQ(http.run.render_thread_fetches, 0u) << "a frame waited on the network";
    if (!recovered) return;
    for (size_t i = http.frames.size() - kSettledFrames; i < http.frames.size(); ++i)
      EXPECT_TRUE(http.frames[i] == s_local->frames[i]) << "frame " << i << " differs";
  }

  static size_t identicalFrames(const CapturedFlight& a, const CapturedFlight& b) {
    size_t same = 0;
    for (size_t i = 0; i < std::min(a.frames.size(), b.frames.size()); ++i)
      same += a.frames[i] == b.frames[i];
    return same;
  }

  static test::TempDir* s_dir;
  static std::string s_store, s_other;
  static CapturedFlight* s_local;
  test::TempDir m_work{"http-flight-nginx"};
  std::unique_ptr<NginxServer> m_server;
  FlightPath m_path;
};

test::TempDir* HttpFlight::s_dir = nullptr;
std::string HttpFlight::s_store, HttpFlight::s_other;
CapturedFlight* HttpFlight::s_local = nullptr;

TEST_F(HttpFlight, FramesEqualTheLocalFlight) {
  CapturedFlight http;
  const Status s = fly(openUrl(m_server->url("store.cstore")), m_path, {}, false, &http);
  ASSERT_TRUE(s.ok()) << s.toString();
  checkFlight(http, true);
  EXPECT_EQ(http.run.tile_failures, 0u);
  EXPECT_EQ(http.run.streamer.loader_threads, RemoteOptions{}.connections);
  std::printf("  identical frames: %zu of %zu (the rest differ only while tiles stream in)\n",
              identicalFrames(http, *s_local), http.frames.size());
}

// The program, as the README runs it: clipstream-fly with a URL.
TEST_F(HttpFlight, ClipstreamFlyFliesAStoreByUrl) {
  const std::string out = m_work.file("fly");
  const std::string command = std::string("'") + CLIPSTREAM_FLY_EXE + "' '" +
                              m_server->url("store.cstore") + "' --frames 10 --size 160x96 "
                              "--http-connections 4 --out '" + out + "' 2>&1";
  std::string output;
  FILE* pipe = ::popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  char buffer[4096];
  size_t got;
  while ((got = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, got);
  const int status = ::pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << output;
  EXPECT_TRUE(std::filesystem::exists(out + "/frames.csv")) << output;
  EXPECT_FALSE(m_server->requests().empty());
}

// summary.tsv as key -> value (its two lines: the keys, the values).
std::map<std::string, std::string> readSummary(const std::string& path) {
  std::ifstream in(path);
  std::string keys, values;
  std::getline(in, keys);
  std::getline(in, values);
  std::map<std::string, std::string> summary;
  std::stringstream k(keys), v(values);
  for (std::string key, value; std::getline(k, key, '\t');) {
    value.clear();
    std::getline(v, value, '\t');
    summary[key] = value;
  }
  return summary;
}

// The summary says what the network and the disk cache did: a first run
// with --disk-cache sends requests and misses; a second, identical one is
// served by the cache (the same bytes were read before either way, so
// nothing else told the two runs apart). A local store leaves the fields
// empty.
TEST_F(HttpFlight, ClipstreamFlySummaryHasTheNetworkAndDiskCacheFigures) {
  const std::string cache = m_work.file("disk-cache");
  auto flyUrl = [&](const std::string& out) {
    const std::string command = std::string("'") + CLIPSTREAM_FLY_EXE + "' '" +
                                m_server->url("store.cstore") + "' --frames 20 --size 160x96 --save-frames 0 "
                                "--disk-cache '" + cache + "' --out '" + out + "' > '" + out + ".log' 2>&1";
    EXPECT_EQ(std::system(command.c_str()), 0) << command;
    return readSummary(out + "/summary.tsv");
  };
  const auto first = flyUrl(m_work.file("first"));
  const auto second = flyUrl(m_work.file("second"));
  for (const char* key : {"http_requests", "http_bytes", "http_retries", "disk_cache_hits", "disk_cache_misses"}) {
    ASSERT_EQ(first.count(key), 1u) << key;
    ASSERT_FALSE(first.at(key).empty()) << key;
    ASSERT_FALSE(second.at(key).empty()) << key;
  }
  EXPECT_GT(std::stoull(first.at("http_requests")), 0u);
  EXPECT_GT(std::stoull(first.at("http_bytes")), 0u);
  EXPECT_GT(std::stoull(first.at("disk_cache_misses")), 0u);
  // The first run hits too (a range read earlier in the run serves a later
  // tile); the second is served by what the first left.
  EXPECT_GT(std::stoull(second.at("disk_cache_hits")), std::stoull(first.at("disk_cache_hits")));
  EXPECT_LT(std::stoull(second.at("disk_cache_misses")), std::stoull(first.at("disk_cache_misses")));
  EXPECT_LT(std::stoull(second.at("http_requests")), std::stoull(first.at("http_requests")));
  EXPECT_LT(std::stoull(second.at("http_bytes")), std::stoull(first.at("http_bytes")));

  const std::string local_out = m_work.file("local");
  const std::string command = std::string("'") + CLIPSTREAM_FLY_EXE + "' '" + s_store +
                              "' --frames 5 --size 160x96 --save-frames 0 --out '" + local_out + "' > /dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  const auto local = readSummary(local_out + "/summary.tsv");
  EXPECT_EQ(local.at("http_requests"), "");
  EXPECT_EQ(local.at("disk_cache_hits"), "");
}

TEST_F(HttpFlight, NginxStoppedMidFlightDegradesAndRecovers) {
  CapturedFlight http;
  const auto at_frame = [&](uint32_t frame) {
    // Moving frames take about a millisecond each here, so the outage is
    // made to last in wall time: from the first frame into the rest frames
    // (at least kRestFrameMs each), then the server returns.
    if (frame == 0) m_server->stop();
    if (frame == kMovingFrames + kOutageRestFrames) {
      ASSERT_TRUE(m_server->restart().ok());
    }
  };
  const Status s = fly(openUrl(m_server->url("store.cstore")), m_path, at_frame, false, &http);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_GT(http.run.tile_failures, 0u) << "the outage was never seen";
  checkFlight(http, true);
  std::printf("  %llu tile reads failed; identical frames: %zu of %zu\n",
              static_cast<unsigned long long>(http.run.tile_failures), identicalFrames(http, *s_local),
              http.frames.size());
}

TEST_F(HttpFlight, StoreReplacedMidFlightIsNotMixedIn) {
  CapturedFlight http;
  const auto at_frame = [&](uint32_t frame) {
    if (frame != 0) return;
    const std::string tmp = s_dir->file("www/.store.cstore.new");
    std::filesystem::copy_file(s_other, tmp, std::filesystem::copy_options::overwrite_existing);
    std::filesystem::rename(tmp, s_dir->file("www/store.cstore"));
  };
  const Status s = fly(openUrl(m_server->url("store.cstore")), m_path, at_frame, false, &http);
  ASSERT_TRUE(s.ok()) << s.toString();
  checkFlight(http, false);
  EXPECT_GT(http.run.tile_failures, 0u) << "the new version was never noticed";
  // Detected by If-Range: the server answered with the whole (new) file,
  // which the reader cut off instead of taking a range of it.
  bool saw_200 = false;
  for (const test::LoggedRequest& r : m_server->requests()) saw_200 |= r.status == 200;
  EXPECT_TRUE(saw_200);
  // What was drawn after the change holds no tile of the new version: the
  // final frame is not the one the new store would give.
  CapturedFlight other;
  Status open_status;
  ASSERT_TRUE(fly(openStoreSource(s_other, &open_status), m_path, {}, false, &other).ok());
  EXPECT_FALSE(http.frames.back() == other.frames.back());
}

TEST_F(HttpFlight, SlowServerNeverHoldsAFrame) {
  std::unique_ptr<test::DelayProxy> proxy;
  ASSERT_TRUE(test::DelayProxy::start(m_server->port(), 50.0, &proxy).ok());
  CapturedFlight http;
  const Status s = fly(openUrl(proxy->url("store.cstore")), m_path, {}, false, &http);
  ASSERT_TRUE(s.ok()) << s.toString();
  checkFlight(http, true);
  EXPECT_EQ(http.run.tile_failures, 0u);
  std::printf("  identical frames at 50 ms: %zu of %zu\n", identicalFrames(http, *s_local),
              http.frames.size());
}

// A Cloud-Optimized GeoTIFF made by gdal_translate, served by nginx and
// streamed directly (no tiling), gives the frames of the store the tiler
// makes of it once the flight rests: its overviews (GDAL's average) are
// the store's box levels and its missing levels are built with the same
// filter. clipstream-fly takes its URL like a store's.
TEST(HttpCogFlight, AServedCogGivesItsTiledStoresFramesAtRest) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("cog-flight"), work("cog-flight-nginx");
  std::filesystem::create_directories(dir.file("www"));
  const std::string half = dir.file("half.tif"), cog = dir.file("www/image.tif"), store = dir.file("image.cstore");
  // Halved first, then made a COG: gdal_translate -of COG of a source with
  // overviews of its own (a JPEG's) would take them over.
  ASSERT_EQ(std::system(("gdal_translate -q -outsize 50% 50% -co TILED=YES '" + test::bundledDataPath("autzen.jpg") +
                         "' '" + half + "' >/dev/null 2>&1")
                            .c_str()),
            0);
  ASSERT_EQ(std::system(("gdal_translate -q -of COG -co OVERVIEW_RESAMPLING=AVERAGE -co COMPRESS=DEFLATE '" + half +
                         "' '" + cog + "' >/dev/null 2>&1")
                            .c_str()),
            0);
  ASSERT_EQ(std::system((std::string("'") + CLIPSTREAM_TILE_EXE + "' '" + cog + "' '" + store + "' >/dev/null 2>&1").c_str()), 0);
  std::unique_ptr<NginxServer> server;
  const Status started = NginxServer::start(work.path().string(), dir.file("www"), &server);
  ASSERT_TRUE(started.ok()) << started.toString();

  Status s;
  const std::shared_ptr<TileSource> local = openStoreSource(store, &s);
  ASSERT_TRUE(local) << s.toString();
  const std::shared_ptr<TileSource> streamed = openStoreSource(server->url("image.tif"), &s);
  ASSERT_TRUE(streamed) << s.toString();
  EXPECT_EQ(streamed->describe().rfind("cog:", 0), 0u);
  FlightPath path;
  ASSERT_TRUE(FlightPath::builtin("pass", local->geometry(), &path).ok());
  CapturedFlight tiled, direct;
  ASSERT_TRUE(fly(local, path, {}, true, &tiled).ok());
  ASSERT_EQ(tiled.run.final_max_abs_error, 0) << "the store's flight did not converge";
  const Status flown = fly(streamed, path, {}, false, &direct);
  ASSERT_TRUE(flown.ok()) << flown.toString();
  ASSERT_EQ(direct.frames.size(), tiled.frames.size());
  EXPECT_EQ(direct.run.tile_failures, 0u);
  EXPECT_EQ(direct.run.render_thread_fetches, 0u) << "a frame waited on the network";
  for (size_t i = direct.frames.size() - kSettledFrames; i < direct.frames.size(); ++i)
    EXPECT_TRUE(direct.frames[i] == tiled.frames[i]) << "frame " << i << " differs";
  for (const test::LoggedRequest& r : server->requests()) EXPECT_EQ(r.status, 206) << r.range;

  // The program, by URL.
  const std::string out = work.file("fly");
  const std::string command = std::string("'") + CLIPSTREAM_FLY_EXE + "' '" + server->url("image.tif") +
                              "' --frames 10 --size 160x96 --out '" + out + "' 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  char buffer[4096];
  for (size_t got; (got = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0;) output.append(buffer, got);
  const int status = ::pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << output;
  EXPECT_TRUE(std::filesystem::exists(out + "/frames.csv")) << output;
}

// A COG's georeference is the scene's as its tiled store's would be: a
// colour relief of the bundled DEM, made a COG by GDAL and served by
// nginx, lines up with the DEM's store exactly as the store the tiler
// makes of the same COG does.
TEST(HttpCogFlight, ACogLinesUpWithAnElevationStoreAsItsTiledStoreDoes) {
  test::TempDir dir("cog-align"), work("cog-align-nginx");
  std::filesystem::create_directories(dir.file("www"));
  const std::string dem = test::bundledDataPath("mount_st_helens_30m.tif");
  const std::string colours = dir.file("colours.txt"), relief = dir.file("relief.tif"),
                    cog = dir.file("www/relief.tif"), store = dir.file("relief.cstore"),
                    dem_store = dir.file("dem.cstore");
  std::ofstream(colours) << "700 40 90 40\n1500 140 120 80\n2600 250 250 250\n";
  ASSERT_EQ(std::system(("gdaldem color-relief -q '" + dem + "' '" + colours + "' '" + relief + "' >/dev/null 2>&1").c_str()), 0);
  ASSERT_EQ(std::system(("gdal_translate -q -of COG '" + relief + "' '" + cog + "' >/dev/null 2>&1").c_str()), 0);
  for (const auto& [in, out] : {std::pair{cog, store}, std::pair{dem, dem_store}})
    ASSERT_EQ(std::system((std::string("'") + CLIPSTREAM_TILE_EXE + "' '" + in + "' '" + out + "' >/dev/null 2>&1").c_str()), 0);
  std::unique_ptr<NginxServer> server;
  const Status started = NginxServer::start(work.path().string(), dir.file("www"), &server);
  ASSERT_TRUE(started.ok()) << started.toString();

  Status s;
  const auto tiled = openStoreSource(store, &s);
  ASSERT_TRUE(tiled) << s.toString();
  TerrainLayerConfig by_cog, by_store;
  std::vector<std::string> warnings;
  s = openTerrainLayer(server->url("relief.tif"), tiled->geometry(), dem_store, 1.0, false, 64, &by_cog, &warnings);
  ASSERT_TRUE(s.ok()) << s.toString();
  s = openTerrainLayer(store, tiled->geometry(), dem_store, 1.0, false, 64, &by_store, &warnings);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_FALSE(by_cog.alignment.stretched) << "placed by its georeference";
  EXPECT_EQ(by_cog.alignment.world_per_sample, by_store.alignment.world_per_sample);
  EXPECT_EQ(by_cog.alignment.sample0_world, by_store.alignment.sample0_world);
  EXPECT_EQ(by_cog.alignment.world_per_height, by_store.alignment.world_per_height);
  EXPECT_EQ(by_cog.alignment.metres_per_world, by_store.alignment.metres_per_world);
}

}  // namespace
}  // namespace clipstream
