// An output file of a long run (a batch report, a trade study's CSV and SVG)
// opened before the run, so a path that cannot be written fails before
// minutes of simulation instead of after them, and written once at the end.
// util::PendingOutputFile does the writing: until write() the file the user
// named is untouched (the text goes to a temporary file beside it, renamed
// over it when complete); a device, a FIFO or /dev/stdout is written in
// place. A run that ends before write() (a refused --record, an error)
// leaves the user's earlier file as it was.
#pragma once

#include <string>

#include "util/output_file.hpp"

namespace tissue::app {

class OutputFile {
 public:
  OutputFile() = default;
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  // Gets ready to write `path`. Empty on success, else
  // "cannot write WHAT PATH: reason" (`what` says which file it is: "report").
  std::string open(const std::string& path, const std::string& what = {});
  // Writes `text` and puts the file in place; the same kind of message on
  // failure (a full disk shows up here).
  std::string write(const std::string& text);
  // Gives up on the file: PATH stays as it was before open() (only the
  // temporary file goes). The destructor does this too.
  void discard() { file_.abandon(); }
  bool is_open() const { return file_.is_open(); }

 private:
  std::string name() const;
  std::string path_, what_;
  util::PendingOutputFile file_;
};

}  // namespace tissue::app
