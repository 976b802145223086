# Writes OUTPUT, a C++ source defining `const unsigned char NAME[]` and `NAME_size` with the bytes
# of INPUT: how the OptiX IR of the device programs travels inside the library.
file(READ ${INPUT} hex HEX)
string(LENGTH "${hex}" hex_length)
math(EXPR size "${hex_length} / 2")
string(REGEX REPLACE "([0-9a-f][0-9a-f])" "0x\\1," bytes "${hex}")
file(WRITE ${OUTPUT} "// Generated from ${INPUT} by cmake/embed_binary.cmake.\n#include <cstddef>\n"
  "extern const unsigned char ${NAME}[] = {${bytes}};\n"
  "extern const std::size_t ${NAME}_size = ${size};\n")
