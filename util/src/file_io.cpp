#include <clipstream/util/file_io.h>

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <vector>

namespace clipstream::fileio {

std::string errnoText(int err) { return std::strerror(err); }

Status preadAll(int fd, void* data, size_t bytes, uint64_t offset, const std::string& path) {
  auto* out = static_cast<uint8_t*>(data);
  size_t done = 0;
  while (done < bytes) {
    const ssize_t got = ::pread(fd, out + done, bytes - done, static_cast<off_t>(offset + done));
    if (got < 0) {
      if (errno == EINTR) continue;
      return Status::error(ErrorCode::kIo, "reading " + path + " at byte " +
                                               std::to_string(offset + done) + ": " +
                                               errnoText(errno));
    }
    if (got == 0) {
      return Status::error(ErrorCode::kTruncated,
                           path + " ends at byte " + std::to_string(offset + done) +
                               ", needed " + std::to_string(bytes) + " bytes from byte " +
                               std::to_string(offset));
    }
    done += static_cast<size_t>(got);
  }
  return okStatus();
}

Status pwriteAll(int fd, const void* data, size_t bytes, uint64_t offset,
                 const std::string& path) {
  const auto* in = static_cast<const uint8_t*>(data);
  size_t done = 0;
  while (done < bytes) {
    const ssize_t put = ::pwrite(fd, in + done, bytes - done, static_cast<off_t>(offset + done));
    if (put < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      if (err == ENOSPC || err == EDQUOT) {
        return Status::error(ErrorCode::kNoSpace, "no space left on device writing " + path +
                                                      " (" + std::to_string(bytes - done) +
                                                      " more bytes needed)");
      }
      if (err == EFBIG) {
        return Status::error(ErrorCode::kNoSpace, "writing " + path + ": " + errnoText(err) +
                                                      " (the file-size limit, ulimit -f)");
      }
      return Status::error(ErrorCode::kIo, "writing " + path + ": " + errnoText(err));
    }
    done += static_cast<size_t>(put);
  }
  return okStatus();
}

Status copyRange(int from_fd, const std::string& from_path, uint64_t bytes, int to_fd,
                 uint64_t to_offset, const std::string& to_path) {
  // Plain read/write in 4 MiB chunks: bounded memory, works on every
  // filesystem (copy_file_range is not available everywhere).
  constexpr size_t kChunkBytes = size_t(4) << 20;
  std::vector<uint8_t> buffer(static_cast<size_t>(std::min<uint64_t>(bytes, kChunkBytes)));
  uint64_t done = 0;
  while (done < bytes) {
    const size_t chunk = static_cast<size_t>(std::min<uint64_t>(bytes - done, kChunkBytes));
    Status status = preadAll(from_fd, buffer.data(), chunk, done, from_path);
    if (!status) return status;
    status = pwriteAll(to_fd, buffer.data(), chunk, to_offset + done, to_path);
    if (!status) return status;
    done += chunk;
  }
  return okStatus();
}

}  // namespace clipstream::fileio
