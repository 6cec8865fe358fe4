#include "app/output_file.hpp"

#include <cerrno>
#include <cstring>

namespace tissue::app {

std::string OutputFile::open(const std::string& path, const std::string& what) {
  discard();
  path_ = path;
  what_ = what;
  errno = 0;
  file_ = std::fopen(path.c_str(), "w");
  return file_ ? std::string() : failure(errno);
}

std::string OutputFile::write(const std::string& text) {
  if (!file_) return "cannot write " + name() + ": not open";
  errno = 0;
  const bool wrote = std::fwrite(text.data(), 1, text.size(), file_) == text.size() && std::fflush(file_) == 0;
  const int write_errno = errno;
  const bool closed = std::fclose(file_) == 0;
  const int close_errno = errno;
  file_ = nullptr;
  if (!wrote) return failure(write_errno);
  if (!closed) return failure(close_errno);
  return {};
}

void OutputFile::discard() {
  if (!file_) return;
  std::fclose(file_);
  file_ = nullptr;
  std::remove(path_.c_str());
}

std::string OutputFile::name() const { return what_.empty() ? path_ : what_ + " " + path_; }

std::string OutputFile::failure(int err) const {
  return "cannot write " + name() + ": " + (err != 0 ? std::strerror(err) : "unknown error");
}

}  // namespace tissue::app
