#include "util/output_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
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

namespace {

// ".NAME.tmp-PID-N" in `dir`: hidden from listings and globs, unique to this
// process and call; NAME cut so the whole fits the 255 bytes of a name.
std::string temporary_name(const std::string& dir, const std::string& name) {
  static std::atomic<unsigned> counter{0};
  std::string out = dir;
  if (!out.empty() && out.back() != '/') out += '/';
  out.append(".").append(name.substr(0, 200)).append(".tmp-").append(std::to_string(::getpid()));
  out.append("-").append(std::to_string(counter.fetch_add(1)));
  return out;
}

}  // namespace

// Renames `from` to `to` unless `to` exists (atomically: no check-then-act
// window). Returns 0 or the errno. Filesystems without RENAME_NOREPLACE get a
// hard link, which is just as exclusive, and the unlink of the old name;
// those without hard links either (FAT and exFAT sticks) a check, then a
// plain rename: two writers publishing the same name in the same instant
// there could replace one another's file.
int rename_without_replacing(const std::string& from, const std::string& to) {
  if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) return 0;
  if (errno != EINVAL && errno != ENOSYS) return errno;
  if (::link(from.c_str(), to.c_str()) == 0) {
    ::unlink(from.c_str());
    return 0;
  }
  if (errno != EPERM && errno != EOPNOTSUPP) return errno;
  if (::access(to.c_str(), F_OK) == 0) return EEXIST;
  return ::rename(from.c_str(), to.c_str()) == 0 ? 0 : errno;
}

std::string PendingOutputFile::open(const std::string& path) {
  abandon();
  replace_ = true;
  struct stat st {};
  const bool exists = ::stat(path.c_str(), &st) == 0;
  if (exists && S_ISDIR(st.st_mode)) return "is a directory";
  if (exists && (!S_ISREG(st.st_mode) || through_proc(path))) {
    fd_ = ::open(path.c_str(), O_WRONLY | O_CLOEXEC | (S_ISREG(st.st_mode) ? O_APPEND : 0));
    if (fd_ < 0) return std::strerror(errno);
    target_ = path;
    return {};
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
  std::string why = open_temporary(target);
  // The replacement keeps the replaced file's permissions (a report the user
  // made private stays private; the new file had 0666 minus the umask).
  if (why.empty() && exists && ::fchmod(fd_, st.st_mode & 07777) != 0) {
    why = std::string("cannot give the temporary file the permissions of the one it replaces: ") + std::strerror(errno);
    abandon();
  }
  return why;
}

std::string PendingOutputFile::open_new(const std::string& path) {
  abandon();
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) return std::string(kAlreadyExists);
  replace_ = false;
  return open_temporary(path);
}

std::string PendingOutputFile::open_temporary(const std::string& target) {
  const std::filesystem::path p(target);
  const std::string dir = p.has_parent_path() ? p.parent_path().string() : std::string(".");
  // A name another writer (or anyone) took is skipped, never opened.
  for (int attempt = 0; attempt < 100; ++attempt) {
    const std::string tmp = temporary_name(p.has_parent_path() ? dir : std::string(), p.filename().string());
    fd_ = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
    if (fd_ >= 0) {
      target_ = target;
      tmp_ = tmp;
      return {};
    }
    if (errno != EEXIST) break;
  }
  return "cannot create a temporary file in '" + dir + "': " + std::strerror(errno);
}

std::string PendingOutputFile::commit(std::string_view text) {
  if (fd_ < 0) return "not open";
  int err = write_all(fd_, text);
  // On disk before it replaces anything: a crash after the rename must not
  // leave an empty file where the old one was.
  if (err == 0 && !tmp_.empty() && ::fsync(fd_) != 0) err = errno;
  if (::close(fd_) != 0 && err == 0) err = errno;
  fd_ = -1;
  if (err == 0 && !tmp_.empty()) {
    if (replace_)
      err = std::rename(tmp_.c_str(), target_.c_str()) == 0 ? 0 : errno;
    else
      err = rename_without_replacing(tmp_, target_);
  }
  if (err != 0) {
    abandon();  // after saving errno: unlink may change it
    return !replace_ && err == EEXIST ? std::string(kAlreadyExists) : std::string(std::strerror(err));
  }
  if (!tmp_.empty()) {
    // The rename itself, durable (best effort: some filesystems refuse it).
    const std::filesystem::path p(target_);
    const int dir = ::open(p.has_parent_path() ? p.parent_path().c_str() : ".", O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dir >= 0) {
      ::fsync(dir);
      ::close(dir);
    }
  }
  tmp_.clear();
  target_.clear();
  return {};
}

void PendingOutputFile::abandon() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!tmp_.empty()) ::unlink(tmp_.c_str());
  tmp_.clear();
  target_.clear();
}

std::string write_output_file(const std::string& path, std::string_view text) {
  PendingOutputFile file;
  if (std::string why = file.open(path); !why.empty()) return why;
  return file.commit(text);
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
