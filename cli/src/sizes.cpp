// Viewport-size option values. See sizes.h.
#include <clipstream/cli/sizes.h>

namespace clipstream::cli {

Status parseSize(const std::string& text, uint32_t* width_px, uint32_t* height_px) {
  const size_t sep = text.find('x');
  uint64_t side[2] = {0, 0};
  bool digits = sep != std::string::npos && sep > 0 && sep + 1 < text.size();
  for (size_t i = 0; digits && i < text.size(); ++i) {
    if (i == sep) continue;
    if (text[i] < '0' || text[i] > '9') digits = false;
    uint64_t& v = side[i < sep ? 0 : 1];
    if (digits && v <= kMaxSizeSidePx) v = v * 10 + uint64_t(text[i] - '0');
  }
  if (!digits)
    return Status::error(ErrorCode::kInvalidArgument,
                         "size \"" + printableText(text, 40) + "\" is not WIDTHxHEIGHT (e.g. 1280x720)");
  if (side[0] == 0 || side[1] == 0 || side[0] > kMaxSizeSidePx || side[1] > kMaxSizeSidePx)
    return Status::error(ErrorCode::kInvalidArgument,
                         "size \"" + printableText(text, 40) + "\": each side must be from 1 to " +
                             std::to_string(kMaxSizeSidePx) + " px");
  *width_px = uint32_t(side[0]);
  *height_px = uint32_t(side[1]);
  return okStatus();
}

Status parseResize(const std::string& text, uint32_t max_frame, uint32_t* frame, uint32_t* width_px,
                   uint32_t* height_px) {
  const size_t colon = text.find(':');
  const std::string digits = colon == std::string::npos ? std::string() : text.substr(0, colon);
  if (digits.empty() || digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos ||
      std::stoul(digits) == 0 || std::stoul(digits) > max_frame)
    return Status::error(ErrorCode::kInvalidArgument,
                         "resize \"" + printableText(text, 40) +
                             "\" is not FRAME:WIDTHxHEIGHT with FRAME from 1 to " + std::to_string(max_frame) +
                             " (e.g. 120:640x360)");
  if (Status s = parseSize(text.substr(colon + 1), width_px, height_px); !s) return s;
  *frame = uint32_t(std::stoul(digits));
  return okStatus();
}

}  // namespace clipstream::cli
