// The Status every fallible call of the project returns: an error category
// and a message that names the problem, and printableText() for the
// untrusted text such messages quote.
//
// Thread-safe: plain data and pure functions only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>

namespace clipstream {

// Error categories. Bad data is never an assert: it is one of these.
enum class ErrorCode : uint32_t {
  kOk = 0,
  kIo,             // open/read/write/rename failed (errno text in message)
  kNotFound,       // file does not exist
  kTruncated,      // file shorter than its structures say
  kBadMagic,       // not a clipstream tile store
  kBadVersion,     // a format version this reader does not know
  kBadHeader,      // header fields inconsistent or checksum wrong
  kCorruptIndex,   // an index page or level table failed its checksum or bounds
  kCorruptTile,    // a tile payload failed its checksum or did not decode
  kOutOfRange,     // a tile key outside the pyramid
  kInvalidArgument,
  kUnsupported,    // valid input of a kind we do not handle (pixel type, ...)
  kNoSpace,        // disk full
  kCancelled,
  kUnavailable,    // transient source failure (e.g. injected), may be retried
  kAlreadyExists,  // an output path is taken by a file this program may not replace
  kOutOfMemory,    // an allocation failed (std::bad_alloc): the input or the budget is too large
};
const char* errorCodeName(ErrorCode code);

// Result of a fallible call: a code plus a message that names the problem
// (file, tile, field) in words a user can act on. Check it with ok() (or
// in a condition: `if (!status)`); a success is okStatus(), a failure
// Status::error(). No static member reads like a query: `status.ok()` is
// always the question "did it succeed" (tests/store/test_format.cpp pins
// it at compile time).
struct [[nodiscard]] Status {
  ErrorCode code = ErrorCode::kOk;
  std::string message;

  static Status error(ErrorCode c, std::string msg) { return {c, std::move(msg)}; }
  [[nodiscard]] bool ok() const { return code == ErrorCode::kOk; }
  explicit operator bool() const { return ok(); }
  std::string toString() const;  // "corrupt tile: level 3 tile (4, 7): checksum mismatch"
};

// A success.
inline Status okStatus() { return {}; }

// Untrusted text (from a file, a command line) made safe to show on a
// terminal or in a message: C0 and C1 controls (newlines, escapes, NUL),
// bidirectional overrides and bytes that are not valid UTF-8 become '?';
// printable UTF-8 passes. Longer than max_bytes is cut and marked "...".
std::string printableText(const std::string& text, size_t max_bytes = SIZE_MAX);

}  // namespace clipstream
