// Whether this test binary runs under a sanitizer. Their runtimes add
// memory of their own (shadow, allocator, reserved address space), so
// checks of a memory budget or an address-space limit are only meaningful
// in plain builds.
#pragma once

namespace clipstream::test {

#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif

}  // namespace clipstream::test
