// Private: where a TileStoreReader's bytes come from. A local file (pread
// on one descriptor) or a URL (HTTP range requests, http_source.cpp). The
// reader parses; a byte source only moves bytes and names its failures.
#pragma once

#include <clipstream/store/remote.h>
#include <clipstream/store/types.h>

#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace clipstream {

// One range of a ByteSource::readMany() call: `bytes` bytes at `offset`
// into `data` (owned by the caller).
struct ByteRange {
  void* data = nullptr;
  size_t bytes = 0;
  uint64_t offset = 0;
};

// Thread-safe: read() and the counters from any number of threads at once,
// no lock held across I/O. prefetch() only while the reader is being opened
// (one thread, before any concurrent read).
class ByteSource {
 public:
  virtual ~ByteSource() = default;

  // Size of the file in bytes, as found when it was opened.
  virtual uint64_t size() const = 0;

  // Reads exactly `bytes` at `offset` into `data`. kTruncated if the file
  // ends first; kIo / kNotFound / kUnavailable (transient, may be retried)
  // with a message naming the path or URL.
  virtual Status read(void* data, size_t bytes, uint64_t offset) const = 0;

  // read() for several ranges: statuses[i] for ranges[i] (spans of equal
  // size). A remote source has them all in flight at once (HTTP/2 streams
  // on one connection, or several connections), so together they cost one
  // round trip; a local file reads them one after another.
  virtual void readMany(std::span<const ByteRange> ranges, std::span<Status> statuses) const {
    for (size_t i = 0; i < ranges.size() && i < statuses.size(); ++i)
      statuses[i] = read(ranges[i].data, ranges[i].bytes, ranges[i].offset);
  }

  // What names this version of the file, "" when nothing does: for a URL
  // the strong ETag, else the Last-Modified date, with the size. Constant
  // from open on. The disk cache keys its entries by URL and this.
  virtual std::string version() const { return {}; }

  // A hint that [offset, offset + bytes) is read next in small pieces: a
  // remote source fetches it in one request and serves those reads from
  // memory. Failures are ignored (the reads then go to the medium).
  virtual void prefetch(uint64_t offset, uint64_t bytes) {
    (void)offset;
    (void)bytes;
  }

  // Loader threads worth running against this source; 0 = no preference.
  virtual unsigned suggestedReadThreads() const { return 0; }

  virtual RemoteStats remoteStats() const { return {}; }
};

// Opens `path` as a local regular file (anything else is refused with a
// message saying what it is). Fills *size_out-independent state only.
Status openFileSource(const std::string& path, std::unique_ptr<ByteSource>* out);

// Opens an http:// or https:// URL: one range request for the first bytes,
// which records the size and the validators (ETag, Last-Modified) that every
// later request is checked against.
Status openHttpSource(const std::string& url, const RemoteOptions& options,
                      std::unique_ptr<ByteSource>* out);

}  // namespace clipstream
