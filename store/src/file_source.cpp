// ByteSource over a local regular file: one descriptor, positional reads.
#include "byte_source.h"
#include <clipstream/util/file_io.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>

namespace clipstream {
namespace {

class FileSource final : public ByteSource {
 public:
  FileSource(std::string path, int fd, uint64_t size)
      : m_path(std::move(path)), m_fd(fd), m_size(size) {}
  ~FileSource() override { ::close(m_fd); }

  uint64_t size() const override { return m_size; }
  Status read(void* data, size_t bytes, uint64_t offset) const override {
    return fileio::preadAll(m_fd, data, bytes, offset, m_path);
  }

 private:
  const std::string m_path;
  const int m_fd;
  const uint64_t m_size;
};

}  // namespace

Status openFileSource(const std::string& path, std::unique_ptr<ByteSource>* out) {
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a
  // writer forever; the regular-file check below comes before any read.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd < 0) {
    const int err = errno;
    return Status::error(err == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                         "cannot open " + path + ": " + fileio::errnoText(err));
  }
  auto fail = [&](const std::string& what) {
    ::close(fd);
    return Status::error(ErrorCode::kIo, path + ": " + what);
  };
  struct stat file_stat {};
  if (::fstat(fd, &file_stat) != 0) return fail(std::string("fstat: ") + fileio::errnoText(errno));
  if (S_ISDIR(file_stat.st_mode)) return fail("is a directory, not a tile store");
  if (!S_ISREG(file_stat.st_mode)) {
    return fail(std::string(S_ISFIFO(file_stat.st_mode)   ? "is a FIFO"
                            : S_ISCHR(file_stat.st_mode) ? "is a character device"
                            : S_ISBLK(file_stat.st_mode) ? "is a block device"
                            : S_ISSOCK(file_stat.st_mode) ? "is a socket"
                                                           : "is not a regular file") +
                ", not a tile store (only regular files are read)");
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  *out = std::make_unique<FileSource>(path, fd, static_cast<uint64_t>(file_stat.st_size));
  return okStatus();
}

}  // namespace clipstream
