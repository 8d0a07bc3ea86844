// Compiles: the one right way to check a Status (tests/store/CMakeLists.txt
// compiles this file and expects success; status_static_ok.cpp, the same
// with the old static factory, must fail).
#include <clipstream/store/types.h>

clipstream::Status open(bool fail) {
  if (fail) return clipstream::Status::error(clipstream::ErrorCode::kNotFound, "no such store");
  return clipstream::okStatus();
}

int main() {
  const clipstream::Status st = open(true);
  if (!st.ok()) return 1;
  return 0;
}
