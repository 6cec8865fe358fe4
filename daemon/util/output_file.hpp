// Writing a file the user named with -o: `tissue x3d`, `render`, the XDMF
// sidecar writer (tissue_record); write_all for the service's export and
// same_file for the trade study. Part of tissue_util, which links nothing of
// the simulation. (Batch reports and the trade study's CSV/SVG are opened
// before their run instead: app/output_file.hpp.)
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

// Writes `text` to `path`. Returns "" on success, else the reason (what the
// OS said, e.g. "No space left on device"), for the caller to put after the
// path in its own message.
//
// A regular file (or a new name) is written to PATH.tmp and renamed over
// PATH, so a failed write never leaves a truncated PATH (nor clobbers a good
// one); a symbolic link to a regular file stays a link, and the file it
// names is replaced. Written in place instead:
// - an existing node that is not a regular file (a character device such as
//   /dev/null or /dev/full, a FIFO, a socket): a rename would replace the
//   node with a regular file, and a device's own write error (ENOSPC from
//   /dev/full) is the answer the user asked for;
// - a file reached through /proc (-o /dev/stdout with standard output
//   redirected to a file): renaming there would have replaced /dev/stdout
//   itself (as root) or failed. It is appended to, since its holder opened
//   it (`>` truncated it already; `>>` keeps what was there).
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
