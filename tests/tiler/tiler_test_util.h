// Helpers shared by the tiler tests: writing test images with OpenImageIO,
// running clipstream-tile, and a reference pyramid computed straight from
// the definitions in docs/tiler.md (not from tiler code). Temporary
// directories and test data come from clipstream_test_support.
//
// Thread rule: plain functions; any thread (the tests call them from the
// test thread only).
#pragma once

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/temp_dir.h>

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <sys/types.h>

namespace clipstream::test {

// An image as plain samples: width * height * channels values, row-major,
// interleaved; values are in the store's sample range (0..255 or 0..65535).
struct RefImage {
  uint64_t width = 0;
  uint64_t height = 0;
  uint32_t channels = 0;
  std::vector<uint32_t> samples;
  uint32_t at(uint64_t x, uint64_t y, uint32_t c) const {
    return samples[(y * width + x) * channels + c];
  }
};

// Next level by the definition: each output pixel is the rounded mean of
// the (up to four) input pixels that exist under it: (s+2)/4, (s+1)/2, s.
RefImage referenceBoxDownsample(const RefImage& in);

// Next level by separable Lanczos-3 at the output scale, in double
// precision, with edge clamp; `linear_light` decodes sRGB first for the
// first three channels.
RefImage referenceLanczosDownsample(const RefImage& in, bool linear_light);

// Writes an image file through OIIO; sample(x, y, c) gives native values.
// tile_px > 0 writes a tiled file (TIFF) with square tiles of that size.
// `configure` may set more of the spec (compression, BigTIFF, ...).
bool writeImage(const std::string& path, uint64_t w, uint64_t h, int channels, OIIO::TypeDesc type,
                const std::function<double(uint64_t, uint64_t, int)>& sample, int tile_px = 0,
                const std::function<void(OIIO::ImageSpec&)>& configure = {});

// Compares every tile of level `level` against `ref`, including padding
// (edge clamp). Returns the largest absolute sample difference.
uint32_t maxTileError(const TileStoreReader& reader, uint32_t level, const RefImage& ref);

// A shell command's exit status, its output discarded (the reference files
// come from GDAL's own programs), and a path quoted for it.
int shell(const std::string& command);
std::string shellQuoted(const std::string& s);

struct RunResult {
  int exit_code = -1;
  std::string output;  // stdout + stderr
};
// Runs clipstream-tile with `args` (shell-quoted here), capturing output;
// `stdout_redirect` (e.g. ">/dev/full") redirects standard output alone.
RunResult runTiler(const std::vector<std::string>& args, const std::string& stdout_redirect = "");

// Runs clipstream-merge the same way.
RunResult runMerge(const std::vector<std::string>& args);

// Runs clipstream-info the same way.
RunResult runInfo(const std::vector<std::string>& args, const std::string& stdout_redirect = "");

// Every tile of the store at `actual_path` equals the one at `expected_path`
// (same geometry; same constant value, or same checksum and payload bytes;
// same height bounds and error in an elevation store).
void expectSameTiles(const std::string& expected_path, const std::string& actual_path);

// Starts clipstream-tile with `args` in a child with its output discarded
// and a 120 s alarm (a hang fails the test); returns the pid, or -1.
pid_t spawnTiler(const std::vector<std::string>& args);

// Reads a whole image via OIIO as 8-bit samples.
bool readImage8(const std::string& path, RefImage* out);

}  // namespace clipstream::test
