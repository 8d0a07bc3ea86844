# Stores over HTTP against GDAL /vsicurl/ on a COG (docs/benchmarks.md).
add_executable(bench_store_http ${CMAKE_CURRENT_LIST_DIR}/store_http.cpp)
target_link_libraries(bench_store_http PRIVATE clipstream_net_testing clipstream::streamer
  clipstream::store clipstream_warnings)
target_compile_definitions(bench_store_http PRIVATE
  CLIPSTREAM_GDAL_SCRIPT="${CMAKE_CURRENT_LIST_DIR}/gdal_read_windows.py")
