# Tiler benchmark helpers; scripts/bench_tile.sh runs the comparison.
find_package(PkgConfig REQUIRED)
pkg_check_modules(OIIO_BENCH REQUIRED IMPORTED_TARGET OpenImageIO)
add_executable(tiler_make_input ${CMAKE_CURRENT_SOURCE_DIR}/tiler_make_input.cpp)
target_link_libraries(tiler_make_input PRIVATE clipstream::tiler PkgConfig::OIIO_BENCH clipstream_warnings)
add_executable(tiler_filter_quality ${CMAKE_CURRENT_SOURCE_DIR}/tiler_filter_quality.cpp)
target_link_libraries(tiler_filter_quality PRIVATE clipstream::store PkgConfig::OIIO_BENCH clipstream_warnings)
add_executable(tiler_decode ${CMAKE_CURRENT_SOURCE_DIR}/tiler_decode.cpp)
target_link_libraries(tiler_decode PRIVATE clipstream::tiler clipstream_warnings)
