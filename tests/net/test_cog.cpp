// Cloud-Optimized GeoTIFFs read directly (store/src/cog_reader.cpp): COGs
// made by GDAL's own gdal_translate -of COG, in every common compression
// and several internal tile sizes, give the tiles of the store the tiler
// makes of the same file (its overviews, made with GDAL's average, equal
// the tiler's box levels; the levels the file lacks are built with the box
// filter); over HTTP from a real nginx they give the same tiles by range
// requests, the disk cache serves a second reader; what cannot be read is
// refused with the command that converts it.
#include "../tiler/tiler_test_util.h"

#include <clipstream/store/cog.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/net.h>
#include <clipstream/testing/test_data.h>

#include <gtest/gtest.h>

#include <tiffio.h>

#include <cstdlib>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

namespace clipstream::test {
namespace {

namespace fs = std::filesystem;

class Cog : public ::testing::Test {
 protected:
  // The bundled aerial image at half size (1624 x 2193: edge tiles in both
  // directions), as a plain GeoTIFF that the COGs are made from.
  static void SetUpTestSuite() {
    s_dir = new TempDir("cog");
    s_base = s_dir->file("base.tif");
    ASSERT_EQ(shell("gdal_translate -q -outsize 50% 50% -co TILED=YES " + shellQuoted(bundledDataPath("autzen.jpg")) +
                    " " + shellQuoted(s_base)),
              0);
  }
  static void TearDownTestSuite() {
    delete s_dir;
    s_dir = nullptr;
  }

  // gdal_translate -of COG with `options`, overviews by GDAL's average.
  static std::string makeCog(const std::string& name, const std::string& options,
                             const std::string& input = "") {
    const std::string out = s_dir->file(name);
    EXPECT_EQ(shell("gdal_translate -q -of COG -co OVERVIEW_RESAMPLING=AVERAGE " + options + " " +
                    shellQuoted(input.empty() ? s_base : input) + " " + shellQuoted(out)),
              0);
    return out;
  }
  // The store the tiler makes of `cog` (it reads the full image only).
  static std::string tileIt(const std::string& cog) {
    const std::string out = cog + ".cstore";
    const RunResult r = runTiler({cog, out});
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return out;
  }

  static TempDir* s_dir;
  static std::string s_base;
};
TempDir* Cog::s_dir = nullptr;
std::string Cog::s_base;

// Tiles of every level of `reader` that differ from `store`'s (the count),
// and whether the geometry and georeference agree.
// Levels [levels_from, levels_to) are compared.
uint64_t differingTiles(const CogReader& reader, const TileStoreReader& store, uint32_t levels_from = 0,
                        uint32_t levels_to = 64) {
  const PyramidGeometry& g = reader.geometry();
  EXPECT_EQ(g.width_px, store.geometry().width_px);
  EXPECT_EQ(g.height_px, store.geometry().height_px);
  EXPECT_EQ(g.levelCount(), store.geometry().levelCount());
  EXPECT_EQ(g.format, store.geometry().format);
  uint64_t differ = 0;
  std::vector<uint8_t> a(g.tileBytes()), b;
  for (uint32_t l = levels_from; l < std::min(levels_to, g.levelCount()); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        uint64_t bytes = 0;
        const TileKey key{l, x, y};
        const Status s = reader.readTile(key, a, &bytes);
        EXPECT_TRUE(s.ok()) << s.toString();
        EXPECT_TRUE(store.readTile(key, &b).ok());
        differ += a != b;
      }
  return differ;
}

std::unique_ptr<CogReader> openCog(const std::string& path, const RemoteOptions& remote = {}) {
  std::unique_ptr<CogReader> reader;
  const Status s = CogReader::open(path, remote, &reader);
  EXPECT_TRUE(s.ok()) << s.toString();
  return reader;
}

std::unique_ptr<TileStoreReader> openStore(const std::string& path) {
  std::unique_ptr<TileStoreReader> reader;
  const Status s = TileStoreReader::open(path, &reader);
  EXPECT_TRUE(s.ok()) << s.toString();
  return reader;
}

TEST_F(Cog, EveryCompressionAndTileSizeGivesItsTiledStoresTiles) {
  struct Case {
    const char* name;
    const char* options;
    uint32_t tile_px;
    const char* codec;
    // Lossy: each overview is compressed on its own, so only the full
    // image's pixels are the tiler's (level 0 alone is compared).
    bool lossy;
  } cases[] = {
      {"deflate.tif", "-co COMPRESS=DEFLATE -co PREDICTOR=YES", 512, "deflate", false},
      {"lzw.tif", "-co COMPRESS=LZW -co BLOCKSIZE=128", 128, "lzw", false},
      {"zstd.tif", "-co COMPRESS=ZSTD -co BLOCKSIZE=1024", 1024, "zstd", false},
      {"jpeg.tif", "-co COMPRESS=JPEG -co BLOCKSIZE=256", 256, "jpeg", true},
      {"webp.tif", "-co COMPRESS=WEBP -co BLOCKSIZE=64", 64, "webp", true},
      // 32 px tiles: GDAL's overviews of this size are 1/4, 1/8 with
      // rounded sizes (406 x 548), not the pyramid's (406 x 549): built.
      {"none.tif", "-co COMPRESS=NONE -co BLOCKSIZE=32", 32, "none", false},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string cog = makeCog(c.name, c.options);
    const auto reader = openCog(cog);
    const auto store = openStore(tileIt(cog));
    ASSERT_TRUE(reader && store);
    EXPECT_EQ(reader->layout().internal_tile_px, c.tile_px);
    EXPECT_EQ(reader->layout().compression, c.codec);
    EXPECT_FALSE(reader->layout().stored_levels.back()) << "the one-tile level is below GDAL's last overview";
    if (c.tile_px >= 512) {
      EXPECT_TRUE(reader->layout().stored_levels[1]) << "GDAL's overviews are the pyramid's levels";
    }
    EXPECT_EQ(differingTiles(*reader, *store, 0, c.lossy ? 1 : reader->geometry().levelCount()), 0u);
    // The georeference the tiler read from the same file.
    EXPECT_TRUE(reader->info().geo.present);
    for (int i = 0; i < 6; ++i) EXPECT_EQ(reader->info().geo.transform[i], store->info().geo.transform[i]);
    EXPECT_EQ(reader->info().geo.crs, store->info().geo.crs);
  }
}

TEST_F(Cog, LevelsTheFileLacksAreBuiltWithTheStoresBoxFilter) {
  const std::string cog = makeCog("no_overviews.tif", "-co OVERVIEWS=NONE -co COMPRESS=DEFLATE");
  const auto reader = openCog(cog);
  ASSERT_TRUE(reader);
  for (size_t l = 1; l < reader->layout().stored_levels.size(); ++l) EXPECT_FALSE(reader->layout().stored_levels[l]);
  const auto store = openStore(tileIt(cog));
  EXPECT_EQ(differingTiles(*reader, *store), 0u);
}

TEST_F(Cog, GreyGreyAlphaAndRgbaAreRead) {
  struct Case {
    const char* name;
    const char* options;
    PixelFormat format;
  } cases[] = {
      {"grey.tif", "-b 1", PixelFormat::kR8},
      {"rgba.tif", "-b 1 -b 2 -b 3 -b 1 -colorinterp_4 alpha", PixelFormat::kRGBA8},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const auto reader = openCog(makeCog(c.name, std::string(c.options) + " -co COMPRESS=DEFLATE"));
    ASSERT_TRUE(reader);
    EXPECT_EQ(reader->geometry().format, c.format);
    const auto store = openStore(tileIt(s_dir->file(c.name)));
    EXPECT_EQ(differingTiles(*reader, *store, 0), 0u);
  }
  // Grey + alpha is widened to RGBA8: grey in R, G and B.
  const auto ga = openCog(makeCog("grey_alpha.tif", "-b 1 -b 2 -colorinterp_2 alpha -co COMPRESS=LZW"));
  const auto grey = openCog(s_dir->file("grey.tif"));
  ASSERT_TRUE(ga && grey);
  EXPECT_EQ(ga->geometry().format, PixelFormat::kRGBA8);
  std::vector<uint8_t> a(ga->geometry().tileBytes()), g(grey->geometry().tileBytes());
  uint64_t bytes = 0;
  ASSERT_TRUE(ga->readTile({0, 3, 4}, a, &bytes).ok());
  ASSERT_TRUE(grey->readTile({0, 3, 4}, g, &bytes).ok());
  bool widened = true;
  for (size_t i = 0; i < g.size(); ++i) widened = widened && a[4 * i] == g[i] && a[4 * i + 1] == g[i] && a[4 * i + 2] == g[i];
  EXPECT_TRUE(widened);
}

TEST_F(Cog, WhatCannotBeReadIsRefusedWithTheCommandThatConvertsIt) {
  struct Case {
    std::string path;
    ErrorCode code;
    const char* says;
  };
  const std::string striped = s_dir->file("striped.tif");
  ASSERT_EQ(shell("gdal_translate -q -co TILED=NO " + shellQuoted(s_base) + " " + shellQuoted(striped)), 0);
  const std::string text = s_dir->file("notes.tif");
  std::ofstream(text) << "not an image\n";
  const std::string truncated = s_dir->file("truncated.tif");
  const std::string deflate = makeCog("cut_from.tif", "-co COMPRESS=DEFLATE");
  fs::copy_file(deflate, truncated);
  fs::resize_file(truncated, 3000);
  const Case cases[] = {
      {makeCog("dem.tif", "", bundledDataPath("mount_st_helens_30m.tif")), ErrorCode::kUnsupported, "tile a DEM"},
      {striped, ErrorCode::kUnsupported, "gdal_translate -of COG"},
      {makeCog("big_bare.tif", "-co OVERVIEWS=NONE", bundledDataPath("autzen.jpg")), ErrorCode::kUnsupported,
       "add overviews"},
      {text, ErrorCode::kBadMagic, "not a TIFF"},
      {truncated, ErrorCode::kTruncated, "past the end"},
      {s_dir->file("missing.tif"), ErrorCode::kNotFound, "missing.tif"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.path);
    std::unique_ptr<CogReader> reader;
    const Status s = CogReader::open(c.path, {}, &reader);
    EXPECT_FALSE(s.ok());
    EXPECT_FALSE(reader);
    EXPECT_EQ(s.code, c.code) << s.toString();
    EXPECT_NE(s.message.find(c.says), std::string::npos) << s.toString();
    EXPECT_NE(s.message.find(fs::path(c.path).filename().string()), std::string::npos) << s.toString();
  }
  // The programs' dispatch: a file neither a store nor a TIFF says both.
  Status s;
  EXPECT_FALSE(openStoreSource(text, &s));
  EXPECT_NE(s.message.find("not a clipstream tile store nor a TIFF"), std::string::npos) << s.toString();
}

TEST_F(Cog, ADamagedTileIsACorruptTileNotACrash) {
  const std::string cog = makeCog("damaged.tif", "-co COMPRESS=DEFLATE -co BLOCKSIZE=256");
  const auto healthy = openCog(cog);
  ASSERT_TRUE(healthy);
  // Overwrite the middle of the file (tile data; the header lies first).
  {
    std::fstream f(cog, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(fs::file_size(cog) / 2));
    const std::string junk(20000, '\x5a');
    f.write(junk.data(), std::streamsize(junk.size()));
  }
  const auto reader = openCog(cog);
  ASSERT_TRUE(reader);
  std::vector<uint8_t> pixels(reader->geometry().tileBytes());
  uint64_t corrupt = 0, bytes = 0;
  const LevelInfo& level0 = reader->geometry().levels[0];
  for (uint32_t y = 0; y < level0.tiles_y; ++y)
    for (uint32_t x = 0; x < level0.tiles_x; ++x) {
      const Status s = reader->readTile({0, x, y}, pixels, &bytes);
      if (!s.ok()) {
        EXPECT_EQ(s.code, ErrorCode::kCorruptTile) << s.toString();
        ++corrupt;
      }
    }
  EXPECT_GT(corrupt, 0u);
  EXPECT_EQ(reader->readTile({reader->geometry().levelCount(), 0, 0}, pixels, &bytes).code, ErrorCode::kOutOfRange);
}

// Over HTTP: a real nginx, range requests only, the same tiles as the file;
// a second reader with the same disk cache folder asks for no tile again.
TEST_F(Cog, OverHttpTheTilesComeByRangeRequestsAndTheDiskCacheKeepsThem) {
  const std::string cog = makeCog("served.tif", "-co COMPRESS=JPEG -co BLOCKSIZE=512");
  TempDir www("cog-www"), work("cog-nginx");
  fs::copy_file(cog, www.file("served.tif"));
  std::unique_ptr<NginxServer> server;
  const Status started = NginxServer::start(work.path().string(), www.path().string(), &server);
  ASSERT_TRUE(started.ok()) << started.toString();
  RemoteOptions remote;
  remote.disk_cache_dir = work.file("cache");
  const auto local = openCog(cog);
  auto remote_reader = openCog(server->url("served.tif"), remote);
  ASSERT_TRUE(local && remote_reader);
  const size_t open_requests = server->requests(1).size();  // the open reads at least once (the log lands late)
  EXPECT_LE(open_requests, 3u) << "the header and tile tables come in a few reads";
  const PyramidGeometry& g = local->geometry();
  std::vector<uint8_t> a(g.tileBytes()), b(g.tileBytes());
  uint64_t tiles = 0, bytes = 0, differ = 0;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        ASSERT_TRUE(local->readTile({l, x, y}, a, &bytes).ok());
        const Status s = remote_reader->readTile({l, x, y}, b, &bytes);
        ASSERT_TRUE(s.ok()) << s.toString();
        differ += a != b;
        ++tiles;
      }
  EXPECT_EQ(differ, 0u);
  const std::vector<LoggedRequest> log = server->requests();
  for (const LoggedRequest& r : log) {
    EXPECT_EQ(r.status, 206) << r.range;
    EXPECT_FALSE(r.range.empty());
  }
  // One request per internal tile read (each 512 px tile feeds 16 pyramid tiles).
  const RemoteStats first = remote_reader->remoteStats();
  EXPECT_LT(log.size(), tiles / 4) << "internal tiles are read once for their pyramid tiles";
  EXPECT_GT(first.disk_cache_misses, 0u);
  remote_reader.reset();

  server->clearLog();
  const auto again = openCog(server->url("served.tif"), remote);
  ASSERT_TRUE(again);
  for (uint32_t y = 0; y < g.levels[0].tiles_y; ++y)
    for (uint32_t x = 0; x < g.levels[0].tiles_x; ++x) ASSERT_TRUE(again->readTile({0, x, y}, b, &bytes).ok());
  EXPECT_EQ(again->remoteStats().disk_cache_misses, 0u);
  EXPECT_GT(again->remoteStats().disk_cache_hits, 0u);
  // As many as an open makes (the log may still lack some: it lands late), no tile.
  EXPECT_LE(server->requests().size(), 3u) << "only the open's reads go to the server";
}

// The programs' entry: openStoreSource() takes a COG path or URL.
TEST_F(Cog, OpenStoreSourceServesACogAsRgba8) {
  const std::string cog = makeCog("source.tif", "-co COMPRESS=ZSTD");
  Status s;
  const auto source = openStoreSource(cog, &s);
  ASSERT_TRUE(source) << s.toString();
  EXPECT_EQ(source->describe().rfind("cog:", 0), 0u);
  const auto store = openStoreSource(tileIt(cog), &s);
  ASSERT_TRUE(store) << s.toString();
  std::vector<uint8_t> a, b;
  ASSERT_TRUE(source->fetch({1, 2, 3}, &a).ok());
  ASSERT_TRUE(store->fetch({1, 2, 3}, &b).ok());
  EXPECT_EQ(a, b);
  StoreInfo info;
  ASSERT_TRUE(readRasterInfo(cog, {}, &info).ok());
  EXPECT_TRUE(info.geo.present);
  EXPECT_EQ(info.geometry.width_px, source->geometry().width_px);
}

// A COG's no-data value is transparency, as the tiler makes it of the same
// file (D293): RGBA8, black under alpha 0 where every sample is no-data.
TEST_F(Cog, ANoDataCollarIsTransparentAsInTheTiledStore) {
  const std::string collar = s_dir->file("collar.tif");
  // 100 px outside the image on every side: GDAL fills them with 0.
  ASSERT_EQ(shell("gdal_translate -q -a_nodata 0 -srcwin -100 -100 1824 2393 " + shellQuoted(s_base) + " " +
                  shellQuoted(collar)),
            0);
  const std::string cog = makeCog("collar_cog.tif", "-co COMPRESS=DEFLATE", collar);
  const auto reader = openCog(cog);
  const auto store = openStore(tileIt(cog));
  ASSERT_TRUE(reader && store);
  EXPECT_EQ(reader->geometry().format, PixelFormat::kRGBA8);
  EXPECT_EQ(store->geometry().format, PixelFormat::kRGBA8);
  EXPECT_EQ(differingTiles(*reader, *store, 0, 1), 0u);
  std::vector<uint8_t> corner(reader->geometry().tileBytes());
  uint64_t bytes = 0;
  ASSERT_TRUE(reader->readTile({0, 0, 0}, corner, &bytes).ok());
  EXPECT_EQ(corner[3], 0) << "the collar's first texel";
  EXPECT_EQ(corner[((120 * 128) + 120) * 4 + 3], 255) << "inside the image";
}

// Overviews made apart from the full image: one compressed otherwise (JPEG
// overviews of a deflate COG) is a level all the same, decoded with its
// own codec; overviews that skip levels have the gap built, up to two
// levels in a row, and three in a row are refused naming the fix.
TEST_F(Cog, OverviewsOfAnotherCodecAreLevelsAndGapsAreBuiltOrRefused) {
  const std::string square = s_dir->file("square.tif");
  ASSERT_EQ(shell("gdal_translate -q -co TILED=YES -outsize 2048 2048 " + shellQuoted(bundledDataPath("autzen.jpg")) +
                  " " + shellQuoted(square)),
            0);
  const auto reader = openCog(makeCog("jpeg_overviews.tif", "-co COMPRESS=DEFLATE -co OVERVIEW_COMPRESS=JPEG", square));
  ASSERT_TRUE(reader);
  EXPECT_TRUE(reader->layout().stored_levels[1]);
  const auto store = openStore(tileIt(s_dir->file("jpeg_overviews.tif")));
  ASSERT_TRUE(store);
  EXPECT_EQ(differingTiles(*reader, *store, 0, 1), 0u);
  // Level 1 is GDAL's JPEG-compressed average: near the store's box level.
  std::vector<uint8_t> a(reader->geometry().tileBytes()), b;
  uint64_t bytes = 0, sum = 0;
  ASSERT_TRUE(reader->readTile({1, 3, 2}, a, &bytes).ok());
  ASSERT_TRUE(store->readTile({1, 3, 2}, &b).ok());
  for (size_t i = 0; i < a.size(); ++i) sum += uint64_t(std::abs(int(a[i]) - int(b[i])));
  EXPECT_LT(double(sum) / double(a.size()), 4.0) << "YCbCr JPEG overviews decoded as RGB";

  for (const auto& [factor, opens] : {std::pair{8, true}, std::pair{16, false}}) {
    SCOPED_TRACE(factor);
    const std::string sparse = s_dir->file("overview_" + std::to_string(factor) + ".tif");
    fs::copy_file(square, sparse, fs::copy_options::overwrite_existing);
    ASSERT_EQ(shell("gdaladdo -q -r average " + shellQuoted(sparse) + " " + std::to_string(factor)), 0);
    std::unique_ptr<CogReader> gappy;
    const Status s = CogReader::open(sparse, {}, &gappy);
    EXPECT_EQ(s.ok(), opens) << s.toString();
    if (opens) {
      EXPECT_FALSE(gappy->layout().stored_levels[1]);
      EXPECT_FALSE(gappy->layout().stored_levels[2]);
      EXPECT_TRUE(gappy->layout().stored_levels[3]);
      const auto tiled = openStore(tileIt(sparse));
      ASSERT_TRUE(tiled);
      EXPECT_EQ(differingTiles(*gappy, *tiled, 0, 3), 0u) << "levels 1 and 2 built with the box filter";
    } else {
      EXPECT_NE(s.message.find("every factor of 2"), std::string::npos) << s.toString();
    }
  }
}

// A tiled TIFF that keeps its directory at the end (as libtiff writes
// one) is opened by reading the blocks around it, not the file whole.
TEST_F(Cog, ATiledTiffWithItsDirectoryAtTheEndIsNotReadWhole) {
  const std::string tiff = s_dir->file("directory_last.tif");
  {
    // libtiff writes the directory after the image data.
    TIFF* t = TIFFOpen(tiff.c_str(), "w");
    ASSERT_NE(t, nullptr);
    const uint32_t w = 2000, h = 1500, tile = 256;
    TIFFSetField(t, TIFFTAG_IMAGEWIDTH, w);
    TIFFSetField(t, TIFFTAG_IMAGELENGTH, h);
    TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, 3);
    TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, 8);
    TIFFSetField(t, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_RGB);
    TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(t, TIFFTAG_TILEWIDTH, tile);
    TIFFSetField(t, TIFFTAG_TILELENGTH, tile);
    std::vector<uint8_t> pixels(size_t(tile) * tile * 3);
    for (uint32_t ty = 0; ty < h; ty += tile)
      for (uint32_t tx = 0; tx < w; tx += tile) {
        for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t((tx + i / 3 % tile) * 7 + (ty + i / 3 / tile) * 3 + i % 3 * 50);
        ASSERT_GE(TIFFWriteTile(t, pixels.data(), tx, ty, 0, 0), 0);
      }
    TIFFClose(t);
  }
  {
    std::ifstream in(tiff, std::ios::binary);
    uint8_t head[8] = {};
    in.read(reinterpret_cast<char*>(head), 8);
    const uint32_t first_ifd = uint32_t(head[4]) | uint32_t(head[5]) << 8 | uint32_t(head[6]) << 16 | uint32_t(head[7]) << 24;
    ASSERT_GT(first_ifd, fs::file_size(tiff) / 2) << "the writer put the directory first: the test needs it last";
  }
  const auto reader = openCog(tiff);
  ASSERT_TRUE(reader);
  EXPECT_LT(reader->layout().header_bytes, 256u << 10) << "of " << fs::file_size(tiff);
  EXPECT_LT(reader->bytesRead(), 256u << 10);
  const auto store = openStore(tileIt(tiff));
  ASSERT_TRUE(store);
  EXPECT_EQ(differingTiles(*reader, *store), 0u);
}

// Loader threads share one reader: the decoded-tile cache (one decode
// for many askers), the libtiff handle pools and the built levels give
// every thread the tiles one thread reads alone, in any order.
TEST_F(Cog, ConcurrentReadersGetTheTilesOneReaderGets) {
  const std::string cog = makeCog("shared.tif", "-co COMPRESS=DEFLATE -co BLOCKSIZE=256");
  const auto alone = openCog(cog);
  const auto shared = openCog(cog);
  ASSERT_TRUE(alone && shared);
  const PyramidGeometry& g = alone->geometry();
  std::vector<TileKey> keys;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) keys.push_back({l, x, y});
  std::vector<std::vector<uint8_t>> expected(keys.size(), std::vector<uint8_t>(g.tileBytes()));
  uint64_t bytes = 0;
  for (size_t i = 0; i < keys.size(); ++i) ASSERT_TRUE(alone->readTile(keys[i], expected[i], &bytes).ok());
  constexpr unsigned kThreads = 6;
  std::vector<uint64_t> wrong(kThreads, 0);
  std::vector<std::thread> threads;
  for (unsigned t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      std::vector<uint8_t> pixels(g.tileBytes());
      // Each thread its own order: coarsest first, finest first, strided.
      for (size_t n = 0; n < keys.size(); ++n) {
        const size_t i = t % 2 == 0 ? (n * (2 * t + 1)) % keys.size() : keys.size() - 1 - n;
        uint64_t read = 0;
        if (!shared->readTile(keys[i], pixels, &read).ok() || pixels != expected[i]) ++wrong[t];
      }
    });
  for (std::thread& t : threads) t.join();
  for (unsigned t = 0; t < kThreads; ++t) EXPECT_EQ(wrong[t], 0u) << "thread " << t;
}

// clipstream-info describes a COG as the programs stream it and, with
// --verify, reads every pyramid tile; a damaged one fails with exit 3.
TEST_F(Cog, ClipstreamInfoDescribesAndVerifiesACog) {
  const std::string cog = makeCog("described.tif", "-co COMPRESS=LZW");
  RunResult r = runInfo({cog, "--verify"});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("512 px inside the file, streamed as 128 px"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("lzw"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("no: built from the level below"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("verify       "), std::string::npos) << r.output;
  r = runInfo({cog, "--json"});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("\"internal_tile_px\": 512"), std::string::npos) << r.output;
  {
    std::fstream f(cog, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(fs::file_size(cog) / 2));
    const std::string junk(50000, '\x33');
    f.write(junk.data(), std::streamsize(junk.size()));
  }
  r = runInfo({cog, "--verify"});
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("corrupt tile"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace clipstream::test
