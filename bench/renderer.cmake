# renderer benchmarks: programs that print tab-separated tables (best-of-N).
find_package(OpenGL REQUIRED COMPONENTS OpenGL)
add_executable(bench_renderer_frame ${CMAKE_CURRENT_LIST_DIR}/renderer_frame.cpp)
target_link_libraries(bench_renderer_frame PRIVATE clipstream::renderer clipstream_warnings
  OpenGL::OpenGL)


add_executable(bench_renderer_buffering ${CMAKE_CURRENT_LIST_DIR}/renderer_buffering.cpp)
target_link_libraries(bench_renderer_buffering PRIVATE clipstream::renderer clipstream_warnings
  OpenGL::OpenGL)
