// Reading a file that came from outside (a scene, a mesh, an image, a recording): only a regular
// file, and never more than a stated size. A named pipe, a device (/dev/zero), a socket or a
// directory is refused before anything is read: opening a named pipe for reading alone blocks
// until a writer comes, and /dev/zero never ends. A regular file larger than the limit is
// refused by its size, before reading. Errors name the file and what it was read as.
#pragma once

#include <cstddef>
#include <string>

namespace neurosim::common {

// The whole file. Throws std::runtime_error "<path>: <what>: is a named pipe, not a regular
// file", "<path>: <what>: <n> bytes, above the limit of <max_bytes> bytes", "<path>: cannot
// open <what>: <reason>", or "<path>: out of memory reading <what> (<n> bytes)".
std::string read_input_file(const std::string& path, std::size_t max_bytes,
                            const std::string& what);

// The same checks without reading, for readers that open the file themselves (VTK's): a path
// that does not exist passes (the reader reports it), anything else that is not a regular file
// of at most max_bytes is refused with the errors above.
void require_regular_file(const std::string& path, std::size_t max_bytes,
                          const std::string& what);

// "a named pipe", "a character device", "a directory", ... for a st_mode; "a regular file".
const char* file_kind(unsigned mode);

}  // namespace neurosim::common
