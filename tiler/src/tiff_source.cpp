// TIFF and BigTIFF through libtiff (native_source.h): the strips or tiles
// under each read are decoded by several threads at once, each with its own
// handle on the file (a libtiff handle is one thread's), into a band kept
// for the next read, since the tiler's strips are seldom the file's.
#include "native_source.h"
#include "pixel_convert.h"

#include <tiffio.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <mutex>
#include <new>
#include <system_error>
#include <thread>
#include <vector>

namespace clipstream {
namespace {

using namespace pixel_convert;
namespace fs = std::filesystem;

// A strip that decodes to more than this (a file written as one huge
// compressed strip) is read a scanline at a time on one thread instead of
// being held whole; tiles larger than this are left to OpenImageIO.
constexpr size_t kMaxChunkBytes = size_t(64) << 20;
// libtiff refuses any single allocation above this, so a damaged header
// asking for terabytes fails with a message instead of exhausting memory.
constexpr tmsize_t kMaxTiffAllocBytes = tmsize_t(1) << 30;
// More decode threads than this gain nothing on one file's bands.
constexpr unsigned kMaxDecodeThreads = 16;

// One libtiff handle and the errors and warnings it reported since they
// were last taken.
struct Handle {
  TIFF* tiff = nullptr;
  std::string messages;
  std::string warnings;
  ~Handle() {
    if (tiff != nullptr) TIFFClose(tiff);
  }
};

int onTiffError(TIFF*, void* user, const char* module, const char* fmt, va_list ap) {
  auto* h = static_cast<Handle*>(user);
  char text[512];
  std::vsnprintf(text, sizeof text, fmt, ap);
  if (!h->messages.empty()) h->messages += '\n';
  if (module != nullptr && *module) h->messages += std::string(module) + ": ";
  h->messages += text;
  return 1;  // handled: nothing reaches libtiff's default (stderr)
}

// Warnings are kept, but for tags libtiff does not know (GDAL's metadata,
// GeoTIFF keys), which are not the user's concern. What a kept warning
// means is decided where it is raised: about the file's layout at open
// (strip or tile offsets and byte counts ignored or recomputed: libtiff
// would read zeros where the data should be), the file is refused; during
// a decode, the chunk is (a decoder that ran out of data fills the rest);
// any other at open goes into the run's warnings.
int onTiffWarning(TIFF*, void* user, const char* module, const char* fmt, va_list ap) {
  auto* h = static_cast<Handle*>(user);
  char text[512];
  std::vsnprintf(text, sizeof text, fmt, ap);
  if (std::strstr(text, "Unknown field with tag") != nullptr) return 1;
  if (!h->warnings.empty()) h->warnings += '\n';
  if (module != nullptr && *module) h->warnings += std::string(module) + ": ";
  h->warnings += text;
  return 1;
}

// Whether a libtiff warning says the strip or tile layout was not as the
// file declares it.
bool isLayoutWarning(const std::string& text) {
  for (const char* tag : {"StripOffsets", "StripByteCounts", "TileOffsets", "TileByteCounts"}) {
    if (text.find(tag) != std::string::npos) return true;
  }
  return false;
}

Status openHandle(const std::string& path, Handle* h) {
  TIFFOpenOptions* opts = TIFFOpenOptionsAlloc();
  if (opts == nullptr) return Status::error(ErrorCode::kOutOfMemory, path + ": cannot open image");
  TIFFOpenOptionsSetMaxSingleMemAlloc(opts, kMaxTiffAllocBytes);
  TIFFOpenOptionsSetErrorHandlerExtR(opts, onTiffError, h);
  TIFFOpenOptionsSetWarningHandlerExtR(opts, onTiffWarning, h);
  // "m": read(), not mmap(): mapped pages of a large uncompressed input
  // would count as the tiler's resident memory.
  h->tiff = TIFFOpenExt(path.c_str(), "rm", opts);
  TIFFOpenOptionsFree(opts);
  if (h->tiff == nullptr) {
    return Status::error(ErrorCode::kIo, path + ": cannot open image: " +
                                             decoderMessage(h->messages, "not a TIFF libtiff can read"));
  }
  h->messages.clear();
  if (isLayoutWarning(h->warnings)) {
    return Status::error(ErrorCode::kTruncated,
                         path + ": damaged TIFF: " + decoderMessage(h->warnings, "layout warning"));
  }
  return okStatus();
}

// Every strip or tile must lie inside the file, and hold something; an
// uncompressed one, all its bytes. A file that declares far more data than
// it holds is refused here, before the work starts, instead of tiling the
// missing data as zeros for minutes.
Status checkChunks(const std::string& path, TIFF* t, bool tiled, uint16_t compression,
                   uint64_t chunk_bytes, uint64_t last_chunk_bytes) {
  std::error_code ec;
  const uint64_t file_bytes = fs::file_size(path, ec);
  if (ec) return Status::error(ErrorCode::kIo, path + ": " + ec.message());
  const uint32_t n = tiled ? TIFFNumberOfTiles(t) : TIFFNumberOfStrips(t);
  const char* what = tiled ? "tile" : "strip";
  for (uint32_t i = 0; i < n; ++i) {
    int err = 0;
    const uint64_t offset = TIFFGetStrileOffsetWithErr(t, i, &err);
    const uint64_t bytes = err == 0 ? TIFFGetStrileByteCountWithErr(t, i, &err) : 0;
    std::string problem;
    if (err != 0) {
      problem = "its offset or byte count cannot be read";
    } else if (bytes == 0) {
      problem = "it holds no bytes (a damaged file, or a sparse one, which is not read)";
    } else if (offset > file_bytes || bytes > file_bytes - offset) {
      problem = "it lies beyond the end of the file (" + std::to_string(bytes) + " bytes at " +
                std::to_string(offset) + ", the file has " + std::to_string(file_bytes) + ")";
    } else if (compression == COMPRESSION_NONE && !tiled &&
               bytes < (i + 1 == n ? last_chunk_bytes : chunk_bytes)) {
      problem = "it holds " + std::to_string(bytes) + " bytes of the " +
                std::to_string(i + 1 == n ? last_chunk_bytes : chunk_bytes) + " its rows need";
    } else if (compression == COMPRESSION_NONE && tiled && bytes < chunk_bytes) {
      problem = "it holds " + std::to_string(bytes) + " bytes of the " + std::to_string(chunk_bytes) +
                " a tile needs";
    }
    if (!problem.empty()) {
      return Status::error(ErrorCode::kTruncated, path + ": damaged TIFF: " + what + " " +
                                                      std::to_string(i) + " of " + std::to_string(n) +
                                                      ": " + problem);
    }
  }
  return okStatus();
}

// Runs tasks on the calling thread and up to `extra` threads of its own,
// started on the first run that has work for them.
//
// Thread rule: run() is called by one thread at a time (the source's).
class DecodePool {
 public:
  explicit DecodePool(unsigned extra) : m_wanted(extra) {}
  ~DecodePool() {
    {
      std::lock_guard lock(m_mutex);
      m_stop = true;
    }
    m_wake.notify_all();
    for (std::thread& t : m_threads) t.join();
  }

  unsigned workers() const { return 1 + unsigned(m_threads.size()); }

  // fn(task, worker) for every task in [0, n), worker in [0, workers()).
  void run(size_t n, const std::function<void(size_t, unsigned)>& fn) {
    if (n > 1) startThreads();
    if (n <= 1 || m_threads.empty()) {
      for (size_t i = 0; i < n; ++i) fn(i, 0);
      return;
    }
    {
      std::lock_guard lock(m_mutex);
      m_fn = &fn;
      m_tasks = n;
      m_next.store(0);
      m_busy = unsigned(m_threads.size());
      ++m_generation;
    }
    m_wake.notify_all();
    work(0);
    std::unique_lock lock(m_mutex);
    m_done.wait(lock, [&] { return m_busy == 0; });
    m_fn = nullptr;
  }

 private:
  void startThreads() {
    while (m_threads.size() < m_wanted) {
      const unsigned id = 1 + unsigned(m_threads.size());
      try {
        m_threads.emplace_back([this, id] { loop(id); });
      } catch (const std::system_error&) {
        m_wanted = unsigned(m_threads.size());  // the system's thread limit: decode with fewer
      }
    }
  }

  void work(unsigned worker) {
    for (size_t i = m_next.fetch_add(1); i < m_tasks; i = m_next.fetch_add(1)) (*m_fn)(i, worker);
  }

  void loop(unsigned worker) {
    uint64_t seen = 0;
    std::unique_lock lock(m_mutex);
    for (;;) {
      m_wake.wait(lock, [&] { return m_stop || m_generation != seen; });
      if (m_stop) return;
      seen = m_generation;
      lock.unlock();
      work(worker);
      lock.lock();
      if (--m_busy == 0) m_done.notify_one();
    }
  }

  unsigned m_wanted;
  std::vector<std::thread> m_threads;
  std::mutex m_mutex;
  std::condition_variable m_wake, m_done;
  const std::function<void(size_t, unsigned)>* m_fn = nullptr;
  size_t m_tasks = 0;
  std::atomic<size_t> m_next{0};
  unsigned m_busy = 0;
  uint64_t m_generation = 0;
  bool m_stop = false;
};

// How the file's pixels are laid out, read once from the first handle.
struct PixelLayout {
  SampleKind kind = SampleKind::kU8;
  bool doubles = false;       // 64-bit floats, narrowed to float on conversion
  size_t native_pixel = 0;    // bytes of one decoded pixel
  bool tiled = false;
  uint32_t chunk_w = 0;       // tile width, or the image width for strips
  uint32_t chunk_h = 0;       // tile height, or rows per strip
  bool scanlines = false;     // strips too large to hold: one row at a time
  bool jpeg_rgb = false;      // JPEG-compressed YCbCr, delivered as RGB by libtiff
};

class TiffSource final : public ImageSource {
 public:
  TiffSource(std::string path, SourceInfo info, PixelLayout layout, std::unique_ptr<Handle> first,
             unsigned threads)
      : m_path(std::move(path)), m_info(std::move(info)), m_layout(layout), m_pool(threads - 1) {
    m_handles.resize(threads);
    m_handles[0] = std::move(first);
    m_scratch.resize(threads);
  }

  const SourceInfo& info() const override { return m_info; }

  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    if (y0 + rows > m_info.height_px || x0 + width > m_info.width_px) {
      return Status::error(ErrorCode::kOutOfRange, m_path + ": row request outside the image");
    }
    if (rows == 0 || width == 0) return okStatus();
    const size_t np = m_layout.native_pixel;
    if (m_layout.scanlines) {
      m_row.resize(size_t(m_info.width_px) * np);
      for (uint32_t r = 0; r < rows; ++r) {
        Handle& h = *m_handles[0];
        if (TIFFReadScanline(h.tiff, m_row.data(), uint32_t(y0 + r), 0) < 0) {
          return readError(h, "row " + std::to_string(y0 + r));
        }
        if (!h.warnings.empty()) return damagedChunk(h, "row " + std::to_string(y0 + r));
        convert(m_row.data() + x0 * np, width, dst + size_t(r) * dst_stride);
      }
      return okStatus();
    }
    Status s = ensureBand(y0, y0 + rows, x0, x0 + width);
    if (!s) return s;
    const size_t stride = size_t(m_band_x1 - m_band_x0) * np;
    for (uint32_t r = 0; r < rows; ++r) {
      const uint8_t* src = m_band.data() + size_t(y0 + r - m_band_y0) * stride + (x0 - m_band_x0) * np;
      convert(src, width, dst + size_t(r) * dst_stride);
    }
    return okStatus();
  }

 private:
  void convert(const uint8_t* src, uint64_t width, uint8_t* out) {
    const uint32_t nch = m_info.input_channels;
    if (m_layout.doubles) {
      m_narrow.resize(size_t(width) * nch);
      for (size_t i = 0; i < m_narrow.size(); ++i) {
        double d;
        std::memcpy(&d, src + 8 * i, 8);
        m_narrow[i] = float(d);
      }
      src = reinterpret_cast<const uint8_t*>(m_narrow.data());
    }
    const bool fast_copy = m_layout.kind == SampleKind::kU8 && formatChannels(m_info.format) == nch;
    convertNativeRow(m_layout.kind, src, nch, width, m_info.format, fast_copy, out,
                     &m_info.clamped_samples);
  }

  // A chunk the decoder read whole but warned about (data ran out, a
  // corrupt code): its pixels are partly the decoder's filling.
  Status damagedChunk(Handle& h, const std::string& what) {
    std::string why = decoderMessage(h.warnings, "decoder warning");
    h.warnings.clear();
    return Status::error(ErrorCode::kTruncated, m_path + ": damaged image data in " + what + ": " + why);
  }

  Status readError(Handle& h, const std::string& what) {
    std::string why = decoderMessage(h.messages, "decoder failed");
    h.messages.clear();
    return Status::error(ErrorCode::kIo, m_path + ": cannot read " + what + ": " + why);
  }

  // Makes the band hold every chunk under rows [y0, y1) and columns
  // [x0, x1): chunk rows already in it are kept, the rest decoded.
  Status ensureBand(uint64_t y0, uint64_t y1, uint64_t x0, uint64_t x1) {
    const uint64_t W = m_info.width_px, H = m_info.height_px;
    const uint64_t cw = m_layout.chunk_w, ch = m_layout.chunk_h;
    const uint64_t by0 = y0 / ch * ch, by1 = std::min((y1 + ch - 1) / ch * ch, H);
    const uint64_t bx0 = m_layout.tiled ? x0 / cw * cw : 0;
    const uint64_t bx1 = m_layout.tiled ? std::min((x1 + cw - 1) / cw * cw, W) : W;
    if (m_band_valid && by0 >= m_band_y0 && by1 <= m_band_y1 && bx0 == m_band_x0 && bx1 == m_band_x1) {
      return okStatus();
    }
    const size_t np = m_layout.native_pixel;
    const size_t stride = size_t(bx1 - bx0) * np;
    // Rows of the old band that the new one starts with move to its top.
    uint64_t kept_y1 = by0;
    if (m_band_valid && bx0 == m_band_x0 && bx1 == m_band_x1 && by0 >= m_band_y0 && by0 < m_band_y1) {
      kept_y1 = m_band_y1;
      std::memmove(m_band.data(), m_band.data() + size_t(by0 - m_band_y0) * stride,
                   size_t(kept_y1 - by0) * stride);
    }
    m_band_valid = false;
    m_band.resize(size_t(by1 - by0) * stride);
    m_band_y0 = by0, m_band_y1 = by1, m_band_x0 = bx0, m_band_x1 = bx1;

    struct Chunk {
      uint64_t x, y;  // its first pixel
    };
    std::vector<Chunk> chunks;
    for (uint64_t y = kept_y1; y < by1; y += ch)
      for (uint64_t x = bx0; x < bx1; x += cw) chunks.push_back({x, y});
    std::vector<Status> results(chunks.size());
    m_pool.run(chunks.size(), [&](size_t i, unsigned worker) {
      try {
        results[i] = decodeChunk(chunks[i].x, chunks[i].y, worker, stride);
      } catch (const std::bad_alloc&) {  // a worker must not throw: the run fails instead
        results[i] = Status::error(ErrorCode::kOutOfMemory,
                                   m_path + ": an allocation failed while decoding");
      }
    });
    for (Status& s : results)
      if (!s) return std::move(s);
    m_band_valid = true;
    return okStatus();
  }

  // Decodes the strip or tile whose first pixel is (x, y) into the band.
  Status decodeChunk(uint64_t x, uint64_t y, unsigned worker, size_t stride) {
    std::unique_ptr<Handle>& slot = m_handles[worker];
    if (!slot) {
      auto h = std::make_unique<Handle>();
      Status s = openHandle(m_path, h.get());
      if (!s) return s;
      h->warnings.clear();  // the first handle's, reported at open
      if (m_layout.jpeg_rgb) TIFFSetField(h->tiff, TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
      slot = std::move(h);
    }
    Handle& h = *slot;
    const size_t np = m_layout.native_pixel;
    const uint64_t W = m_info.width_px, H = m_info.height_px;
    const uint64_t rows = std::min<uint64_t>(m_layout.chunk_h, H - y);
    uint8_t* at = m_band.data() + size_t(y - m_band_y0) * stride + size_t(x - m_band_x0) * np;
    if (!m_layout.tiled) {
      const uint32_t strip = TIFFComputeStrip(h.tiff, uint32_t(y), 0);
      const tmsize_t want = tmsize_t(rows * W * np);
      const tmsize_t got = TIFFReadEncodedStrip(h.tiff, strip, at, want);
      if (got == want && !h.warnings.empty()) return damagedChunk(h, "strip " + std::to_string(strip));
      if (got != want) {
        if (got >= 0 && h.messages.empty()) h.messages = "strip holds fewer pixels than its rows";
        return readError(h, "strip " + std::to_string(strip) + " (rows " + std::to_string(y) + "-" +
                                std::to_string(y + rows - 1) + ")");
      }
      return okStatus();
    }
    const size_t tile_bytes = size_t(m_layout.chunk_w) * m_layout.chunk_h * np;
    std::vector<uint8_t>& scratch = m_scratch[worker];
    scratch.resize(tile_bytes);
    const uint32_t tile = TIFFComputeTile(h.tiff, uint32_t(x), uint32_t(y), 0, 0);
    const tmsize_t got = TIFFReadEncodedTile(h.tiff, tile, scratch.data(), tmsize_t(tile_bytes));
    if (got == tmsize_t(tile_bytes) && !h.warnings.empty()) return damagedChunk(h, "tile " + std::to_string(tile));
    if (got != tmsize_t(tile_bytes)) {
      if (got >= 0 && h.messages.empty()) h.messages = "tile holds fewer pixels than its size";
      return readError(h, "tile " + std::to_string(tile) + " at (" + std::to_string(x) + ", " +
                              std::to_string(y) + ")");
    }
    const size_t cols = size_t(std::min<uint64_t>(m_layout.chunk_w, W - x));
    for (uint64_t r = 0; r < rows; ++r) {
      std::memcpy(at + r * stride, scratch.data() + r * m_layout.chunk_w * np, cols * np);
    }
    return okStatus();
  }

  std::string m_path;
  SourceInfo m_info;
  PixelLayout m_layout;
  std::vector<std::unique_ptr<Handle>> m_handles;  // one per worker, opened when it first decodes
  std::vector<std::vector<uint8_t>> m_scratch;     // one tile per worker
  std::vector<uint8_t> m_band;                     // decoded pixels of [y0, y1) x [x0, x1)
  uint64_t m_band_y0 = 0, m_band_y1 = 0, m_band_x0 = 0, m_band_x1 = 0;
  bool m_band_valid = false;
  std::vector<uint8_t> m_row;     // one scanline (scanline mode)
  std::vector<float> m_narrow;    // one row of doubles narrowed
  DecodePool m_pool;              // last: stopped before the handles close
};

// The baseline fields the readers decide by, with libtiff's defaults for
// those the file leaves out.
struct TiffFields {
  uint32_t w = 0, h = 0;
  uint16_t spp = 1, bits = 1, sample_format = SAMPLEFORMAT_UINT, planar = PLANARCONFIG_CONTIG;
  uint16_t photometric = 0, compression = COMPRESSION_NONE, orientation = ORIENTATION_TOPLEFT;
};

// The first handle's fields, as the file gives them or as libtiff defaults them.
TiffFields readFields(TIFF* t) {
  TiffFields f;
  TIFFGetField(t, TIFFTAG_IMAGEWIDTH, &f.w);
  TIFFGetField(t, TIFFTAG_IMAGELENGTH, &f.h);
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLESPERPIXEL, &f.spp);
  TIFFGetFieldDefaulted(t, TIFFTAG_BITSPERSAMPLE, &f.bits);
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLEFORMAT, &f.sample_format);
  TIFFGetFieldDefaulted(t, TIFFTAG_PLANARCONFIG, &f.planar);
  TIFFGetFieldDefaulted(t, TIFFTAG_COMPRESSION, &f.compression);
  TIFFGetFieldDefaulted(t, TIFFTAG_ORIENTATION, &f.orientation);
  if (!TIFFGetField(t, TIFFTAG_PHOTOMETRIC, &f.photometric)) {
    f.photometric = f.spp >= 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK;
  }
  return f;
}

// The samples and colour model: sets the layout's kind, doubles and
// jpeg_rgb, and returns whether these readers cover them (1 to 4
// interleaved samples of uint8, uint16, int16, float or double; grey, RGB,
// or JPEG's YCbCr); what they do not is OpenImageIO's.
bool sampleLayout(const TiffFields& f, PixelLayout* layout) {
  bool ok = f.spp >= 1 && f.spp <= 4 && (f.planar == PLANARCONFIG_CONTIG || f.spp == 1);
  if (f.sample_format == SAMPLEFORMAT_UINT && f.bits == 8) {
    layout->kind = SampleKind::kU8;
  } else if (f.sample_format == SAMPLEFORMAT_UINT && f.bits == 16) {
    layout->kind = SampleKind::kU16;
  } else if (f.sample_format == SAMPLEFORMAT_INT && f.bits == 16) {
    layout->kind = SampleKind::kI16;
  } else if (f.sample_format == SAMPLEFORMAT_IEEEFP && (f.bits == 32 || f.bits == 64)) {
    layout->kind = SampleKind::kF32;
    layout->doubles = f.bits == 64;
  } else {
    ok = false;
  }
  if (f.photometric == PHOTOMETRIC_YCBCR) {
    ok = ok && f.compression == COMPRESSION_JPEG && f.spp == 3;
    layout->jpeg_rgb = true;
  } else if (f.photometric == PHOTOMETRIC_RGB) {
    ok = ok && f.spp >= 3;
  } else {
    ok = ok && f.photometric == PHOTOMETRIC_MINISBLACK;
  }
  return ok;
}

// The strips or tiles: sets the layout's pixel size, chunk size and
// scanline mode, and returns whether these readers cover them (tiles of at
// most kMaxChunkBytes, chunks whose size libtiff agrees with).
bool chunkLayout(TIFF* t, const TiffFields& f, PixelLayout* layout) {
  layout->native_pixel = size_t(f.bits / 8) * f.spp;
  layout->tiled = TIFFIsTiled(t) != 0;
  if (layout->tiled) {
    uint32_t tw = 0, th = 0;
    TIFFGetField(t, TIFFTAG_TILEWIDTH, &tw);
    TIFFGetField(t, TIFFTAG_TILELENGTH, &th);
    if (tw == 0 || th == 0 || size_t(tw) * th * layout->native_pixel > kMaxChunkBytes ||
        TIFFTileSize64(t) != uint64_t(tw) * th * layout->native_pixel) {
      return false;
    }
    layout->chunk_w = tw, layout->chunk_h = th;
    return true;
  }
  uint32_t rps = f.h;
  TIFFGetFieldDefaulted(t, TIFFTAG_ROWSPERSTRIP, &rps);
  rps = std::clamp<uint32_t>(rps, 1, f.h);
  layout->chunk_w = f.w, layout->chunk_h = rps;
  layout->scanlines = uint64_t(rps) * f.w * layout->native_pixel > kMaxChunkBytes;
  return TIFFScanlineSize64(t) == uint64_t(f.w) * layout->native_pixel;
}

// checkChunks() with the chunk sizes of this layout (the last strip holds
// the rows left over).
Status checkLayoutChunks(const std::string& path, TIFF* t, const TiffFields& f,
                         const PixelLayout& layout) {
  const uint64_t chunk = uint64_t(layout.chunk_w) * layout.chunk_h * layout.native_pixel;
  const uint64_t last_rows =
      layout.tiled ? layout.chunk_h : f.h - (uint64_t(f.h) - 1) / layout.chunk_h * layout.chunk_h;
  return checkChunks(path, t, layout.tiled, f.compression, chunk,
                     uint64_t(layout.chunk_w) * last_rows * layout.native_pixel);
}

// The source's SourceInfo. Takes the first handle's warnings (what libtiff
// said of the file at open that does not stop the run) into its warnings.
SourceInfo tiffInfo(const std::string& path, const TiffFields& f, const PixelLayout& layout,
                    std::optional<PixelFormat> forced, Handle* first) {
  SourceInfo info;
  info.width_px = f.w;
  info.height_px = f.h;
  info.input_channels = f.spp;
  for (size_t at = 0; at < first->warnings.size();) {
    const size_t end = std::min(first->warnings.find('\n', at), first->warnings.size());
    info.warnings.push_back(path + ": libtiff: " + first->warnings.substr(at, end - at));
    at = end + 1;
  }
  first->warnings.clear();
  info.input_type = layout.doubles ? "double" : sampleKindName(layout.kind);
  info.decoder = "libtiff";
  info.tiled = layout.tiled;
  info.sequential_only = false;
  std::error_code ec;
  info.file_bytes = fs::file_size(path, ec);
  info.format = forced ? *forced : defaultFormat(f.spp, layout.kind);
  if (f.orientation != ORIENTATION_TOPLEFT) info.warnings.push_back(orientationWarning(path, f.orientation));
  return info;
}

}  // namespace

// The reader in its steps: open the first handle, read its fields, decide
// whether the samples and chunks are covered, check the chunks lie in the
// file, then make the source with its decode threads.
Status openTiffImage(const std::string& path, std::optional<PixelFormat> forced,
                     const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                     bool* covered) {
  *covered = true;
  auto first = std::make_unique<Handle>();
  Status s = openHandle(path, first.get());
  if (!s) return s;
  TIFF* t = first->tiff;
  const TiffFields f = readFields(t);
  if (f.w == 0 || f.h == 0) {
    return Status::error(ErrorCode::kInvalidArgument, path + ": image size " + std::to_string(f.w) +
                                                          "x" + std::to_string(f.h) + " is empty or not 2D");
  }

  // What these readers cover; the rest (and its errors) is OpenImageIO's.
  PixelLayout layout;
  if (!sampleLayout(f, &layout)) {
    *covered = false;
    return okStatus();
  }
  if (layout.jpeg_rgb) TIFFSetField(t, TIFFTAG_JPEGCOLORMODE, JPEGCOLORMODE_RGB);
  if (!chunkLayout(t, f, &layout)) {
    *covered = false;
    return okStatus();
  }
  s = checkLayoutChunks(path, t, f, layout);
  if (!s) return s;

  SourceInfo info = tiffInfo(path, f, layout, forced, first.get());
  unsigned threads = read.decode_threads != 0 ? read.decode_threads : std::thread::hardware_concurrency();
  threads = std::clamp(threads, 1u, kMaxDecodeThreads);
  if (layout.scanlines) threads = 1;
  *out = std::make_unique<TiffSource>(path, std::move(info), layout, std::move(first), threads);
  return okStatus();
}

}  // namespace clipstream
