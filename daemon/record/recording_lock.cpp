#include "record/recording_lock.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

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

bool RecordingLock::take(const std::string& path) noexcept {
  release();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  struct flock lock = whole_file(F_RDLCK);
  if (::fcntl(fd, F_OFD_SETLK, &lock) != 0) {
    ::close(fd);
    return false;
  }
  fd_ = fd;
  return true;
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
