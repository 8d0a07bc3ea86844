// Shared by the libFuzzer drivers (tests/fuzz): a per-process scratch path
// for the parsers that read files, and seed writing.
//
// Every driver follows one convention: run with CLIPSTREAM_FUZZ_SEEDS=DIR
// and -runs=0 it writes its seed inputs into DIR (from the project's own
// writers or the codec libraries), then exits; run on DIR it fuzzes.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace clipstream::fuzz {

// A file name of this process under $TMPDIR (else /tmp).
inline std::string scratchPath(const std::string& name) {
  const char* dir = std::getenv("TMPDIR");
  return std::string(dir ? dir : "/tmp") + "/clipstream_fuzz_" + std::to_string(::getpid()) + "_" + name;
}

// Writes `size` bytes to `path` (aborts on failure: the fuzzer's own fault).
inline void writeFile(const std::string& path, const uint8_t* data, size_t size) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, file) != size) std::abort();
  if (std::fclose(file) != 0) std::abort();
}
inline void writeFile(const std::string& path, const std::string& text) {
  writeFile(path, reinterpret_cast<const uint8_t*>(text.data()), text.size());
}

inline std::vector<uint8_t> readFile(const std::string& path) {
  std::vector<uint8_t> bytes;
  std::FILE* in = std::fopen(path.c_str(), "rb");
  if (in == nullptr) std::abort();
  for (int c; (c = std::fgetc(in)) != EOF;) bytes.push_back(uint8_t(c));
  std::fclose(in);
  return bytes;
}

// The seed folder, if this run writes seeds.
inline const char* seedDir() { return std::getenv("CLIPSTREAM_FUZZ_SEEDS"); }

}  // namespace clipstream::fuzz
