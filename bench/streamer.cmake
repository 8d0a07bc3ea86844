# streamer benchmarks: programs that print tab-separated tables.
add_executable(bench_streamer_throughput ${CMAKE_CURRENT_LIST_DIR}/streamer_throughput.cpp)
target_link_libraries(bench_streamer_throughput PRIVATE clipstream::streamer clipstream::store
  zstd::libzstd_shared clipstream_warnings)

add_executable(bench_streamer_hitrate ${CMAKE_CURRENT_LIST_DIR}/streamer_hitrate.cpp)
target_link_libraries(bench_streamer_hitrate PRIVATE clipstream::streamer clipstream_warnings)

add_executable(bench_streamer_bc1 ${CMAKE_CURRENT_LIST_DIR}/streamer_bc1.cpp)
target_link_libraries(bench_streamer_bc1 PRIVATE clipstream::streamer clipstream_warnings)

add_executable(bench_streamer_plan ${CMAKE_CURRENT_LIST_DIR}/streamer_plan.cpp)
target_link_libraries(bench_streamer_plan PRIVATE clipstream::streamer clipstream_warnings)
