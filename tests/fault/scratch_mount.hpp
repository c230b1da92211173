// Storage faults on demand: a private mount namespace for the test process (and the children it
// starts), where a small tmpfs stands for a full disk or is remounted read-only. Root ignores
// file permissions, a read-only mount it does not; tmpfs gives ENOSPC like a full disk.
#pragma once

#include <sched.h>
#include <sys/mount.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace neurosim::testing {

// Enters a private mount namespace once; returns "" or why it is not possible (then the
// caller skips: storage faults need CAP_SYS_ADMIN).
inline std::string enter_private_mounts() {
  static std::string why = [] {
    if (::unshare(CLONE_NEWNS) != 0)
      return std::string("unshare(CLONE_NEWNS): ") + std::strerror(errno);
    if (::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0)
      return std::string("making / private: ") + std::strerror(errno);
    return std::string();
  }();
  return why;
}

// A tmpfs of `bytes` at dir (created); "" or the error.
inline std::string mount_small_tmpfs(const std::filesystem::path& dir, std::size_t bytes) {
  std::filesystem::create_directories(dir);
  const std::string opts = "size=" + std::to_string(bytes);
  if (::mount("tmpfs", dir.c_str(), "tmpfs", 0, opts.c_str()) != 0)
    return "mount tmpfs at " + dir.string() + ": " + std::strerror(errno);
  return {};
}

inline std::string remount_read_only(const std::filesystem::path& dir) {
  if (::mount(nullptr, dir.c_str(), nullptr, MS_REMOUNT | MS_RDONLY, nullptr) != 0)
    return "remount " + dir.string() + " read-only: " + std::strerror(errno);
  return {};
}

// Fills the file system at dir to the last byte (a file of zeros until ENOSPC).
inline void fill_up(const std::filesystem::path& dir) {
  std::ofstream f(dir / "filler", std::ios::binary);
  const std::vector<char> block(4096, 0);
  while (f.write(block.data(), static_cast<std::streamsize>(block.size()))) {
  }
  // Partial blocks: byte by byte to the end.
  f.clear();
  while (f.put('\0') && f.flush()) {
  }
}

inline void unmount(const std::filesystem::path& dir) { ::umount2(dir.c_str(), MNT_DETACH); }

// A list of a folder's entries (names), to check that nothing half-written is left.
inline std::vector<std::string> entries(const std::filesystem::path& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec))
    out.push_back(e.path().filename().string());
  return out;
}

}  // namespace neurosim::testing
