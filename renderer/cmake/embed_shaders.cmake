# Turns the GLSL files into one C++ source of raw string literals, so the
# programs need no shader files at run time. Run with
#   -DOUT=<file.cpp> -DINPUTS=<a.glsl;b.frag;...>
set(text "// Generated from renderer/shaders by embed_shaders.cmake; do not edit.\n")
string(APPEND text "#include \"shaders.h\"\n\nnamespace clipstream::shaders {\n")
foreach(path IN LISTS INPUTS)
  get_filename_component(name "${path}" NAME)
  string(MAKE_C_IDENTIFIER "${name}" ident)
  file(READ "${path}" body)
  string(APPEND text "const char* const k_${ident} = R\"glsl(${body})glsl\";\n")
endforeach()
string(APPEND text "}  // namespace clipstream::shaders\n")
file(WRITE "${OUT}.tmp" "${text}")
file(COPY_FILE "${OUT}.tmp" "${OUT}" ONLY_IF_DIFFERENT)
