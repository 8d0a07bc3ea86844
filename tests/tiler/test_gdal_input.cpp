// Inputs read through GDAL (tiler/src/gdal_source.cpp): a VRT and a URL
// served by a real nginx tile like the local file they stand for, JPEG 2000
// goes to GDAL with the pixels OpenImageIO decodes, --reader gdal gives the
// tiler's own readers' tiles, a failing server is an error naming the URL
// with nothing written, and GDAL is loaded only when an input needs it.
#include "tiler_test_util.h"

#include <clipstream/testing/files.h>
#include <clipstream/testing/net.h>
#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/georef.h>
#include <clipstream/tiler/image_source.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace clipstream::test {
namespace {

namespace fs = std::filesystem;

double pattern(uint64_t x, uint64_t y, int c) {
  return double((x * 131 + y * 71 + uint64_t(c) * 29 + ((x * y) >> 3)) & 255);
}

// Whether clipstream-tile, tiling `input`, loaded a library whose file
// name contains `library` (the dynamic loader's own log, LD_DEBUG=files).
bool tilerLoads(const TempDir& dir, const std::string& input, const std::string& library) {
  const std::string log_dir = dir.file("ld-" + fs::path(input).filename().string());
  fs::create_directories(log_dir);
  ::setenv("LD_DEBUG", "files", 1);
  ::setenv("LD_DEBUG_OUTPUT", (log_dir + "/ld").c_str(), 1);
  const RunResult r = runTiler({input, dir.file(fs::path(input).filename().string() + ".cst")});
  ::unsetenv("LD_DEBUG");
  ::unsetenv("LD_DEBUG_OUTPUT");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  bool found = false, logged = false;
  for (const auto& entry : fs::directory_iterator(log_dir)) {
    const std::string log = readText(entry.path().string());
    logged = logged || log.find("clipstream-tile") != std::string::npos;
    found = found || log.find(library) != std::string::npos;
  }
  EXPECT_TRUE(logged) << "no loader log in " << log_dir;
  return found;
}

// clipstream-info's description of a store, less its first line (the path).
std::string describe(const std::string& store) {
  const RunResult r = runInfo({store});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  const size_t eol = r.output.find('\n');
  return eol == std::string::npos ? r.output : r.output.substr(eol + 1);
}

// The bundled DEM as a VRT written by hand: one simple source, with the
// file's size, type, georeference, no-data value and unit.
std::string writeDemVrt(const TempDir& dir) {
  const std::string dem = bundledDataPath("mount_st_helens_30m.tif");
  std::unique_ptr<ImageSource> src;
  EXPECT_TRUE(openImageFile(dem, std::nullopt, &src).ok());
  GeoReference geo;
  EXPECT_TRUE(findGeoReference(dem, &geo).ok());
  if (!src || !geo.present) return {};
  const uint64_t w = src->info().width_px, h = src->info().height_px;
  char transform[256];
  std::snprintf(transform, sizeof transform, "%.17g, %.17g, %.17g, %.17g, %.17g, %.17g", geo.transform[0],
                geo.transform[1], geo.transform[2], geo.transform[3], geo.transform[4], geo.transform[5]);
  const std::string vrt = dir.file("helens.vrt");
  std::ofstream(vrt) << "<VRTDataset rasterXSize=\"" << w << "\" rasterYSize=\"" << h << "\">\n"
                     << "  <SRS>" << geo.crs << "</SRS>\n"
                     << "  <GeoTransform>" << transform << "</GeoTransform>\n"
                     << "  <VRTRasterBand dataType=\"Int16\" band=\"1\">\n"
                     << "    <NoDataValue>-32767</NoDataValue>\n"
                     << "    <UnitType>m</UnitType>\n"
                     << "    <SimpleSource>\n"
                     << "      <SourceFilename relativeToVRT=\"0\">" << fs::absolute(dem).string()
                     << "</SourceFilename>\n"
                     << "      <SourceBand>1</SourceBand>\n"
                     << "    </SimpleSource>\n"
                     << "  </VRTRasterBand>\n"
                     << "</VRTDataset>\n";
  return vrt;
}

TEST(TilerGdal, AVrtTilesLikeItsFile) {
  TempDir dir("gdal");
  const std::string vrt = writeDemVrt(dir);
  ASSERT_FALSE(vrt.empty());
  const RunResult file = runTiler({bundledDataPath("mount_st_helens_30m.tif"), dir.file("file.cst")});
  ASSERT_EQ(file.exit_code, 0) << file.output;
  const RunResult through = runTiler({vrt, dir.file("vrt.cst"), "--json-summary", dir.file("vrt.json")});
  ASSERT_EQ(through.exit_code, 0) << through.output;
  expectSameTiles(dir.file("file.cst"), dir.file("vrt.cst"));
  // Same georeference, CRS, heights, no-data and unit.
  EXPECT_EQ(describe(dir.file("file.cst")), describe(dir.file("vrt.cst")));
  EXPECT_NE(readText(dir.file("vrt.json")).find("\"decoder\": \"gdal VRT\""), std::string::npos)
      << readText(dir.file("vrt.json"));
}

TEST(TilerGdal, AUrlTilesLikeItsFileThroughRangeRequests) {
  TempDir dir("gdal");
  fs::create_directories(dir.file("www"));
  fs::copy_file(bundledDataPath("mount_st_helens_30m.tif"), dir.file("www/helens.tif"));
  std::unique_ptr<NginxServer> server;
  const Status started = NginxServer::start(dir.path().string(), dir.file("www"), &server);
  ASSERT_TRUE(started.ok()) << started.toString();
  const RunResult file = runTiler({dir.file("www/helens.tif"), dir.file("file.cst")});
  ASSERT_EQ(file.exit_code, 0) << file.output;
  const std::string url = server->url("helens.tif");
  const RunResult remote = runTiler({url, dir.file("url.cst"), "--json-summary", dir.file("url.json")});
  ASSERT_EQ(remote.exit_code, 0) << remote.output;
  expectSameTiles(dir.file("file.cst"), dir.file("url.cst"));
  EXPECT_EQ(describe(dir.file("file.cst")), describe(dir.file("url.cst")));
  const std::string summary = readText(dir.file("url.json"));
  EXPECT_NE(summary.find("\"decoder\": \"gdal GTiff\""), std::string::npos) << summary;
  // GDAL read the file in ranges; nothing but the file was asked for.
  const std::vector<LoggedRequest> requests = server->requests(1);
  ASSERT_FALSE(requests.empty());
  size_t ranged = 0;
  for (const LoggedRequest& r : requests) {
    EXPECT_EQ(r.uri, "/helens.tif");
    if (r.status == 206 && !r.range.empty()) ++ranged;
  }
  EXPECT_GT(ranged, 0u);
  // Shards of a colour image's URL (each fingerprints the name, not a
  // file) merge to the local file's store.
  ASSERT_TRUE(writeImage(dir.file("www/colour.tif"), 300, 520, 3, OIIO::TypeDesc::UINT8, pattern));
  const RunResult colour = runTiler({dir.file("www/colour.tif"), dir.file("colour.cst")});
  ASSERT_EQ(colour.exit_code, 0) << colour.output;
  for (const char* shard : {"1/2", "2/2"}) {
    const RunResult part = runTiler({server->url("colour.tif"), dir.file(std::string("part") + shard[0] + ".cst"),
                                     "--shard", shard});
    ASSERT_EQ(part.exit_code, 0) << part.output;
  }
  const RunResult merged = runMerge({dir.file("merged.cst"), dir.file("part1.cst"), dir.file("part2.cst")});
  ASSERT_EQ(merged.exit_code, 0) << merged.output;
  expectSameTiles(dir.file("colour.cst"), dir.file("merged.cst"));
}

TEST(TilerGdal, AFailingServerIsAnErrorNamingTheUrlAndWritesNothing) {
  TempDir dir("gdal");
  fs::create_directories(dir.file("www"));
  fs::create_directories(dir.file("out"));
  std::unique_ptr<NginxServer> server;
  const Status started = NginxServer::start(dir.path().string(), dir.file("www"), &server);
  ASSERT_TRUE(started.ok()) << started.toString();
  // 404, and 503 (nginx's /failing.cstore location).
  for (const std::string& name : {std::string("missing.tif"), std::string("failing.cstore")}) {
    const std::string url = server->url(name);
    const RunResult r = runTiler({url, dir.file("out/x.cst")});
    EXPECT_NE(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find(url + ": cannot open image"), std::string::npos) << r.output;
    EXPECT_TRUE(fs::is_empty(dir.file("out"))) << name;
  }
}

TEST(TilerGdal, JpegTwoThousandGoesToGdalWithTheSamePixels) {
  TempDir dir("gdal");
  const std::string jp2 = dir.file("a.jp2");
  ASSERT_TRUE(writeImage(jp2, 300, 200, 3, OIIO::TypeDesc::UINT8, pattern));
  const RunResult gdal = runTiler({jp2, dir.file("gdal.cst"), "--json-summary", dir.file("gdal.json")});
  ASSERT_EQ(gdal.exit_code, 0) << gdal.output;
  EXPECT_NE(readText(dir.file("gdal.json")).find("\"decoder\": \"gdal JP2OpenJPEG\""), std::string::npos)
      << readText(dir.file("gdal.json"));
  const RunResult oiio = runTiler({jp2, dir.file("oiio.cst"), "--reader", "openimageio"});
  ASSERT_EQ(oiio.exit_code, 0) << oiio.output;
  expectSameTiles(dir.file("oiio.cst"), dir.file("gdal.cst"));
}

// GDAL decodes what the tiler's own readers decode to the same tiles:
// colour (8-bit RGB, tiled and striped) and an int16 DEM.
TEST(TilerGdal, ReaderGdalGivesTheTilesOfTheTilersOwnReaders) {
  TempDir dir("gdal");
  const std::string striped = dir.file("striped.tif"), tiled = dir.file("tiled.tif");
  ASSERT_TRUE(writeImage(striped, 301, 257, 3, OIIO::TypeDesc::UINT8, pattern));
  ASSERT_TRUE(writeImage(tiled, 300, 200, 4, OIIO::TypeDesc::UINT8, pattern, 64));
  for (const std::string& in : {striped, tiled, bundledDataPath("mount_st_helens_30m.tif")}) {
    const std::string name = fs::path(in).stem().string();
    const RunResult own = runTiler({in, dir.file(name + ".own.cst")});
    ASSERT_EQ(own.exit_code, 0) << own.output;
    const RunResult gdal = runTiler({in, dir.file(name + ".gdal.cst"), "--reader", "gdal"});
    ASSERT_EQ(gdal.exit_code, 0) << gdal.output;
    expectSameTiles(dir.file(name + ".own.cst"), dir.file(name + ".gdal.cst"));
    EXPECT_EQ(describe(dir.file(name + ".own.cst")), describe(dir.file(name + ".gdal.cst"))) << name;
  }
}

// Formats the tiler reads itself never load GDAL (nor its ~200
// libraries); an input that needs it does, and GDAL hands over the
// georeference, no-data value and unit it read.
TEST(TilerGdal, GdalIsLoadedOnlyWhenAnInputNeedsIt) {
  TempDir dir("gdal");
  EXPECT_FALSE(tilerLoads(dir, bundledDataPath("mount_st_helens_30m.tif"), "libgdal.so"));
  const std::string vrt = writeDemVrt(dir);
  EXPECT_TRUE(tilerLoads(dir, vrt, "libgdal.so"));
  std::unique_ptr<ImageSource> src;
  const Status s = openImageFile(vrt, std::nullopt, &src);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_EQ(src->info().decoder, "gdal VRT");
  const SourceMetadata& meta = src->info().metadata;
  EXPECT_TRUE(meta.present && meta.geo.present);
  EXPECT_TRUE(meta.has_nodata);
  EXPECT_EQ(meta.nodata, -32767.0);
  EXPECT_EQ(meta.units, HeightUnits::kMetre);
}

// A name that is neither a file nor anything GDAL opens is "no such file",
// as before; a connection string GDAL cannot open is GDAL's error.
TEST(TilerGdal, MissingNamesAreErrorsNamingThem) {
  std::unique_ptr<ImageSource> src;
  const Status missing = openImageFile("/nonexistent/dem.tif", std::nullopt, &src);
  EXPECT_EQ(missing.code, ErrorCode::kNotFound) << missing.toString();
  const Status netcdf = openImageFile("NETCDF:\"/nonexistent/x.nc\":elevation", std::nullopt, &src);
  EXPECT_FALSE(netcdf.ok());
  EXPECT_NE(netcdf.message.find("NETCDF:\"/nonexistent/x.nc\":elevation: cannot open image: GDAL"),
            std::string::npos)
      << netcdf.toString();
}

}  // namespace
}  // namespace clipstream::test
