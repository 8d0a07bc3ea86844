// Private: where a TileStoreReader's bytes come from. A local file (pread
// on one descriptor) or a URL (HTTP range requests, http_source.cpp). The
// reader parses; a byte source only moves bytes and names its failures.
#pragma once

#include <clipstream/store/remote.h>
#include <clipstream/store/types.h>

#include <cstdint>
#include <memory>
#include <string>

namespace clipstream {

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
