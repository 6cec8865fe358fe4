#include "record/recording_lock.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace tissue::record {
namespace {

struct flock whole_file(short type) {
  struct flock lock {};
  lock.l_type = type;
  lock.l_whence = SEEK_SET;
  lock.l_start = 0;
  lock.l_len = 0;  // to the end, however the file grows
  return lock;
}

}  // namespace

std::string RecordingLock::take(const std::string& path) {
  release();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return std::string("cannot open it for the lock: ") + std::strerror(errno);
  struct flock lock = whole_file(F_RDLCK);
  if (::fcntl(fd, F_OFD_SETLK, &lock) != 0) {
    const int error = errno;
    ::close(fd);
    const std::string why = std::string("(fcntl F_OFD_SETLK: ") + std::strerror(error) + ")";
    // EINVAL: a kernel before 3.15 (no F_OFD_SETLK); the others come from
    // file systems (some network and FUSE mounts) that do not lock, which
    // is the case the operator has to act on: say so rather than only errno.
    if (error == EINVAL || error == ENOLCK || error == EOPNOTSUPP || error == ENOSYS)
      return "the file system or kernel does not support open file description locks " + why;
    if (error == EAGAIN || error == EACCES) return "another lock on it conflicts " + why;
    return "cannot lock it " + why;
  }
  fd_ = fd;
  return {};
}

void RecordingLock::release() noexcept {
  if (fd_ < 0) return;
  ::close(fd_);  // drops the lock
  fd_ = -1;
}

bool being_recorded(const std::string& path) noexcept {
  // Only a regular file can be a session. A plain open of a FIFO blocks
  // until a writer comes (`tissue session repair` on one hung for good), and
  // opening a device can have effects of its own: look before opening, and
  // open without blocking in case the name is swapped in between.
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd < 0) return false;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return false;
  }
  // Would a write lock be refused? Only by a reader's lock: a recorder's.
  struct flock lock = whole_file(F_WRLCK);
  const bool held = ::fcntl(fd, F_OFD_GETLK, &lock) == 0 && lock.l_type != F_UNLCK;
  ::close(fd);
  return held;
}

}  // namespace tissue::record
