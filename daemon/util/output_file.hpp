// Writing a file the user named with -o: `tissue x3d`, `render`, the XDMF
// sidecar writer (tissue_record), and, opened before their run, batch
// reports and the trade study's CSV/SVG (app/output_file.hpp); write_all for
// the service's export and same_file for the trade study. Part of
// tissue_util, which links nothing of the simulation.
#pragma once

#include <iosfwd>
#include <string>
#include <string_view>

namespace tissue::util {

// Writes all of `text` to the open descriptor `fd` (EINTR and short writes
// retried); returns the errno of the failure, 0 on success.
int write_all(int fd, std::string_view text);

// The canonical directory of `path` joined with its last name (the link
// itself, not followed); "" when the directory does not resolve.
std::string canonical_link_path(const std::string& path);

// Whether `path`, following its symbolic links, passes through /proc: an
// open descriptor's link such as /dev/stdout (-> /proc/self/fd/1), /dev/fd/N
// or /proc/PID/fd/N. Its file is one a process already holds open (a
// shell's `> out`): it is written in place, never renamed over.
bool through_proc(const std::string& path);

// A file the user named, written whole or not at all: opened first (a path
// that cannot be written fails before the work that fills it), given its
// text once at the end by commit(). The one writer of output files: the
// tools' -o (write_output_file below), batch reports and the trade study's
// CSV and SVG (app/output_file.hpp).
//
// A regular file (or a new name) is written to a temporary file beside it,
// ".NAME.tmp-PID-N" made with O_EXCL | O_NOFOLLOW (never a file or link
// already there: not the user's own NAME.tmp, not through a link planted
// there), synced, and renamed over PATH: PATH is untouched until the text is
// complete on disk, a failed or abandoned write leaves PATH as it was, and
// the temporary file goes. A symbolic link to a regular file stays a link,
// and the file it names is replaced. Written in place instead, from open():
// - an existing node that is not a regular file (a character device such as
//   /dev/null or /dev/full, a FIFO, a socket): a rename would replace the
//   node with a regular file, and a device's own write error (ENOSPC from
//   /dev/full) is the answer the user asked for;
// - a file reached through /proc (-o /dev/stdout or --report /dev/stdout
//   with standard output redirected to a file): renaming there would have
//   replaced /dev/stdout itself (as root) or failed. It is appended to,
//   since its holder opened it (`>` truncated it already; `>>` keeps what
//   was there).
// Either way nothing this class did not create is ever removed.
class PendingOutputFile {
 public:
  PendingOutputFile() = default;
  PendingOutputFile(const PendingOutputFile&) = delete;
  PendingOutputFile& operator=(const PendingOutputFile&) = delete;
  ~PendingOutputFile() { abandon(); }

  // Gets ready to write `path`: "" on success, else the reason (what the OS
  // said, e.g. "Permission denied", or "is a directory"), for the caller to
  // put after the path in its own message.
  std::string open(const std::string& path);
  // As open(), for a file that must be new (the daemon's exports: files are
  // never overwritten): kAlreadyExists when PATH exists, and commit() puts it
  // in place only while PATH does not exist (rename_without_replacing), else
  // returns kAlreadyExists and removes its temporary file. Always written to
  // a temporary file first, so a crash mid-write leaves no part file at PATH.
  std::string open_new(const std::string& path);
  static constexpr std::string_view kAlreadyExists = "it already exists";
  // Writes all of `text`, syncs it and puts it in place; "" or the reason.
  // Closed afterwards either way.
  std::string commit(std::string_view text);
  // Closes without writing: the temporary file goes, PATH stays as it was.
  void abandon();
  bool is_open() const { return fd_ >= 0; }
  // The temporary file, "" when writing in place or not open (tests).
  const std::string& temporary_path() const { return tmp_; }

 private:
  std::string open_temporary(const std::string& target);

  std::string target_, tmp_;
  int fd_ = -1;
  bool replace_ = true;
};

// rename(from, to) that fails with EEXIST instead of replacing `to`; 0 or the
// errno. The session writer publishes new recordings with it.
int rename_without_replacing(const std::string& from, const std::string& to);

// Writes `text` to `path` as PendingOutputFile does. Returns "" on success,
// else the reason, for the caller to put after the path in its own message.
std::string write_output_file(const std::string& path, std::string_view text);

// True when `path` is the file (or pipe) this process's standard output
// writes to: -o /dev/stdout, or the file stdout was redirected to.
bool is_standard_output(const std::string& path);

// Where a tool says "wrote PATH": standard output, or standard error when
// PATH is standard output (the line would land inside the output).
std::ostream& summary_stream(const std::string& path);

// True when `out` and `input` name the same existing file (another spelling,
// a hard or symbolic link): writing `out` would destroy the input.
bool same_file(const std::string& out, const std::string& input);

}  // namespace tissue::util
