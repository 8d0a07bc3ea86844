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

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
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

// Side-car files GDAL would write beside its inputs (.aux.xml), anywhere
// under `dir`: reading an input must write nothing beside it.
std::vector<std::string> sidecars(const TempDir& dir) {
  std::vector<std::string> found;
  for (const auto& e : fs::recursive_directory_iterator(dir.path())) {
    if (e.path().string().ends_with(".aux.xml")) found.push_back(e.path().string());
  }
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
      << readText(dir.file("vrt.json"));  EXPECT_TRUE(sidecars(dir).empty()) << sidecars(dir).front();
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
  expectSameTiles(dir.file("oiio.cst"), dir.file("gdal.cst"));  EXPECT_TRUE(sidecars(dir).empty()) << sidecars(dir).front();
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
  }  EXPECT_TRUE(sidecars(dir).empty()) << sidecars(dir).front();
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

// A format neither our readers nor OpenImageIO open (NetCDF) goes to
// GDAL, as a file or by its driver's connection string, and tiles like the
// GeoTIFF it was made from (same heights and georeference).
TEST(TilerGdal, ANetCdfFileAndItsConnectionStringTileLikeTheirGeoTiff) {
  TempDir dir("gdal");
  const std::string nc = dir.file("dem.nc");
  ASSERT_EQ(shell("gdal_translate -q -of netCDF " + shellQuoted(bundledDataPath("mount_st_helens_30m.tif")) + " " +
                  shellQuoted(nc)),
            0);
  const RunResult tiff = runTiler({bundledDataPath("mount_st_helens_30m.tif"), dir.file("tiff.cst")});
  ASSERT_EQ(tiff.exit_code, 0) << tiff.output;
  const RunResult file = runTiler({nc, dir.file("nc.cst"), "--json-summary", dir.file("nc.json")});
  ASSERT_EQ(file.exit_code, 0) << file.output;
  EXPECT_NE(readText(dir.file("nc.json")).find("\"decoder\": \"gdal netCDF\""), std::string::npos);
  const RunResult named = runTiler({"NETCDF:\"" + nc + "\":Band1", dir.file("named.cst")});
  ASSERT_EQ(named.exit_code, 0) << named.output;
  expectSameTiles(dir.file("tiff.cst"), dir.file("nc.cst"));
  expectSameTiles(dir.file("tiff.cst"), dir.file("named.cst"));
  const RunResult info = runInfo({dir.file("nc.cst")});
  EXPECT_NE(info.output.find("CRS          EPSG:26710"), std::string::npos) << info.output;  EXPECT_TRUE(sidecars(dir).empty()) << sidecars(dir).front();
}

// A NetCDF file of two variables (made by gdalmdimtranslate from a
// multidimensional VRT over the DEM) is refused naming both as the inputs
// to give instead; each opens by its name.
TEST(TilerGdal, AContainerOfSeveralRastersNamesThem) {
  TempDir dir("gdal");
  std::unique_ptr<ImageSource> dem;
  ASSERT_TRUE(openImageFile(bundledDataPath("mount_st_helens_30m.tif"), std::nullopt, &dem).ok());
  const uint64_t w = dem->info().width_px, h = dem->info().height_px;
  std::ofstream vrt(dir.file("two.vrt"));
  vrt << "<VRTDataset><Group name=\"/\"><Dimension name=\"y\" size=\"" << h << "\"/><Dimension name=\"x\" size=\""
      << w << "\"/>";
  for (const char* name : {"first", "second"}) {
    vrt << "<Array name=\"" << name << "\"><DataType>Int16</DataType><DimensionRef ref=\"y\"/>"
        << "<DimensionRef ref=\"x\"/><Source><SourceFilename>"
        << fs::absolute(bundledDataPath("mount_st_helens_30m.tif")).string()
        << "</SourceFilename><SourceBand>1</SourceBand></Source></Array>";
  }
  vrt << "</Group></VRTDataset>\n";
  vrt.close();
  const std::string nc = dir.file("two.nc");
  ASSERT_EQ(shell("gdalmdimtranslate " + shellQuoted(dir.file("two.vrt")) + " " + shellQuoted(nc)), 0);
  const RunResult whole = runTiler({nc, dir.file("whole.cst")});
  EXPECT_NE(whole.exit_code, 0);
  EXPECT_NE(whole.output.find(nc + ": holds several rasters; name one as the input: NETCDF:\"" + nc +
                              "\":first, NETCDF:\"" + nc + "\":second"),
            std::string::npos)
      << whole.output;
  EXPECT_FALSE(fs::exists(dir.file("whole.cst")));
  std::unique_ptr<ImageSource> second;
  const Status s = openImageFile("NETCDF:\"" + nc + "\":second", std::nullopt, &second);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_EQ(second->info().decoder, "gdal netCDF");
  EXPECT_EQ(second->info().width_px, w);
  EXPECT_EQ(second->info().height_px, h);
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

namespace clipstream::test {
namespace {


// Level 0 of a store, row-major, in its pixel format.
std::vector<uint8_t> level0(const std::string& store, PyramidGeometry* geometry, GeoReference* geo) {
  std::unique_ptr<TileStoreReader> r;
  EXPECT_TRUE(TileStoreReader::open(store, &r).ok()) << store;
  if (!r) return {};
  *geometry = r->geometry();
  *geo = r->info().geo;
  const uint32_t bpp = bytesPerPixel(geometry->format), t = geometry->tile_px;
  std::vector<uint8_t> out(geometry->width_px * geometry->height_px * bpp);
  std::vector<uint8_t> tile;
  for (uint32_t ty = 0; ty < geometry->levels[0].tiles_y; ++ty) {
    for (uint32_t tx = 0; tx < geometry->levels[0].tiles_x; ++tx) {
      EXPECT_TRUE(r->readTile({0, tx, ty}, &tile).ok());
      for (uint32_t y = 0; y < t && uint64_t(ty) * t + y < geometry->height_px; ++y) {
        const uint64_t w = std::min<uint64_t>(t, geometry->width_px - uint64_t(tx) * t);
        std::memcpy(out.data() + ((uint64_t(ty) * t + y) * geometry->width_px + uint64_t(tx) * t) * bpp,
                    tile.data() + size_t(y) * t * bpp, w * bpp);
      }
    }
  }
  return out;
}

// A whole image through the tiler's own reader, in `format`.
std::vector<uint8_t> wholeImage(const std::string& path, PixelFormat format, uint64_t* w, uint64_t* h) {
  std::unique_ptr<ImageSource> src;
  const Status s = openImageFile(path, format, &src);
  EXPECT_TRUE(s.ok()) << s.toString();
  if (!s) return {};
  *w = src->info().width_px, *h = src->info().height_px;
  const size_t row = *w * bytesPerPixel(format);
  std::vector<uint8_t> out(row * *h);
  EXPECT_TRUE(src->readRows(0, uint32_t(*h), 0, *w, out.data(), row).ok());
  return out;
}

// The bundled DEM (UTM 10N, NAD27) warped to geographic coordinates by
// gdalwarp: a DEM as SRTM tiles come.
std::string geographicDem(const TempDir& dir) {
  const std::string out = dir.file("dem4326.tif");
  EXPECT_EQ(shell("gdalwarp -q -t_srs EPSG:4326 -r bilinear " +
                  shellQuoted(bundledDataPath("mount_st_helens_30m.tif")) + " " + shellQuoted(out)),
            0)
      << "gdalwarp (Debian's gdal-bin, scripts/deps.sh) failed";
  return out;
}

// A geographic DEM tiled with --t-srs into the UTM texture's CRS lands on
// gdalwarp's grid with gdalwarp's heights: the same warper, run block by
// block.
TEST(TilerWarp, AGeographicDemReprojectedMatchesGdalwarp) {
  TempDir dir("warp");
  const std::string dem = geographicDem(dir);
  const RunResult r = runTiler({dem, dir.file("utm.cst"), "--t-srs", "EPSG:26710", "--json-summary",
                                dir.file("utm.json")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("reprojected: EPSG:4326 (WGS 84) -> EPSG:26710 (NAD27 / UTM zone 10N), bilinear"),
            std::string::npos)
      << r.output;
  const std::string ref = dir.file("ref.tif");
  ASSERT_EQ(shell("gdalwarp -q -t_srs EPSG:26710 -r bilinear " + shellQuoted(dem) + " " + shellQuoted(ref)), 0);

  PyramidGeometry g;
  GeoReference geo, ref_geo;
  const std::vector<uint8_t> ours = level0(dir.file("utm.cst"), &g, &geo);
  ASSERT_TRUE(findGeoReference(ref, &ref_geo).ok());
  uint64_t w = 0, h = 0;
  const std::vector<uint8_t> theirs = wholeImage(ref, PixelFormat::kI16, &w, &h);
  ASSERT_EQ(g.width_px, w);
  ASSERT_EQ(g.height_px, h);
  ASSERT_EQ(g.format, PixelFormat::kI16);
  EXPECT_EQ(geo.crs, "EPSG:26710");
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(geo.transform[i], ref_geo.transform[i], 1e-6 * 30.0) << i;
  // Every sample gdalwarp gives a height equals ours (the no-data collar
  // is filled in the store, as any void).
  uint64_t compared = 0, differ = 0;
  for (size_t i = 0; i < w * h; ++i) {
    int16_t a, b;
    std::memcpy(&a, ours.data() + 2 * i, 2);
    std::memcpy(&b, theirs.data() + 2 * i, 2);
    if (b == -32767) continue;
    ++compared;
    differ += a != b;
  }
  EXPECT_GT(compared, w * h / 2);
  EXPECT_EQ(differ, 0u) << "of " << compared;
  EXPECT_TRUE(sidecars(dir).empty()) << sidecars(dir).front();
}

// --t-srs FILE: the input goes onto the CRS of another raster (a texture
// onto its DEM's), the same grid gdalwarp makes with that CRS; a file GDAL
// cannot read is an error naming it.
TEST(TilerWarp, ARasterFileGivesItsCoordinateSystem) {
  TempDir dir("warp");
  const std::string dem = bundledDataPath("mount_st_helens_30m.tif");
  ASSERT_TRUE(writeImage(dir.file("rgb.tif"), 240, 200, 3, OIIO::TypeDesc::UINT8, pattern));
  const std::string rgb = dir.file("rgb4326.tif");
  ASSERT_EQ(shell("gdal_translate -q -a_srs EPSG:4326 -a_ullr -122.30 46.30 -122.10 46.12 " +
                  shellQuoted(dir.file("rgb.tif")) + " " + shellQuoted(rgb)),
            0);
  const RunResult r = runTiler({rgb, dir.file("onto_dem.cst"), "--t-srs", dem});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  GeoReference dem_geo, geo;
  ASSERT_TRUE(findGeoReference(dem, &dem_geo).ok());
  PyramidGeometry g;
  (void)level0(dir.file("onto_dem.cst"), &g, &geo);
  ASSERT_FALSE(dem_geo.crs.empty());
  EXPECT_EQ(geo.crs, dem_geo.crs);
  const std::string ref = dir.file("ref.tif");
  ASSERT_EQ(shell("gdalwarp -q -dstalpha -t_srs " + dem_geo.crs + " " + shellQuoted(rgb) + " " + shellQuoted(ref)), 0);
  GeoReference ref_geo;
  ASSERT_TRUE(findGeoReference(ref, &ref_geo).ok());
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(geo.transform[i], ref_geo.transform[i], 1e-6 * 30.0) << i;

  const std::string text = dir.file("not_a_raster.txt");
  std::ofstream(text) << "EPSG but not quite\n";
  const RunResult bad = runTiler({rgb, dir.file("bad.cst"), "--t-srs", text});
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("not a raster GDAL reads"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(dir.file("bad.cst")));
}

// --t-srs auto: a geographic input goes to the WGS 84 UTM zone of its
// centre, said in the summary; a colour image gains an alpha band that is
// transparent where no input pixel lands, as gdalwarp -dstalpha draws it.
TEST(TilerWarp, AutoPicksTheUtmZoneAndTheCollarIsTransparent) {
  TempDir dir("warp");
  const std::string dem = geographicDem(dir);
  const RunResult r = runTiler({dem, dir.file("auto.cst"), "--t-srs", "auto", "--json-summary",
                                dir.file("auto.json")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(readText(dir.file("auto.json")).find("EPSG:32610 (WGS 84 / UTM zone 10N)"), std::string::npos)
      << readText(dir.file("auto.json"));

  // A colour image placed in geographic coordinates, reprojected.
  ASSERT_TRUE(writeImage(dir.file("rgb.tif"), 240, 200, 3, OIIO::TypeDesc::UINT8, pattern));
  const std::string rgb = dir.file("rgb4326.tif");
  ASSERT_EQ(shell("gdal_translate -q -a_srs EPSG:4326 -a_ullr -122.30 46.30 -122.10 46.12 " +
                  shellQuoted(dir.file("rgb.tif")) + " " + shellQuoted(rgb)),
            0);
  const RunResult c = runTiler({rgb, dir.file("rgb.cst"), "--t-srs", "auto"});
  ASSERT_EQ(c.exit_code, 0) << c.output;
  const std::string ref = dir.file("rgb_ref.tif");
  ASSERT_EQ(shell("gdalwarp -q -t_srs EPSG:32610 -r bilinear -dstalpha " + shellQuoted(rgb) + " " + shellQuoted(ref)), 0);
  PyramidGeometry g;
  GeoReference geo;
  const std::vector<uint8_t> ours = level0(dir.file("rgb.cst"), &g, &geo);
  uint64_t w = 0, h = 0;
  std::vector<uint8_t> theirs = wholeImage(ref, PixelFormat::kRGBA8, &w, &h);
  ASSERT_EQ(g.format, PixelFormat::kRGBA8);
  ASSERT_EQ(g.width_px, w);
  ASSERT_EQ(g.height_px, h);
  // gdalwarp's alpha is straight, the store's colour premultiplied by it
  // (the same where alpha is 0 or 255, as it is everywhere here).
  for (size_t i = 0; i < theirs.size(); i += 4) {
    for (int k = 0; k < 3; ++k) theirs[i + k] = uint8_t((theirs[i + k] * uint32_t(theirs[i + 3]) + 127) / 255);
  }
  EXPECT_TRUE(ours == theirs);
  uint64_t transparent = 0;
  for (size_t i = 3; i < ours.size(); i += 4) transparent += ours[i] == 0;
  EXPECT_GT(transparent, 0u) << "a rotated footprint leaves corners no input pixel reaches";
}

// --t-srs auto in the corners of the world: longitudes given as 0..360
// (190 E is 170 W: zone 2), an input already in the target (kept, said),
// one too wide for a zone (refused).
TEST(TilerWarp, AutoFindsTheZoneOfLongitudesPast180AndRefusesTooWide) {
  TempDir dir("warp");
  ASSERT_TRUE(writeImage(dir.file("rgb.tif"), 120, 100, 3, OIIO::TypeDesc::UINT8, pattern));
  auto placed = [&](const std::string& name, const std::string& ullr) {
    const std::string out = dir.file(name);
    EXPECT_EQ(shell("gdal_translate -q -a_srs EPSG:4326 -a_ullr " + ullr + " " + shellQuoted(dir.file("rgb.tif")) + " " +
                    shellQuoted(out)),
              0);
    return out;
  };
  const RunResult east = runTiler({placed("east.tif", "190 10 191 9"), dir.file("east.cst"), "--t-srs", "auto"});
  ASSERT_EQ(east.exit_code, 0) << east.output;
  EXPECT_NE(east.output.find("EPSG:32602 (WGS 84 / UTM zone 2N)"), std::string::npos) << east.output;
  const RunResult kept = runTiler({placed("kept.tif", "10 10 11 9"), dir.file("kept.cst"), "--t-srs", "EPSG:4326"});
  ASSERT_EQ(kept.exit_code, 0) << kept.output;
  EXPECT_NE(kept.output.find("kept (the input is in it already)"), std::string::npos) << kept.output;
  const RunResult wide = runTiler({placed("wide.tif", "-180 60 180 -60"), dir.file("wide.cst"), "--t-srs", "auto"});
  EXPECT_NE(wide.exit_code, 0);
  EXPECT_NE(wide.output.find("spans 360.0 degrees of longitude"), std::string::npos) << wide.output;
}

TEST(TilerWarp, WhatCannotBeReprojectedIsAnErrorNamingItWithNothingWritten) {
  TempDir dir("warp");
  fs::create_directories(dir.file("out"));
  const std::string out = dir.file("out/x.cst");
  // The bundled photo has a world file but no CRS.
  RunResult r = runTiler({bundledDataPath("autzen.jpg"), out, "--t-srs", "EPSG:32610"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("autzen.jpg: has no coordinate system to reproject from"), std::string::npos)
      << r.output;
  r = runTiler({bundledDataPath("mount_st_helens_30m.tif"), out, "--t-srs", "EPSG:99999999"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--t-srs 'EPSG:99999999' is not a coordinate system GDAL knows"), std::string::npos)
      << r.output;
  r = runTiler({bundledDataPath("mount_st_helens_30m.tif"), out, "--t-srs", "auto", "--resampling", "sharp"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--resampling 'sharp' is not"), std::string::npos) << r.output;
  // Refused after the warp was made (five bands): the warp and the file are closed in order.
  ASSERT_TRUE(writeImage(dir.file("rgb.tif"), 40, 30, 3, OIIO::TypeDesc::UINT8, pattern));
  ASSERT_EQ(shell("gdal_translate -q -a_srs EPSG:4326 -a_ullr 10 10 11 9 -b 1 -b 2 -b 3 -b 1 -b 2 " +
                  shellQuoted(dir.file("rgb.tif")) + " " + shellQuoted(dir.file("five.tif"))),
            0);
  r = runTiler({dir.file("five.tif"), out, "--t-srs", "auto"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("5 bands; only 1 (grey)"), std::string::npos) << r.output;
  r = runTiler({bundledDataPath("mount_st_helens_30m.tif"), out, "--t-res", "10"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--t-res needs --t-srs"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::is_empty(dir.file("out")));
}

}  // namespace
}  // namespace clipstream::test

namespace clipstream::test {
namespace {

// A colour image's no-data (--nodata, or the GDAL tag the file carries)
// becomes alpha 0 over black; other pixels are opaque and keep their
// colour, whichever reader decodes the file; a format forced without alpha
// keeps the pixels opaque.
TEST(TilerNoData, AColourNoDataCollarIsTransparent) {
  TempDir dir("nodata");
  auto collared = [](uint64_t x, uint64_t y, int c) {
    return x < 20 || y >= 140 ? 0.0 : std::fmod(pattern(x, y, c), 255.0) + 1.0;  // 1..255
  };
  const std::string plain = dir.file("plain.tif"), tagged = dir.file("tagged.tif");
  ASSERT_TRUE(writeImage(plain, 200, 150, 3, OIIO::TypeDesc::UINT8, collared));
  ASSERT_EQ(shell("gdal_translate -q -a_nodata 0 " + shellQuoted(plain) + " " + shellQuoted(tagged)), 0);
  const RunResult given = runTiler({plain, dir.file("given.cst"), "--nodata", "0"});
  ASSERT_EQ(given.exit_code, 0) << given.output;
  EXPECT_NE(given.output.find("no-data: pixels whose every channel is 0 are transparent"), std::string::npos)
      << given.output;
  const RunResult tag = runTiler({tagged, dir.file("tag.cst")});
  ASSERT_EQ(tag.exit_code, 0) << tag.output;
  const RunResult gdal = runTiler({tagged, dir.file("gdal.cst"), "--reader", "gdal"});
  ASSERT_EQ(gdal.exit_code, 0) << gdal.output;
  expectSameTiles(dir.file("given.cst"), dir.file("tag.cst"));
  expectSameTiles(dir.file("given.cst"), dir.file("gdal.cst"));

  PyramidGeometry g;
  GeoReference geo;
  const std::vector<uint8_t> px = level0(dir.file("given.cst"), &g, &geo);
  ASSERT_EQ(g.format, PixelFormat::kRGBA8);
  for (uint64_t y = 0; y < 150; ++y) {
    for (uint64_t x = 0; x < 200; ++x) {
      const uint8_t* p = px.data() + (y * 200 + x) * 4;
      const bool empty = x < 20 || y >= 140;
      if (empty) {
        ASSERT_EQ(p[0] + p[1] + p[2] + p[3], 0) << x << "," << y;
      } else {
        ASSERT_EQ(p[3], 255) << x << "," << y;
        ASSERT_EQ(p[0], uint8_t(collared(x, y, 0))) << x << "," << y;
      }
    }
  }
  // Forced to RGB8: opaque, as asked.
  const RunResult forced = runTiler({tagged, dir.file("rgb.cst"), "--format", "RGB8"});
  ASSERT_EQ(forced.exit_code, 0) << forced.output;
  EXPECT_EQ(forced.output.find("transparent"), std::string::npos) << forced.output;
  // Forced to RGBA8: transparent as by default.
  const RunResult rgba = runTiler({tagged, dir.file("rgba.cst"), "--format", "RGBA8"});
  ASSERT_EQ(rgba.exit_code, 0) << rgba.output;
  expectSameTiles(dir.file("given.cst"), dir.file("rgba.cst"));
  // Grey: (v, v, v, 255), or all 0 where v is the no-data value.
  ASSERT_TRUE(writeImage(dir.file("grey.tif"), 60, 40, 1, OIIO::TypeDesc::UINT8, collared));
  const RunResult grey = runTiler({dir.file("grey.tif"), dir.file("grey.cst"), "--nodata", "0"});
  ASSERT_EQ(grey.exit_code, 0) << grey.output;
  const std::vector<uint8_t> gp = level0(dir.file("grey.cst"), &g, &geo);
  ASSERT_EQ(g.format, PixelFormat::kRGBA8);
  for (uint64_t y = 0; y < 40; ++y)
    for (uint64_t x = 0; x < 60; ++x) {
      const uint8_t* p = gp.data() + (y * 60 + x) * 4;
      const uint8_t v = uint8_t(collared(x, y, 0));
      ASSERT_EQ(p[3], v == 0 ? 0 : 255) << x << "," << y;
      ASSERT_TRUE(p[0] == v && p[1] == v && p[2] == v) << x << "," << y;
    }
  // 16-bit colour: stays opaque, and says so.
  ASSERT_TRUE(writeImage(dir.file("wide.tif"), 60, 40, 3, OIIO::TypeDesc::UINT16, collared));
  const RunResult wide = runTiler({dir.file("wide.tif"), dir.file("wide.cst"), "--nodata", "0"});
  ASSERT_EQ(wide.exit_code, 0) << wide.output;
  EXPECT_NE(wide.output.find("no-data value 0 stays opaque"), std::string::npos) << wide.output;
}

}  // namespace
}  // namespace clipstream::test
