#include "app/output_file.hpp"

namespace tissue::app {

std::string OutputFile::open(const std::string& path, const std::string& what) {
  path_ = path;
  what_ = what;
  const std::string why = file_.open(path);
  return why.empty() ? why : "cannot write " + name() + ": " + why;
}

std::string OutputFile::write(const std::string& text) {
  if (!file_.is_open()) return "cannot write " + name() + ": not open";
  const std::string why = file_.commit(text);
  return why.empty() ? why : "cannot write " + name() + ": " + why;
}

std::string OutputFile::name() const { return what_.empty() ? path_ : what_ + " " + path_; }

}  // namespace tissue::app
