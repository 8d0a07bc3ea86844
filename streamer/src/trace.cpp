// Trace lines written and read: one definition of each line format. The
// replay against cache policies is trace_replay.cpp.
#include <clipstream/streamer/trace.h>

#include "trace_line.h"

#include <sys/stat.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string_view>
#include <type_traits>

namespace clipstream {

static_assert(std::string_view(kTraceHeader).starts_with(kTraceMagic),
              "the header line starts with the magic");
static_assert(std::string_view(kTraceHeader).substr(std::string_view(kTraceMagic).size(), 2) ==
                  "2:" && kTraceVersion == 2,
              "the header line names kTraceVersion");

namespace {

// The line formats as readTrace() names them in its messages.
constexpr const char* kTileLineFormat = "'frame level x y'";
constexpr const char* kWindowLineFormat = "'w|p frame level x0 y0 x1 y1 kind'";
constexpr const char* kTimeLineFormat = "'t frame seconds 0|1 width height'";

void appendFields(std::string* out) { *out += '\n'; }

// " a b c...\n": every field preceded by one space, then the newline.
template <typename T, typename... Rest>
void appendFields(std::string* out, T value, Rest... rest) {
  *out += ' ';
  if constexpr (std::is_same_v<T, const char*>) {
    *out += value;
  } else {
    *out += std::to_string(value);
  }
  appendFields(out, rest...);
}

}  // namespace

void appendTraceLine(const TraceEvent& e, std::string* out) {
  switch (e.window) {
    case kTraceTimeTag: {
      // Exact time: the replay re-plans the path hint at it.
      char time_text[32];
      std::snprintf(time_text, sizeof time_text, "%.17g", std::isfinite(e.time_s) ? e.time_s : 0.0);
      *out += kTraceTimeTag;
      appendFields(out, e.frame, static_cast<const char*>(time_text), unsigned(e.kind),
                   e.viewport.width_px, e.viewport.height_px);
      return;
    }
    case kTraceWindowTag:
    case kTracePredictedTag:
      *out += e.window;
      appendFields(out, e.frame, e.key.level, e.rect.x0, e.rect.y0, e.rect.x1, e.rect.y1,
                   unsigned(e.kind));
      return;
    default:
      // A tile entry starts with its frame, a leave with its tag.
      if (e.leave) {
        *out += kTraceLeaveTag;
        *out += ' ';
      }
      *out += std::to_string(e.frame);
      appendFields(out, e.key.level, e.key.x, e.key.y);
      return;
  }
}

namespace {

// The message for line line_no of `path`, which does not parse as
// `expected`: it shows at most 80 bytes of the line, control bytes as '?'.
Status lineError(const std::string& path, uint64_t line_no, const std::string& expected,
                 const std::string& line) {
  return Status::error(ErrorCode::kInvalidArgument, path + ":" + std::to_string(line_no) +
                                                        ": expected " + expected + ", got '" +
                                                        printableText(line, 80) + "'");
}

// What stat() says of `path` before it is opened: a file that is not a
// regular one is refused (kIo), and so is one larger than any trace read
// here (kInvalidArgument). A path stat() cannot see is left to the open.
Status checkTraceFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    return Status::error(ErrorCode::kIo, "trace " + path + " is not a regular file");
  }
  if (uint64_t(st.st_size) > kMaxTraceFileBytes) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "trace " + path + " is " + std::to_string(uint64_t(st.st_size) >> 20) +
                             " MiB, larger than any trace read here (" +
                             std::to_string(kMaxTraceFileBytes >> 20) + " MiB at most)");
  }
  return okStatus();
}

// The first bytes name the format: checked before reading a line, so a
// huge file of another kind is refused at once, not read whole. Leaves
// `in` at its start.
Status checkTraceMagic(std::ifstream& in, const std::string& path) {
  char head[20] = {};
  in.read(head, sizeof head);
  const std::string got(head, size_t(in.gcount()));
  const std::string magic = kTraceMagic;
  if (got.empty()) {
    if (in.bad()) return Status::error(ErrorCode::kIo, "error reading trace " + path);
    return Status::error(ErrorCode::kInvalidArgument, path + " is empty, not a clipstream trace");
  }
  if (got != magic.substr(0, got.size()) || got.size() < magic.size())
    return lineError(path, 1, "the header '" + magic + std::to_string(kTraceVersion) + "...'", got);
  in.clear();
  in.seekg(0);
  return okStatus();
}

// The first line names the format: an empty file or another file is not a
// trace, another version is kUnsupported. Reads that line from `in`.
Status readTraceHeader(std::ifstream& in, const std::string& path) {
  std::string line;
  if (!std::getline(in, line)) {
    if (in.bad()) return Status::error(ErrorCode::kIo, "error reading trace " + path);
    return Status::error(ErrorCode::kInvalidArgument, path + " is empty, not a clipstream trace");
  }
  const std::string magic = kTraceMagic;
  const std::string version = std::to_string(kTraceVersion);
  if (line.compare(0, magic.size(), magic) != 0) {
    return lineError(path, 1, "the header '" + magic + version + "...'", line);
  }
  if (line.compare(0, magic.size() + version.size() + 1, magic + version + ":") != 0) {
    return Status::error(ErrorCode::kUnsupported,
                         path + ": trace format '" + printableText(line, 24) + "' is not v" +
                             std::to_string(kTraceVersion));
  }
  return okStatus();
}

// "w|p F L X0 Y0 X1 Y1 K" after its tag, into *e; false when it does not parse.
bool parseWindowFields(std::istringstream& fields, TraceEvent* e) {
  uint64_t level = 0;
  int kind = 0;
  if (!(fields >> e->frame >> level >> e->rect.x0 >> e->rect.y0 >> e->rect.x1 >> e->rect.y1 >> kind) ||
      level > 63 || kind < 0 || kind > 2) {
    return false;
  }
  e->key.level = uint32_t(level);
  e->kind = uint8_t(kind);
  return true;
}

// "t F T H W V" after its tag, into *e; false when it does not parse.
bool parseTimeFields(std::istringstream& fields, TraceEvent* e) {
  int used = 0;
  uint64_t width = 0, height = 0;
  if (!(fields >> e->frame >> e->time_s >> used >> width >> height) || !std::isfinite(e->time_s) ||
      used < 0 || used > 1 || width > UINT32_MAX || height > UINT32_MAX) {
    return false;
  }
  e->kind = uint8_t(used);
  e->viewport = {uint32_t(width), uint32_t(height)};
  return true;
}

// "F L X Y" (after the leave tag, if any), into *e; false when it does not parse.
bool parseTileFields(std::istringstream& fields, TraceEvent* e) {
  uint64_t level = 0, x = 0, y = 0;
  if (!(fields >> e->frame >> level >> x >> y) || level > 63 || x > UINT32_MAX || y > UINT32_MAX) {
    return false;
  }
  e->key = {uint32_t(level), uint32_t(x), uint32_t(y)};
  return true;
}

}  // namespace

const char* parseTraceLine(const std::string& line, TraceEvent* event) {
  std::istringstream fields(line);
  TraceEvent e;
  if (line[0] == kTraceWindowTag || line[0] == kTracePredictedTag) {
    e.window = line[0];
    fields.get();
    if (!parseWindowFields(fields, &e)) return kWindowLineFormat;
  } else if (line[0] == kTraceTimeTag) {
    e.window = kTraceTimeTag;
    fields.get();
    if (!parseTimeFields(fields, &e)) return kTimeLineFormat;
  } else {
    if (line[0] == kTraceLeaveTag) {
      e.leave = true;
      fields.get();
    }
    if (!parseTileFields(fields, &e)) return kTileLineFormat;
  }
  *event = e;
  return nullptr;
}

Status readTrace(const std::string& path, std::vector<TraceEvent>* events) {
  events->clear();
  Status status = checkTraceFile(path);
  if (!status.ok()) return status;
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Status::error(errno == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                         "cannot open trace " + path + ": " + std::strerror(errno));
  }
  status = checkTraceMagic(in, path);
  if (!status.ok()) return status;
  status = readTraceHeader(in, path);
  if (!status.ok()) return status;
  std::string line;
  uint64_t line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    // Every line the streamer writes ends in a newline: a last line without
    // one is a trace cut short (a crash, a full disk).
    if (in.eof()) {
      return Status::error(ErrorCode::kTruncated,
                           path + ":" + std::to_string(line_no) +
                               ": the trace ends in the middle of a line (truncated)");
    }
    if (line.empty() || line[0] == kTraceCommentTag) continue;
    TraceEvent e;
    if (const char* expected = parseTraceLine(line, &e)) return lineError(path, line_no, expected, line);
    events->push_back(e);
  }
  if (in.bad()) return Status::error(ErrorCode::kIo, "error reading trace " + path);
  return okStatus();
}

}  // namespace clipstream
