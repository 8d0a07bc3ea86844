// An image source over a decoder that runs from the top of the file down
// (JPEG, PNG: jpeg_source.cpp, png_source.cpp). Rows above the decoder's
// next row are reached by starting it again from the file's start; rows
// between are decoded and dropped.
//
// Thread rule: as ImageSource (one thread at a time).
#pragma once

#include "pixel_convert.h"

#include <clipstream/tiler/image_source.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace clipstream {

// Decoder: uint64_t nextRow() const; Status readRow(uint8_t* row), one
// row of info.width_px native pixels of `kind`.
template <typename Decoder>
class SequentialSource final : public ImageSource {
 public:
  // `restart` makes a started decoder at the file's first row.
  using Restart = std::function<Status(std::unique_ptr<Decoder>*)>;

  SequentialSource(std::string path, SourceInfo info, pixel_convert::SampleKind kind,
                   std::unique_ptr<Decoder> decoder, Restart restart)
      : m_path(std::move(path)), m_info(std::move(info)), m_kind(kind),
        m_decoder(std::move(decoder)), m_restart(std::move(restart)) {}

  const SourceInfo& info() const override { return m_info; }

  Status readRows(uint64_t y0, uint32_t rows, uint64_t x0, uint64_t width, uint8_t* dst,
                  size_t dst_stride) override {
    using namespace pixel_convert;
    if (y0 + rows > m_info.height_px || x0 + width > m_info.width_px) {
      return Status::error(ErrorCode::kOutOfRange, m_path + ": row request outside the image");
    }
    if (y0 < m_decoder->nextRow()) {
      std::unique_ptr<Decoder> again;
      Status s = m_restart(&again);
      if (!s) return s;
      m_decoder = std::move(again);
    }
    const uint32_t nch = m_info.input_channels;
    const size_t np = sampleBytes(m_kind) * nch;
    const bool fast_copy = m_kind == SampleKind::kU8 && formatChannels(m_info.format) == nch;
    const bool direct = fast_copy && x0 == 0 && width == m_info.width_px;
    m_row.resize(size_t(m_info.width_px) * np);
    while (m_decoder->nextRow() < y0) {
      Status s = m_decoder->readRow(m_row.data());
      if (!s) return s;
    }
    for (uint32_t r = 0; r < rows; ++r) {
      uint8_t* out = dst + size_t(r) * dst_stride;
      Status s = m_decoder->readRow(direct ? out : m_row.data());
      if (!s) return s;
      if (!direct) {
        convertNativeRow(m_kind, m_row.data() + x0 * np, nch, width, m_info.format, fast_copy, out,
                         &m_info.clamped_samples);
      }
    }
    return okStatus();
  }

 private:
  std::string m_path;
  SourceInfo m_info;
  pixel_convert::SampleKind m_kind;
  std::unique_ptr<Decoder> m_decoder;  // started
  Restart m_restart;
  std::vector<uint8_t> m_row;
};

}  // namespace clipstream
