#include "util/output_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>

namespace tissue::util {

int write_all(int fd, std::string_view text) {
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

std::string canonical_link_path(const std::string& path) {
  const std::filesystem::path p(path);
  const std::string dir = p.has_parent_path() ? p.parent_path().string() : std::string(".");
  char* resolved = ::realpath(dir.c_str(), nullptr);
  if (resolved == nullptr) return {};
  std::string out(resolved);
  std::free(resolved);
  return (out == "/" ? out : out + "/") + p.filename().string();
}

bool through_proc(const std::string& path) {
  std::string p = path;
  for (int hop = 0; hop < 40; ++hop) {  // the kernel's own limit on a chain
    const std::string link = canonical_link_path(p);
    if (link.empty()) return false;
    if (link.rfind("/proc/", 0) == 0) return true;
    struct stat st {};
    if (::lstat(link.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return false;
    char target[PATH_MAX];
    const ssize_t n = ::readlink(link.c_str(), target, sizeof target - 1);
    if (n < 0) return false;
    target[n] = '\0';
    p = target[0] == '/' ? std::string(target)
                         : std::filesystem::path(link).parent_path().string() + "/" + std::string(target);
  }
  return false;
}

std::string write_output_file(const std::string& path, std::string_view text) {
  struct stat st {};
  const bool exists = ::stat(path.c_str(), &st) == 0;
  if (exists && S_ISDIR(st.st_mode)) return "is a directory";
  if (exists && (!S_ISREG(st.st_mode) || through_proc(path))) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC | (S_ISREG(st.st_mode) ? O_APPEND : 0));
    if (fd < 0) return std::strerror(errno);
    int err = write_all(fd, text);
    if (::close(fd) != 0 && err == 0) err = errno;
    return err == 0 ? std::string() : std::string(std::strerror(err));
  }
  std::string target = path;
  struct stat link {};
  if (exists && ::lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode)) {
    char* resolved = ::realpath(path.c_str(), nullptr);
    if (resolved != nullptr) {
      target = resolved;
      std::free(resolved);
    }
  }
  const std::string tmp = target + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) return "cannot create '" + tmp + "': " + std::strerror(errno);
  int err = write_all(fd, text);
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err == 0 && std::rename(tmp.c_str(), target.c_str()) != 0) err = errno;
  if (err != 0) {
    ::unlink(tmp.c_str());  // after saving errno: unlink may change it
    return std::strerror(err);
  }
  return {};
}

bool is_standard_output(const std::string& path) {
  struct stat out {
  }, st{};
  return ::fstat(STDOUT_FILENO, &out) == 0 && ::stat(path.c_str(), &st) == 0 && out.st_dev == st.st_dev &&
         out.st_ino == st.st_ino;
}

std::ostream& summary_stream(const std::string& path) { return is_standard_output(path) ? std::cerr : std::cout; }

bool same_file(const std::string& out, const std::string& input) {
  std::error_code ec;
  return std::filesystem::equivalent(out, input, ec) && !ec;
}

}  // namespace tissue::util
