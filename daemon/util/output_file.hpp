// Writing a file the user named with -o, shared by `tissue x3d` and the XDMF
// sidecar writer (tissue_record). Header-only, like xml.hpp: both libraries
// use it without linking the simulation library.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>

namespace tissue::util {

namespace detail {

// Writes all of `text` to `fd` (EINTR and short writes retried); returns
// the errno of the failure, 0 on success.
inline int write_all(int fd, std::string_view text) {
  while (!text.empty()) {
    const ssize_t n = ::write(fd, text.data(), text.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    text.remove_prefix(static_cast<std::size_t>(n));
  }
  return 0;
}

}  // namespace detail

// Writes `text` to `path`. Returns "" on success, else the reason (what the
// OS said, e.g. "No space left on device"), for the caller to put after the
// path in its own message.
//
// A regular file (or a new name) is written to PATH.tmp and renamed over
// PATH, so a failed write never leaves a truncated PATH (nor clobbers a good
// one). An existing node that is not a regular file (a character device such
// as /dev/null or /dev/full, a FIFO, a socket) is written in place: a rename
// would replace the node with a regular file, and a device's own write error
// (ENOSPC from /dev/full) is the answer the user asked for.
inline std::string write_output_file(const std::string& path, std::string_view text) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    if (S_ISDIR(st.st_mode)) return "is a directory";
    const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd < 0) return std::strerror(errno);
    int err = detail::write_all(fd, text);
    if (::close(fd) != 0 && err == 0) err = errno;
    return err == 0 ? std::string() : std::string(std::strerror(err));
  }
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) return "cannot create '" + tmp + "': " + std::strerror(errno);
  int err = detail::write_all(fd, text);
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err == 0 && std::rename(tmp.c_str(), path.c_str()) != 0) err = errno;
  if (err != 0) {
    ::unlink(tmp.c_str());  // after saving errno: unlink may change it
    return std::strerror(err);
  }
  return {};
}

// True when `out` and `input` name the same existing file (another spelling,
// a hard or symbolic link): writing `out` would destroy the input.
inline bool same_file(const std::string& out, const std::string& input) {
  std::error_code ec;
  return std::filesystem::equivalent(out, input, ec) && !ec;
}

}  // namespace tissue::util
