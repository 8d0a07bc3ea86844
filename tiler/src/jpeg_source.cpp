// JPEG through libjpeg-turbo (native_source.h). Baseline files decode a
// scanline at a time. A progressive (or other multi-scan) file makes
// libjpeg keep every DCT coefficient of the image until its last scan, 2
// bytes a sample: ~200 MB for an 8192x4096 colour image. When that would
// take more than a quarter of the caller's budget, this reader gives
// libjpeg coefficient arrays of its own that live in an unlinked temporary
// file with a window of a few rows in memory (SpilledArray below), through
// the virtual-array methods of libjpeg's memory manager, which an
// application may replace (libjpeg.txt, "Memory management").
#include "native_source.h"
#include "pixel_convert.h"
#include "sequential_source.h"

#include <cstdio>  // jpeglib.h needs FILE first
#include <jpeglib.h>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csetjmp>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <vector>

namespace clipstream {
namespace {

using namespace pixel_convert;
namespace fs = std::filesystem;

// Rows of coefficient blocks a spilled array keeps in memory at once, at
// least what libjpeg asks to see at a time; a window of ~4 MB keeps the
// temporary file's reads and writes large.
constexpr size_t kSpillWindowBytes = size_t(4) << 20;

struct JpegError {
  jpeg_error_mgr pub;  // first: libjpeg sees a jpeg_error_mgr*
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {};
  char warning[JMSG_LENGTH_MAX] = {};
  bool warned = false;
};

[[noreturn]] void onJpegError(j_common_ptr cinfo) {
  auto* e = reinterpret_cast<JpegError*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, e->message);
  std::longjmp(e->jump, 1);
}

// libjpeg reports damage it can step over (data cut short, a bad Huffman
// code) as a warning and pads with grey. The read fails instead of tiling
// the padding, and it fails at once: left to go on, libjpeg pads every
// remaining block of every remaining scan, which for a multi-scan file
// whose header claims a huge image means gigabytes of zeros written to the
// coefficient file before the failure is seen. Trace messages are ignored.
void onJpegMessage(j_common_ptr cinfo, int level) {
  if (level >= 0) return;
  auto* e = reinterpret_cast<JpegError*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, e->warning);
  e->warned = true;
  std::longjmp(e->jump, 1);
}

// One coefficient array kept in a temporary file. libjpeg sees only the
// opaque pointer; access() hands it the window holding the rows it asks for.
struct SpilledArray {
  JDIMENSION blocks_per_row = 0, rows = 0, max_access = 0;
  bool pre_zero = false;
  int fd = -1;
  JDIMENSION window_rows = 0, window_start = 0;
  JDIMENSION written_rows = 0;  // rows [0, written_rows) are in the file
  bool dirty = false;
  std::vector<JCOEF> blocks;      // window_rows x blocks_per_row x DCTSIZE2
  std::vector<JBLOCKROW> row_ptrs;
  ~SpilledArray() {
    if (fd >= 0) ::close(fd);
  }
  size_t rowBytes() const { return size_t(blocks_per_row) * sizeof(JBLOCK); }
};

// The spilled arrays of one decompressor and the memory manager methods
// they replace. Reached from libjpeg's callbacks through client_data.
struct Spill {
  std::string dir;
  std::vector<std::unique_ptr<SpilledArray>> arrays;
  void (*original_realize)(j_common_ptr) = nullptr;
  const char* failure = nullptr;  // what went wrong, for the error message
  int failure_errno = 0;
};

[[noreturn]] void spillFailed(j_common_ptr cinfo, Spill* spill, const char* what) {
  spill->failure = what;
  spill->failure_errno = errno;
  // libjpeg's own error path: the message is built from ours (JERR_FILE_WRITE
  // and friends would name libjpeg's own file).
  auto* e = reinterpret_cast<JpegError*>(cinfo->err);
  std::snprintf(e->message, sizeof e->message, "%s: %s", what, std::strerror(spill->failure_errno));
  std::longjmp(e->jump, 1);
}

Spill* spillOf(j_common_ptr cinfo) { return static_cast<Spill*>(cinfo->client_data); }

jvirt_barray_ptr requestSpilled(j_common_ptr cinfo, int pool_id, boolean pre_zero,
                                JDIMENSION blocks_per_row, JDIMENSION rows, JDIMENSION max_access) {
  (void)pool_id;  // the arrays live until the decompressor is destroyed
  Spill* spill = spillOf(cinfo);
  SpilledArray* a = nullptr;
  try {
    spill->arrays.push_back(std::make_unique<SpilledArray>());
    a = spill->arrays.back().get();
  } catch (const std::bad_alloc&) {
    spillFailed(cinfo, spill, "out of memory for a coefficient array");
  }
  a->blocks_per_row = blocks_per_row;
  a->rows = rows;
  a->max_access = max_access;
  a->pre_zero = pre_zero != 0;
  return reinterpret_cast<jvirt_barray_ptr>(a);
}

void realizeSpilled(j_common_ptr cinfo) {
  Spill* spill = spillOf(cinfo);
  spill->original_realize(cinfo);  // libjpeg's own (sample) arrays
  for (auto& owned : spill->arrays) {
    SpilledArray* a = owned.get();
    if (!a->blocks.empty()) continue;
    const size_t row_bytes = std::max<size_t>(a->rowBytes(), 1);
    a->window_rows = JDIMENSION(std::clamp<size_t>(kSpillWindowBytes / row_bytes, a->max_access,
                                                   std::max<JDIMENSION>(a->rows, 1)));
    a->fd = ::open(spill->dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (a->fd < 0) {
      std::string name = spill->dir + "/clipstream-jpeg-XXXXXX";
      a->fd = ::mkostemp(name.data(), O_CLOEXEC);
      if (a->fd >= 0) ::unlink(name.c_str());
    }
    if (a->fd < 0) spillFailed(cinfo, spill, "cannot create a temporary file for the coefficients");
    try {
      a->blocks.resize(size_t(a->window_rows) * a->blocks_per_row * DCTSIZE2);
      a->row_ptrs.resize(a->window_rows);
    } catch (const std::bad_alloc&) {
      spillFailed(cinfo, spill, "out of memory for a coefficient window");
    }
    for (JDIMENSION r = 0; r < a->window_rows; ++r) {
      a->row_ptrs[r] = reinterpret_cast<JBLOCKROW>(a->blocks.data() + size_t(r) * a->blocks_per_row * DCTSIZE2);
    }
  }
}

bool writeWindow(SpilledArray* a) {
  const JDIMENSION n = std::min(a->window_rows, a->rows - a->window_start);
  const size_t bytes = size_t(n) * a->rowBytes();
  const char* p = reinterpret_cast<const char*>(a->blocks.data());
  for (size_t done = 0; done < bytes;) {
    const ssize_t w = ::pwrite(a->fd, p + done, bytes - done,
                               off_t(size_t(a->window_start) * a->rowBytes() + done));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    done += size_t(w);
  }
  a->written_rows = std::max(a->written_rows, a->window_start + n);
  a->dirty = false;
  return true;
}

bool readWindow(SpilledArray* a) {
  const JDIMENSION n = std::min(a->window_rows, a->rows - a->window_start);
  const JDIMENSION have = a->written_rows > a->window_start
                              ? std::min(n, a->written_rows - a->window_start) : 0;
  char* p = reinterpret_cast<char*>(a->blocks.data());
  const size_t bytes = size_t(have) * a->rowBytes();
  for (size_t done = 0; done < bytes;) {
    const ssize_t r = ::pread(a->fd, p + done, bytes - done,
                              off_t(size_t(a->window_start) * a->rowBytes() + done));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    done += size_t(r);
  }
  // Rows never written read as zero (libjpeg asks for pre-zeroed
  // coefficient arrays; the others are written before they are read).
  std::memset(p + bytes, 0, size_t(n - have) * a->rowBytes());
  return true;
}

JBLOCKARRAY accessSpilled(j_common_ptr cinfo, jvirt_barray_ptr ptr, JDIMENSION start_row,
                          JDIMENSION num_rows, boolean writable) {
  auto* a = reinterpret_cast<SpilledArray*>(ptr);
  Spill* spill = spillOf(cinfo);
  const JDIMENSION end_row = start_row + num_rows;
  if (end_row > a->rows || num_rows > a->window_rows || a->blocks.empty()) {
    spillFailed(cinfo, spill, "a coefficient access outside its array");
  }
  if (start_row < a->window_start || end_row > a->window_start + a->window_rows) {
    if (a->dirty && !writeWindow(a)) spillFailed(cinfo, spill, "cannot write the coefficient file");
    // Forward: the window starts at the rows asked for; backward: it ends
    // at them (libjpeg's own rule for its backing store).
    JDIMENSION start = start_row >= a->window_start
                           ? start_row
                           : (end_row > a->window_rows ? end_row - a->window_rows : 0);
    start = std::min(start, a->rows > a->window_rows ? a->rows - a->window_rows : 0);
    a->window_start = start;
    if (!readWindow(a)) spillFailed(cinfo, spill, "cannot read the coefficient file");
  }
  if (writable) a->dirty = true;
  return a->row_ptrs.data() + (start_row - a->window_start);
}

// Bytes of coefficients a multi-scan decode keeps (the arrays jdcoefct.c
// requests: each component's blocks rounded up to whole MCUs).
uint64_t coefficientBytes(const jpeg_decompress_struct& c) {
  uint64_t total = 0;
  for (int i = 0; i < c.num_components; ++i) {
    const jpeg_component_info& comp = c.comp_info[i];
    const uint64_t w = (uint64_t(comp.width_in_blocks) + comp.h_samp_factor - 1) /
                       comp.h_samp_factor * comp.h_samp_factor;
    const uint64_t h = (uint64_t(comp.height_in_blocks) + comp.v_samp_factor - 1) /
                       comp.v_samp_factor * comp.v_samp_factor;
    total += w * h * sizeof(JBLOCK);
  }
  return total;
}

std::string spillDirectory() {
  const char* env = std::getenv("TMPDIR");
  return env != nullptr && *env ? env : "/tmp";
}

// One decompressor over the file, from its start. Every libjpeg call goes
// through guarded(), the only frame with setjmp; the calls it wraps hold
// nothing that needs destroying.
class Decoder {
 public:
  ~Decoder() {
    if (m_created) jpeg_destroy_decompress(&m_cinfo);
    if (m_file != nullptr) std::fclose(m_file);
  }

  // Opens the file and reads its header (markers kept for the EXIF block).
  Status open(const std::string& path) {
    m_path = path;
    Status opened = openInputFile(path, &m_file);
    if (!opened) return opened;
    m_cinfo.err = jpeg_std_error(&m_err.pub);
    m_err.pub.error_exit = onJpegError;
    m_err.pub.emit_message = onJpegMessage;
    if (!guarded([&] { jpeg_create_decompress(&m_cinfo); })) return failure("cannot open image");
    m_created = true;
    m_cinfo.client_data = &m_spill;
    if (!guarded([&] {
          jpeg_stdio_src(&m_cinfo, m_file);
          jpeg_save_markers(&m_cinfo, JPEG_APP0 + 1, 0xffff);
          jpeg_read_header(&m_cinfo, TRUE);
        })) {
      return failure("cannot open image");
    }
    return okStatus();
  }

  jpeg_decompress_struct& cinfo() { return m_cinfo; }

  // Starts decoding (for a multi-scan file: reads every scan), with the
  // coefficients in a temporary file when `spill`.
  Status start(J_COLOR_SPACE out_space, bool spill) {
    m_cinfo.out_color_space = out_space;
    if (spill) {
      m_spill.dir = spillDirectory();
      jpeg_memory_mgr* mem = m_cinfo.mem;
      m_spill.original_realize = mem->realize_virt_arrays;
      mem->request_virt_barray = requestSpilled;
      mem->realize_virt_arrays = realizeSpilled;
      mem->access_virt_barray = accessSpilled;
    }
    if (!guarded([&] { jpeg_start_decompress(&m_cinfo); })) {
      return failure(m_spill.failure != nullptr ? "cannot decode (coefficient file in " + m_spill.dir + ")"
                                                : std::string("cannot decode image"));
    }
    return okStatus();
  }

  uint64_t nextRow() const { return m_cinfo.output_scanline; }

  // Decodes the next scanline into `row`.
  Status readRow(uint8_t* row) {
    JSAMPROW rows[1] = {row};
    if (!guarded([&] { jpeg_read_scanlines(&m_cinfo, rows, 1); })) {
      return failure("cannot read row " + std::to_string(m_cinfo.output_scanline));
    }
    return okStatus();
  }

 private:
  template <typename F>
  bool guarded(F&& f) {
    if (setjmp(m_err.jump) != 0) return false;
    f();
    return true;
  }

  // A warning (onJpegMessage) ends the call it came from too: it is
  // reported as damage, not as a decoder failure.
  Status failure(const std::string& what) {
    if (m_err.warned) return damaged();
    return Status::error(ErrorCode::kIo,
                         m_path + ": " + what + ": " + decoderMessage(m_err.message, "decoder failed"));
  }
  Status damaged() {
    return Status::error(ErrorCode::kTruncated,
                         m_path + ": damaged image data: " + decoderMessage(m_err.warning, "decoder warning"));
  }

  std::string m_path;
  std::FILE* m_file = nullptr;
  jpeg_decompress_struct m_cinfo{};
  JpegError m_err{};
  Spill m_spill;
  bool m_created = false;
};

}  // namespace

Status openJpegImage(const std::string& path, std::optional<PixelFormat> forced,
                     const ImageReadOptions& read, std::unique_ptr<ImageSource>* out,
                     bool* covered) {
  *covered = true;
  auto decoder = std::make_unique<Decoder>();
  Status s = decoder->open(path);
  if (!s) return s;
  const jpeg_decompress_struct& c = decoder->cinfo();
  J_COLOR_SPACE space;
  if (c.num_components == 1 && c.jpeg_color_space == JCS_GRAYSCALE) {
    space = JCS_GRAYSCALE;
  } else if (c.num_components == 3 && (c.jpeg_color_space == JCS_YCbCr || c.jpeg_color_space == JCS_RGB)) {
    space = JCS_RGB;
  } else {
    *covered = false;  // CMYK, YCCK: OpenImageIO's
    return okStatus();
  }
  if (c.image_width == 0 || c.image_height == 0) {
    return Status::error(ErrorCode::kInvalidArgument,
                         path + ": image size " + std::to_string(c.image_width) + "x" +
                             std::to_string(c.image_height) + " is empty or not 2D");
  }
  SourceInfo info;
  info.width_px = c.image_width;
  info.height_px = c.image_height;
  info.input_channels = uint32_t(c.num_components);
  info.input_type = "uint8";
  info.tiled = false;
  info.sequential_only = true;
  std::error_code ec;
  info.file_bytes = fs::file_size(path, ec);
  info.format = forced ? *forced : defaultFormat(info.input_channels, SampleKind::kU8);
  for (jpeg_saved_marker_ptr m = c.marker_list; m != nullptr; m = m->next) {
    if (m->marker == JPEG_APP0 + 1 && m->data_length > 6 && std::memcmp(m->data, "Exif\0\0", 6) == 0) {
      const uint16_t orientation = exifOrientation(m->data + 6, m->data_length - 6);
      if (orientation != 1) info.warnings.push_back(orientationWarning(path, orientation));
      break;
    }
  }
  const bool spill = jpeg_has_multiple_scans(const_cast<jpeg_decompress_struct*>(&c)) &&
                     read.memory_budget_bytes > 0 &&
                     coefficientBytes(c) > read.memory_budget_bytes / 4;
  info.decoder = spill ? "libjpeg, coefficients in a temporary file" : "libjpeg";
  // Started here, as a multi-scan file's coefficients are read whole at the
  // start: the tiler's memory plan then sees what they take.
  s = decoder->start(space, spill);
  if (!s) return s;
  auto restart = [path, space, spill](std::unique_ptr<Decoder>* again) {
    *again = std::make_unique<Decoder>();
    Status st = (*again)->open(path);
    if (st) st = (*again)->start(space, spill);
    return st;
  };
  *out = std::make_unique<SequentialSource<Decoder>>(path, std::move(info), SampleKind::kU8,
                                                     std::move(decoder), restart);
  return okStatus();
}

}  // namespace clipstream
