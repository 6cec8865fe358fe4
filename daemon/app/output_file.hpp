// An output file of a long run (a batch report, a trade study's CSV and SVG)
// opened before the run, so a path that cannot be written fails before
// minutes of simulation instead of after them, and written once at the end.
#pragma once

#include <cstdio>
#include <string>

namespace tissue::app {

class OutputFile {
 public:
  OutputFile() = default;
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;
  // Closes and deletes a file that was opened and never written.
  ~OutputFile() { discard(); }

  // Creates (or truncates) `path`. Empty on success, else
  // "cannot write WHAT PATH: reason" (`what` says which file it is: "report").
  std::string open(const std::string& path, const std::string& what = {});
  // Writes `text` and closes the file; the same kind of message on failure
  // (a full disk shows up here, at the flush or the close).
  std::string write(const std::string& text);
  // Closes and deletes the file if it is still open (the run did not get to
  // write it).
  void discard();
  bool is_open() const { return file_ != nullptr; }

 private:
  std::string name() const;
  std::string failure(int err) const;
  std::string path_, what_;
  std::FILE* file_ = nullptr;
};

}  // namespace tissue::app
