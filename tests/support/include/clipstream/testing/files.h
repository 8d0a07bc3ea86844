// Whole-file reads and writes for tests that build, damage or inspect files
// byte by byte. A file that cannot be opened, read or written is a test
// failure (ADD_FAILURE naming the path), never a silent empty result.
//
// Thread rule: plain functions; any thread, one writer per path at a time.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace clipstream::test {

std::vector<uint8_t> readBytes(const std::string& path);
std::string readText(const std::string& path);

// Replaces `path` with exactly `bytes`. The old file is unlinked first:
// truncating an existing file makes ext4 flush it on close (auto_da_alloc),
// which turns thousands of rewrites in a damage loop into seconds of I/O.
void writeBytes(const std::string& path, std::span<const uint8_t> bytes);

}  // namespace clipstream::test
