#!/usr/bin/env bash
# The whole test suite, from a fresh Debian 12 machine: installs what is
# missing, builds, runs every test, then builds the concurrent components
# (store, streamer) under ThreadSanitizer and runs their tests again.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh

jobs=$(nproc)
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
cmake --build build -j "$jobs"
ctest --test-dir build --output-on-failure -j "$jobs" --timeout 900

echo "== ThreadSanitizer build of the store and streamer tests =="
cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCLIPSTREAM_SANITIZE=thread -DCLIPSTREAM_BUILD_RENDERER=OFF -DCLIPSTREAM_BUILD_BENCH=OFF
cmake --build build-tsan -j "$jobs" --target test_store test_streamer
TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" \
  ctest --test-dir build-tsan -L 'store|streamer' --output-on-failure -j "$jobs" --timeout 900
