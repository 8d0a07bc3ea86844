// Status formatting and printableText() (status.h). No I/O here.
#include <clipstream/util/status.h>

#include <algorithm>

namespace clipstream {

const char* errorCodeName(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk: return "ok";
    case ErrorCode::kIo: return "I/O error";
    case ErrorCode::kNotFound: return "not found";
    case ErrorCode::kTruncated: return "truncated";
    case ErrorCode::kBadMagic: return "bad magic";
    case ErrorCode::kBadVersion: return "bad version";
    case ErrorCode::kBadHeader: return "bad header";
    case ErrorCode::kCorruptIndex: return "corrupt index";
    case ErrorCode::kCorruptTile: return "corrupt tile";
    case ErrorCode::kOutOfRange: return "out of range";
    case ErrorCode::kInvalidArgument: return "invalid argument";
    case ErrorCode::kUnsupported: return "unsupported";
    case ErrorCode::kNoSpace: return "no space";
    case ErrorCode::kCancelled: return "cancelled";
    case ErrorCode::kUnavailable: return "unavailable";
    case ErrorCode::kAlreadyExists: return "already exists";
    case ErrorCode::kOutOfMemory: return "out of memory";
  }
  return "unknown error";
}

std::string Status::toString() const {
  if (ok()) return "ok";
  std::string text = errorCodeName(code);
  if (!message.empty()) {
    text += ": ";
    text += message;
  }
  return text;
}

std::string printableText(const std::string& text, size_t max_bytes) {
  // Walks UTF-8: printable characters pass (names in any script); C0 and C1
  // controls, DEL, bidirectional overrides (U+202A-202E, U+2066-2069) and
  // bytes that are not valid UTF-8 (a raw 0x9B is a terminal's CSI) become '?'.
  std::string out;
  const size_t n = std::min(text.size(), max_bytes);
  size_t i = 0;
  while (i < n) {
    const auto b0 = static_cast<unsigned char>(text[i]);
    size_t len = b0 < 0x80 ? 1 : (b0 >> 5) == 0x6 ? 2 : (b0 >> 4) == 0xe ? 3 : (b0 >> 3) == 0x1e ? 4 : 0;
    uint32_t cp = len == 1 ? b0 : len == 2 ? (b0 & 0x1f) : len == 3 ? (b0 & 0x0f) : (b0 & 0x07);
    bool valid = len > 0 && i + len <= n;
    for (size_t k = 1; valid && k < len; ++k) {
      const auto b = static_cast<unsigned char>(text[i + k]);
      valid = (b & 0xc0) == 0x80;
      cp = (cp << 6) | (b & 0x3f);
    }
    const bool control = cp < 0x20 || (cp >= 0x7f && cp < 0xa0) || (cp >= 0x202a && cp <= 0x202e) ||
                         (cp >= 0x2066 && cp <= 0x2069);
    if (!valid || control) {
      out += '?';
      i += valid ? len : 1;
    } else {
      out.append(text, i, len);
      i += len;
    }
  }
  if (text.size() > max_bytes) out += "...";
  return out;
}

}  // namespace clipstream
