// PNG writer thread. See frame_writer.h.
#include <clipstream/eval/frame_writer.h>

#include <clipstream/util/output_file.h>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <cstdio>

namespace clipstream {

Status writePng(const std::string& path, uint32_t width_px, uint32_t height_px,
                const uint8_t* rgba) {
  // Encoded in memory, then written and published by OutputFile: every
  // write, the close and the rename are checked (a PNG writer writing to a
  // file would not report a failed write), and no reader sees half a PNG.
  std::vector<unsigned char> png;
  OIIO::Filesystem::IOVecOutput memory(png);
  auto out = OIIO::ImageOutput::create("png", &memory);
  if (!out) return Status::error(ErrorCode::kIo, "cannot create PNG writer for " + path);
  OIIO::ImageSpec spec(int(width_px), int(height_px), 4, OIIO::TypeDesc::UINT8);
  if (!out->open(path, spec) || !out->write_image(OIIO::TypeDesc::UINT8, rgba) || !out->close()) {
    return Status::error(ErrorCode::kIo, "cannot encode PNG " + path + ": " + out->geterror());
  }
  OutputOptions options;
  options.existing = ExistingOutput::kReplaceRegular;
  options.fsync = false;  // frames are measurements a rerun remakes; atomicity is what matters
  options.sweep = false;  // one scan per frame would be quadratic; clipstream-fly sweeps --out once
  return writeOutputFile(path, std::string_view(reinterpret_cast<const char*>(png.data()), png.size()),
                         options);
}

Status readImageRgba(const std::string& path, std::vector<uint8_t>* rgba, uint32_t* width_px,
                     uint32_t* height_px) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) return Status::error(ErrorCode::kNotFound, "cannot open image " + path + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 || spec.width > 65536 ||
      spec.height > 65536)
    return Status::error(ErrorCode::kUnsupported, path + ": unsupported image size");
  const int channels = spec.nchannels;
  std::vector<uint8_t> raw(size_t(spec.width) * spec.height * channels);
  if (!in->read_image(0, 0, 0, channels, OIIO::TypeDesc::UINT8, raw.data()))
    return Status::error(ErrorCode::kIo, path + ": " + in->geterror());
  rgba->assign(size_t(spec.width) * spec.height * 4, 255);
  for (size_t i = 0; i < size_t(spec.width) * spec.height; ++i)
    for (int c = 0; c < 3; ++c)
      (*rgba)[i * 4 + c] = raw[i * channels + (channels >= 3 ? c : 0)];
  *width_px = uint32_t(spec.width);
  *height_px = uint32_t(spec.height);
  return okStatus();
}

FrameWriter::FrameWriter(size_t max_queued)
    : m_max_queued(max_queued), m_thread([this] { run(); }) {}

FrameWriter::~FrameWriter() { (void)close(); }

bool FrameWriter::submit(std::string path, uint32_t width_px, uint32_t height_px,
                         std::vector<uint8_t> rgba) {
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    if (m_closing || m_queue.size() >= m_max_queued) {
      ++m_dropped;
      return false;
    }
    m_queue.push_back({std::move(path), width_px, height_px, std::move(rgba)});
  }
  m_cv.notify_one();
  return true;
}

void FrameWriter::run() {
  for (;;) {
    Job job;
    {
      std::unique_lock<std::mutex> lock(m_mutex);
      m_cv.wait(lock, [this] { return m_closing || !m_queue.empty(); });
      if (m_queue.empty()) return;  // closing and drained
      job = std::move(m_queue.front());
      m_queue.pop_front();
    }
    Status s = writePng(job.path, job.width_px, job.height_px, job.rgba.data());
    std::lock_guard<std::mutex> lock(m_mutex);
    if (s.ok()) ++m_written;
    else if (m_first_error.ok()) m_first_error = std::move(s);
  }
}

Status FrameWriter::close() {
  {
    std::lock_guard<std::mutex> lock(m_mutex);
    m_closing = true;
  }
  m_cv.notify_all();
  if (m_thread.joinable()) m_thread.join();
  std::lock_guard<std::mutex> lock(m_mutex);
  return m_first_error;
}

uint64_t FrameWriter::written() const {
  std::lock_guard<std::mutex> lock(m_mutex);
  return m_written;
}

uint64_t FrameWriter::dropped() const {
  std::lock_guard<std::mutex> lock(m_mutex);
  return m_dropped;
}

}  // namespace clipstream
