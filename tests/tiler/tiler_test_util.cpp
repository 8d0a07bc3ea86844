#include "tiler_test_util.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <numbers>
#include <random>
#include <sys/wait.h>

namespace clipstream::test {

RefImage referenceBoxDownsample(const RefImage& in) {
  RefImage out;
  out.width = (in.width + 1) / 2;
  out.height = (in.height + 1) / 2;
  out.channels = in.channels;
  out.samples.resize(out.width * out.height * out.channels);
  for (uint64_t y = 0; y < out.height; ++y) {
    for (uint64_t x = 0; x < out.width; ++x) {
      for (uint32_t c = 0; c < in.channels; ++c) {
        uint64_t sum = 0, n = 0;
        for (uint64_t dy = 0; dy < 2; ++dy) {
          for (uint64_t dx = 0; dx < 2; ++dx) {
            const uint64_t sx = 2 * x + dx, sy = 2 * y + dy;
            if (sx < in.width && sy < in.height) {
              sum += in.at(sx, sy, c);
              ++n;
            }
          }
        }
        out.samples[(y * out.width + x) * out.channels + c] = uint32_t((sum + n / 2) / n);
      }
    }
  }
  return out;
}

namespace {
double lanczos3(double d) {
  auto sinc = [](double x) {
    if (x == 0.0) return 1.0;
    return std::sin(std::numbers::pi * x) / (std::numbers::pi * x);
  };
  return std::abs(d) < 3.0 ? sinc(d) * sinc(d / 3.0) : 0.0;
}
double toLinear(double e) { return e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4); }
double toSrgb(double l) {
  l = std::clamp(l, 0.0, 1.0);
  return l <= 0.0031308 ? l * 12.92 : 1.055 * std::pow(l, 1.0 / 2.4) - 0.055;
}
}  // namespace

RefImage referenceLanczosDownsample(const RefImage& in, bool linear_light) {
  const uint64_t ow = (in.width + 1) / 2, oh = (in.height + 1) / 2;
  const uint32_t nc = in.channels;
  auto value = [&](int64_t x, int64_t y, uint32_t c) {
    x = std::clamp<int64_t>(x, 0, int64_t(in.width) - 1);
    y = std::clamp<int64_t>(y, 0, int64_t(in.height) - 1);
    const double v = in.at(uint64_t(x), uint64_t(y), c) / 255.0;
    return (linear_light && c < 3) ? toLinear(v) : v;
  };
  RefImage out;
  out.width = ow, out.height = oh, out.channels = nc;
  out.samples.resize(ow * oh * nc);
  for (uint64_t y = 0; y < oh; ++y) {
    for (uint64_t x = 0; x < ow; ++x) {
      for (uint32_t c = 0; c < nc; ++c) {
        // Output centre (x + 0.5) * 2 in input pixels; weights over input
        // centres within 6 input pixels, normalised.
        double acc = 0.0, wsum = 0.0;
        for (int64_t j = int64_t(2 * y) - 6; j <= int64_t(2 * y) + 7; ++j) {
          const double wy = lanczos3((j + 0.5 - (2.0 * y + 1.0)) / 2.0);
          for (int64_t i = int64_t(2 * x) - 6; i <= int64_t(2 * x) + 7; ++i) {
            const double wx = lanczos3((i + 0.5 - (2.0 * x + 1.0)) / 2.0);
            acc += wx * wy * value(i, j, c);
            wsum += wx * wy;
          }
        }
        double v = acc / wsum;
        if (linear_light && c < 3) v = toSrgb(v);
        out.samples[(y * ow + x) * nc + c] = uint32_t(std::clamp(std::lround(v * 255.0), 0L, 255L));
      }
    }
  }
  return out;
}

bool writeImage(const std::string& path, uint64_t w, uint64_t h, int channels, OIIO::TypeDesc type,
                const std::function<double(uint64_t, uint64_t, int)>& sample, int tile_px,
                const std::function<void(OIIO::ImageSpec&)>& configure) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) return false;
  OIIO::ImageSpec spec(int(w), int(h), channels, type);
  spec.attribute("oiio:UnassociatedAlpha", 1);  // store samples as given, no premultiply
  if (tile_px > 0) {
    spec.tile_width = tile_px;
    spec.tile_height = tile_px;
  }
  if (configure) configure(spec);
  if (!out->open(path, spec)) return false;
  // The whole image in native samples: test images are small.
  std::vector<uint8_t> native(w * h * channels * type.size());
  for (uint64_t y = 0; y < h; ++y) {
    for (uint64_t x = 0; x < w; ++x) {
      for (int c = 0; c < channels; ++c) {
        const double v = sample(x, y, c);
        uint8_t* p = native.data() + ((y * w + x) * channels + c) * type.size();
        if (type == OIIO::TypeDesc::UINT8) {
          *p = uint8_t(v);
        } else if (type == OIIO::TypeDesc::UINT16) {
          const uint16_t s = uint16_t(v);
          std::memcpy(p, &s, 2);
        } else if (type == OIIO::TypeDesc::INT16) {
          const int16_t s = int16_t(v);
          std::memcpy(p, &s, 2);
        } else if (type == OIIO::TypeDesc::FLOAT) {
          const float f = float(v);
          std::memcpy(p, &f, 4);
        } else if (type == OIIO::TypeDesc::DOUBLE) {
          std::memcpy(p, &v, 8);
        } else if (type == OIIO::TypeDesc::UINT32) {
          const uint32_t s = uint32_t(v);
          std::memcpy(p, &s, 4);
        } else {
          return false;
        }
      }
    }
  }
  if (!out->write_image(type, native.data())) return false;
  return out->close();
}

uint32_t maxTileError(const TileStoreReader& reader, uint32_t level, const RefImage& ref) {
  const PyramidGeometry& g = reader.geometry();
  const LevelInfo& info = g.levels.at(level);
  EXPECT_EQ(info.width_px, ref.width);
  EXPECT_EQ(info.height_px, ref.height);
  const uint32_t t = g.tile_px;
  const uint32_t nc = channelCount(g.format);
  const bool is16 = g.format == PixelFormat::kR16;
  uint32_t worst = 0;
  std::vector<uint8_t> px;
  for (uint32_t ty = 0; ty < info.tiles_y; ++ty) {
    for (uint32_t tx = 0; tx < info.tiles_x; ++tx) {
      const Status s = reader.readTile({level, tx, ty}, &px);
      EXPECT_TRUE(s.ok()) << s.toString();
      if (!s) return UINT32_MAX;
      for (uint32_t y = 0; y < t; ++y) {
        for (uint32_t x = 0; x < t; ++x) {
          const uint64_t gx = std::min<uint64_t>(uint64_t(tx) * t + x, ref.width - 1);
          const uint64_t gy = std::min<uint64_t>(uint64_t(ty) * t + y, ref.height - 1);
          for (uint32_t c = 0; c < nc; ++c) {
            const size_t i = (size_t(y) * t + x) * nc + c;
            const uint32_t got = is16 ? uint32_t(px[2 * i] | (px[2 * i + 1] << 8)) : px[i];
            const uint32_t want = ref.at(gx, gy, c);
            worst = std::max(worst, got > want ? got - want : want - got);
          }
        }
      }
    }
  }
  return worst;
}

namespace {

RunResult runProgram(const char* exe, const std::vector<std::string>& args,
                     const std::string& stdout_redirect) {
  std::string cmd = std::string("'") + exe + "'";
  for (const std::string& a : args) {
    std::string q = "'";
    for (char c : a) q += (c == '\'') ? std::string("'\\''") : std::string(1, c);
    cmd += " " + q + "'";
  }
  cmd = stdout_redirect.empty() ? cmd + " 2>&1" : "{ " + cmd + " " + stdout_redirect + "; } 2>&1";
  RunResult r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (pipe == nullptr) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), pipe)) > 0) r.output.append(buf, n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

}  // namespace

RunResult runTiler(const std::vector<std::string>& args, const std::string& stdout_redirect) {
  return runProgram(CLIPSTREAM_TILE_EXE, args, stdout_redirect);
}

RunResult runMerge(const std::vector<std::string>& args) {
  return runProgram(CLIPSTREAM_MERGE_EXE, args, "");
}

RunResult runInfo(const std::vector<std::string>& args, const std::string& stdout_redirect) {
  return runProgram(CLIPSTREAM_INFO_EXE, args, stdout_redirect);
}

void expectSameTiles(const std::string& expected_path, const std::string& actual_path) {
  std::unique_ptr<TileStoreReader> a, b;
  ASSERT_TRUE(TileStoreReader::open(expected_path, &a).ok()) << expected_path;
  ASSERT_TRUE(TileStoreReader::open(actual_path, &b).ok()) << actual_path;
  const PyramidGeometry& ga = a->geometry();
  const PyramidGeometry& gb = b->geometry();
  ASSERT_EQ(ga.width_px, gb.width_px);
  ASSERT_EQ(ga.height_px, gb.height_px);
  ASSERT_EQ(ga.tile_px, gb.tile_px);
  ASSERT_EQ(ga.format, gb.format);
  ASSERT_EQ(ga.levelCount(), gb.levelCount());
  uint64_t differing = 0;
  for (uint32_t l = 0; l < ga.levelCount(); ++l) {
    for (uint32_t y = 0; y < ga.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < ga.levels[l].tiles_x; ++x) {
        RawTile ra, rb;
        ASSERT_TRUE(a->readRaw({l, x, y}, &ra).ok());
        ASSERT_TRUE(b->readRaw({l, x, y}, &rb).ok());
        const bool same =
            ra.location.constant == rb.location.constant &&
            std::memcmp(ra.location.constant_pixel, rb.location.constant_pixel, 8) == 0 &&
            ra.location.checksum == rb.location.checksum && ra.payload == rb.payload &&
            ra.location.min_height == rb.location.min_height &&
            ra.location.max_height == rb.location.max_height &&
            ra.location.error == rb.location.error;
        if (!same && differing++ < 5) {
          ADD_FAILURE() << actual_path << ": level " << l << " tile (" << x << ", " << y
                        << ") differs from " << expected_path;
        }
      }
    }
  }
  EXPECT_EQ(differing, 0u);
}

pid_t spawnTiler(const std::vector<std::string>& args) {
  std::vector<char*> argv = {const_cast<char*>(CLIPSTREAM_TILE_EXE)};
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    const int devnull = open("/dev/null", O_WRONLY);
    dup2(devnull, 1);
    dup2(devnull, 2);
    alarm(120);
    execv(CLIPSTREAM_TILE_EXE, argv.data());
    _exit(127);
  }
  return pid;
}

bool readImage8(const std::string& path, RefImage* out) {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) return false;
  const OIIO::ImageSpec& spec = in->spec();
  out->width = uint64_t(spec.width);
  out->height = uint64_t(spec.height);
  out->channels = uint32_t(spec.nchannels);
  std::vector<uint8_t> px(out->width * out->height * out->channels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, px.data())) return false;
  out->samples.assign(px.begin(), px.end());
  return true;
}

int shell(const std::string& command) { return std::system((command + " >/dev/null 2>&1").c_str()); }

std::string shellQuoted(const std::string& s) { return "'" + s + "'"; }

}  // namespace clipstream::test
