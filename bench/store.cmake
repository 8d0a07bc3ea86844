# store benchmarks: predictor/zstd gain on real imagery, and tile read
# throughput. They read /work/shared/data through CLIPSTREAM_STORE_BENCH_DATA
# (default ../shared/data next to the source tree) and print tables.
set(CLIPSTREAM_STORE_BENCH_DATA "${CMAKE_SOURCE_DIR}/../shared/data" CACHE PATH
  "Folder with autzen.jpg, fg_globe_colors_8192x4096.jpg, mt_rainier_90m.tif for store benchmarks")
pkg_check_modules(STORE_BENCH_OIIO IMPORTED_TARGET OpenImageIO)
if(STORE_BENCH_OIIO_FOUND)
  add_executable(store_predictor_bench ${CMAKE_CURRENT_SOURCE_DIR}/store_predictor.cpp)
  target_link_libraries(store_predictor_bench PRIVATE clipstream::store PkgConfig::STORE_BENCH_OIIO
    clipstream_warnings)
  target_compile_definitions(store_predictor_bench PRIVATE
    CLIPSTREAM_STORE_BENCH_DATA="${CLIPSTREAM_STORE_BENCH_DATA}")
endif()
if(STORE_BENCH_OIIO_FOUND)
  add_executable(store_read_bench ${CMAKE_CURRENT_SOURCE_DIR}/store_read.cpp)
  target_link_libraries(store_read_bench PRIVATE clipstream::store PkgConfig::STORE_BENCH_OIIO
    clipstream_warnings)
  target_compile_definitions(store_read_bench PRIVATE
    CLIPSTREAM_STORE_BENCH_DATA="${CLIPSTREAM_STORE_BENCH_DATA}")
endif()

# Reader fuzz driver, only with -DCLIPSTREAM_FUZZ=ON (option in store/). It
# uses the private format helpers to re-seal checksums after mutation.
#   CLIPSTREAM_FUZZ_SEEDS=corpus ./store_fuzz -runs=0   # seed stores
#   ./store_fuzz -max_total_time=300 -timeout=10 corpus
if(CLIPSTREAM_FUZZ)
  add_executable(store_fuzz ${CMAKE_CURRENT_SOURCE_DIR}/store_fuzz.cpp)
  target_include_directories(store_fuzz PRIVATE ${CMAKE_SOURCE_DIR}/store/src)
  target_compile_options(store_fuzz PRIVATE -fsanitize=fuzzer)
  target_link_options(store_fuzz PRIVATE -fsanitize=fuzzer)
  target_link_libraries(store_fuzz PRIVATE clipstream::store clipstream_warnings)
endif()
