// Reads the process's memory figures from /proc/self/status (Linux).
#include <clipstream/util/process_memory.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace clipstream {
namespace {

// The value of a "Field:   1234 kB" line, in bytes; 0 if absent or unreadable.
uint64_t statusFieldBytes(const char* field) {
  std::FILE* file = std::fopen("/proc/self/status", "re");
  if (file == nullptr) return 0;
  const size_t field_len = std::strlen(field);
  uint64_t kb = 0;
  char line[256];
  while (std::fgets(line, sizeof line, file) != nullptr) {
    if (std::strncmp(line, field, field_len) == 0) {
      kb = std::strtoull(line + field_len, nullptr, 10);
      break;
    }
  }
  std::fclose(file);
  return kb * 1024;
}

}  // namespace

uint64_t currentRssBytes() { return statusFieldBytes("VmRSS:"); }
uint64_t peakRssBytes() { return statusFieldBytes("VmHWM:"); }

}  // namespace clipstream
