#include "common/input_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <new>
#include <stdexcept>

namespace neurosim::common {

namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what, const std::string& why) {
  throw std::runtime_error(path + ": " + what + ": " + why);
}

void check_stat(const struct stat& st, const std::string& path, std::size_t max_bytes,
                const std::string& what) {
  if (!S_ISREG(st.st_mode))
    fail(path, what, std::string("is ") + file_kind(st.st_mode) + ", not a regular file");
  if (static_cast<unsigned long long>(st.st_size) > max_bytes)
    fail(path, what,
         std::to_string(st.st_size) + " bytes, above the limit of " + std::to_string(max_bytes) +
             " bytes");
}

// Closes the descriptor on every path out.
struct Fd {
  int fd;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

const char* file_kind(unsigned mode) {
  if (S_ISREG(mode)) return "a regular file";
  if (S_ISFIFO(mode)) return "a named pipe";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a file";
}

std::string read_input_file(const std::string& path, std::size_t max_bytes,
                            const std::string& what) {
  // O_NONBLOCK: opening a named pipe does not wait for a writer (it is refused just below);
  // a regular file ignores the flag.
  Fd f{::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY)};
  if (f.fd < 0) throw std::runtime_error(path + ": cannot open " + what + ": " + std::strerror(errno));
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) fail(path, what, std::string("cannot stat: ") + std::strerror(errno));
  check_stat(st, path, max_bytes, what);
  std::string text;
  try {
    text.reserve(static_cast<std::size_t>(st.st_size) + 1);
    // Up to max_bytes + 1, whatever the size said: a file that grows while read stops here.
    char chunk[1 << 16];
    for (;;) {
      const std::size_t want = std::min(sizeof chunk, max_bytes + 1 - text.size());
      const ssize_t n = ::read(f.fd, chunk, want);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) fail(path, what, std::string("read error: ") + std::strerror(errno));
      if (n == 0) break;
      text.append(chunk, static_cast<std::size_t>(n));
      if (text.size() > max_bytes)
        fail(path, what, "grew above the limit of " + std::to_string(max_bytes) + " bytes while read");
    }
  } catch (const std::bad_alloc&) {
    throw std::runtime_error(path + ": out of memory reading " + what + " (" +
                             std::to_string(st.st_size) + " bytes)");
  }
  return text;
}

void require_regular_file(const std::string& path, std::size_t max_bytes,
                          const std::string& what) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return;  // missing: the reader says so
  check_stat(st, path, max_bytes, what);
}

}  // namespace neurosim::common
