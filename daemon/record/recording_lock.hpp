// The mark a recorder holds on its session file while it writes.
//
// HDF5 gives up its own file lock when SWMR writing starts, and a running
// recording and one left by a crash both keep the superblock's
// open-for-write flags: nothing told them apart, and `tissue session
// repair` on a live recording trimmed and re-flagged a file that was still
// being written. So the writer holds an open file description lock (fcntl
// F_OFD_SETLK: a read lock over the whole file) on a descriptor of its own
// until it closes. The kernel drops it when the descriptor closes, however
// the recorder's process ends, so a crashed session is never marked. It is
// independent of HDF5's flock() locks and conflicts between descriptors of
// one process too (what the tests rely on). Without it there is no
// recording (SessionWriter::create fails): on a file system without these
// locks nothing would tell the live file from a crashed one, and a repair
// would damage it.
#pragma once

#include <string>

namespace tissue::record {

class RecordingLock {
 public:
  RecordingLock() = default;
  ~RecordingLock() { release(); }
  RecordingLock(const RecordingLock&) = delete;
  RecordingLock& operator=(const RecordingLock&) = delete;

  // Marks `path` as being recorded. Returns an empty string when it did, else
  // why not (and no mark): the file could not be opened (no such file, the
  // process is out of descriptors), the file system or kernel does not
  // support these locks, or another holds a conflicting one. Nodiscard: a
  // recording must not go on unmarked (above).
  [[nodiscard]] std::string take(const std::string& path);
  void release() noexcept;
  bool held() const noexcept { return fd_ >= 0; }

 private:
  int fd_ = -1;
};

// True when some process's RecordingLock holds `path` (false when the file
// cannot be opened, is not a regular file, or the file system does not
// support the lock). Never blocks: a FIFO or device is not opened.
bool being_recorded(const std::string& path) noexcept;

}  // namespace tissue::record
