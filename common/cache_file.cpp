#include "common/cache_file.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace neurosim::common {

bool write_cache_file(const std::string& file, const std::string& owner, const std::string& what,
                      const std::function<void(std::ostream&)>& write) {
  std::error_code ec;
  const std::filesystem::path folder = std::filesystem::path(file).parent_path();
  if (!folder.empty()) std::filesystem::create_directories(folder, ec);
  // The temporary is this call's own: the process id and a per-process count, so neither two
  // processes nor two threads of one process writing the same key ever share it; each renames
  // a whole file over the name (the last rename wins; both files hold the same bytes).
  static std::atomic<unsigned long> calls{0};
  const std::string tmp = file + ".tmp." + std::to_string(::getpid()) + "." +
                          std::to_string(calls.fetch_add(1, std::memory_order_relaxed));
  bool ok = false;
  int write_errno = 0;
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (out) write(out);
    out.flush();
    ok = static_cast<bool>(out);
    if (!ok) write_errno = errno;
  }
  if (!ok) {
    std::cerr << owner << ": could not write " << what << ' ' << file << ": "
              << (write_errno != 0 ? std::strerror(write_errno) : "stream error")
              << " (continuing without it)\n";
    std::filesystem::remove(tmp, ec);
    return false;
  }
  std::filesystem::rename(tmp, file, ec);
  if (ec) {
    std::cerr << owner << ": could not store " << what << ' ' << file << ": " << ec.message()
              << " (continuing without it)\n";
    std::filesystem::remove(tmp, ec);
    return false;
  }
  return true;
}

}  // namespace neurosim::common
