# renderer benchmarks: programs that print tab-separated tables (best-of-N).
find_package(OpenGL REQUIRED COMPONENTS OpenGL)

# The plain-texture baseline of bench_renderer_frame: a comparison method,
# built here from the renderer's private GL helpers and ray shader, with its
# own fragment shader embedded like the renderer's.
set(plain_shader ${CMAKE_CURRENT_LIST_DIR}/shaders/ground_plain.frag)
set(plain_shader_cpp ${CMAKE_CURRENT_BINARY_DIR}/plain_shaders_embedded.cpp)
add_custom_command(
  OUTPUT ${plain_shader_cpp}
  COMMAND ${CMAKE_COMMAND} -DOUT=${plain_shader_cpp} -DINPUTS=${plain_shader} -DHEADER=plain_shaders.h
          -P ${PROJECT_SOURCE_DIR}/renderer/cmake/embed_shaders.cmake
  DEPENDS ${plain_shader} ${PROJECT_SOURCE_DIR}/renderer/cmake/embed_shaders.cmake
  COMMENT "Embedding the plain-texture baseline's shader"
  VERBATIM)
add_executable(bench_renderer_frame ${CMAKE_CURRENT_LIST_DIR}/renderer_frame.cpp
  ${CMAKE_CURRENT_LIST_DIR}/plain_texture_renderer.cpp ${plain_shader_cpp})
target_include_directories(bench_renderer_frame PRIVATE ${CMAKE_CURRENT_LIST_DIR}
  ${PROJECT_SOURCE_DIR}/renderer/src)
target_link_libraries(bench_renderer_frame PRIVATE clipstream::renderer clipstream::cli
  clipstream_warnings OpenGL::OpenGL)

add_executable(bench_renderer_buffering ${CMAKE_CURRENT_LIST_DIR}/renderer_buffering.cpp)
target_link_libraries(bench_renderer_buffering PRIVATE clipstream::renderer clipstream::cli clipstream_warnings
  OpenGL::OpenGL)

# Whether a smaller clip changes the picture at rest (the ideal reference).
add_executable(bench_renderer_clip_size ${CMAKE_CURRENT_LIST_DIR}/renderer_clip_size.cpp)
target_link_libraries(bench_renderer_clip_size PRIVATE clipstream::renderer clipstream::eval clipstream::cli
  clipstream_warnings)

# Sampling cost of RGBA8, BC1 and BC7 stacks on this GL (docs/benchmarks.md,
# "Sampling cost of block formats on llvmpipe"); its own pass, built with the
# renderer's private program helper.
add_executable(bench_renderer_sampling ${CMAKE_CURRENT_LIST_DIR}/renderer_sampling.cpp)
target_include_directories(bench_renderer_sampling PRIVATE ${PROJECT_SOURCE_DIR}/renderer/src)
target_link_libraries(bench_renderer_sampling PRIVATE clipstream::renderer clipstream::streamer clipstream::cli
  clipstream_warnings OpenGL::OpenGL)

# The quadtree terrain's node selection against its reference (the full
# rescan of the restriction) and with the triangle budget; built with the renderer's
# private terrain header for its reference switch.
add_executable(bench_renderer_quadtree_select ${CMAKE_CURRENT_LIST_DIR}/renderer_quadtree_select.cpp)
target_include_directories(bench_renderer_quadtree_select PRIVATE ${PROJECT_SOURCE_DIR}/renderer/src)
target_link_libraries(bench_renderer_quadtree_select PRIVATE clipstream::renderer clipstream::tiler clipstream::cli
  clipstream_warnings OpenGL::OpenGL)

# What per-pixel lighting (and the other detail beyond the data) costs a
# terrain frame against the frame without it, alternated in one run.
add_executable(bench_renderer_terrain_detail ${CMAKE_CURRENT_LIST_DIR}/renderer_terrain_detail.cpp)
target_include_directories(bench_renderer_terrain_detail PRIVATE ${PROJECT_SOURCE_DIR}/renderer/src)
target_link_libraries(bench_renderer_terrain_detail PRIVATE clipstream::renderer clipstream::tiler clipstream::cli
  clipstream_warnings OpenGL::OpenGL)
