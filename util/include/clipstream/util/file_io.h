// Positional file I/O that loops over short transfers and turns errno into
// a Status naming the file: what the store's reader and writer and
// OutputFile read and write with.
//
// Thread-safe: each call works on the descriptor it is given (positional
// reads and writes do not move a shared offset).
#pragma once

#include <clipstream/util/status.h>

#include <cstdint>
#include <string>

namespace clipstream::fileio {

// Reads exactly `bytes` at `offset`; kTruncated if the file ends first.
Status preadAll(int fd, void* data, size_t bytes, uint64_t offset, const std::string& path);
// Writes exactly `bytes` at `offset`; kNoSpace on ENOSPC/EDQUOT/EFBIG, else kIo.
Status pwriteAll(int fd, const void* data, size_t bytes, uint64_t offset,
                 const std::string& path);
// Copies `bytes` from the start of `from_fd` to `to_fd` at `to_offset`.
Status copyRange(int from_fd, const std::string& from_path, uint64_t bytes, int to_fd,
                 uint64_t to_offset, const std::string& to_path);
std::string errnoText(int err);

}  // namespace clipstream::fileio
