// Option checks the `tissue` subcommands share.
#pragma once

#include <sys/stat.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "util/lcm_url.hpp"
#include "util/output_file.hpp"
#include "util/text.hpp"

namespace tissue::cli {

// A finite number > 0. CLI::PositiveNumber lets NaN through (every
// comparison with it is false): `--timeout nan` then waited forever.
namespace detail {
// Reads all of `v` as a number into *x; the message when it is not one.
inline std::string whole_number(const std::string& v, double* x) {
  const std::optional<double> read = util::whole_number(v);
  if (!read) return "'" + v + "' is not a number";
  *x = *read;
  return {};
}
}  // namespace detail

inline CLI::Validator finite_positive() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        double x = 0.0;
        if (std::string why = detail::whole_number(v, &x); !why.empty()) return why;
        return std::isfinite(x) && x > 0.0 ? std::string() : v + " must be a finite number > 0";
      },
      "S > 0");
}

// Any finite number (a session time): `--time nan` found "no frame that
// early" instead of saying what was wrong.
inline CLI::Validator finite_number() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        double x = 0.0;
        if (std::string why = detail::whole_number(v, &x); !why.empty()) return why;
        return std::isfinite(x) ? std::string() : v + " is not a finite number";
      },
      "T");
}

// An LCM provider URL as the daemon's config checks it (util/lcm_url.hpp):
// PROVIDER://..., and a udpm:// one needs a multicast group, a port and a
// ttl in range. A word without "://" reached LCM, which could not start
// (exit 3 for a mistyped argument). `provider_required` false lets such a
// word through for an option whose caller decides what it is (`session
// replay --lcm FILE`). Empty is allowed: the callers take it as the default.
inline CLI::Validator lcm_url(bool provider_required = true) {
  return CLI::Validator(
      [provider_required](std::string& v) -> std::string {
        if (provider_required && !v.empty() && v.find("://") == std::string::npos)
          return "'" + v + "' is not an LCM URL (PROVIDER://...)";
        if (const std::string why = util::udpm_url_problem(v); !why.empty()) return "'" + v + "': " + why;
        return {};
      },
      "URL");
}

namespace detail {
// CLI11 reads integers with base 0 (strtoll(v, 0)): "010" was 8, "0x10" 16,
// and a number past 64 bits became the largest one with no word said. So an
// integer option takes decimal digits only, its leading zeros dropped here
// (the validator may rewrite the value before CLI11 converts it), and must
// fit in 64 bits; the option's own Range then bounds it.
inline std::string decimal_digits(std::string& v) {
  if (v.empty() || !std::all_of(v.begin(), v.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return "'" + v + "' is not a whole number in decimal digits";
  const std::size_t first = std::min(v.find_first_not_of('0'), v.size() - 1);
  v.erase(0, first);
  std::uint64_t x = 0;
  const auto [end, error] = std::from_chars(v.data(), v.data() + v.size(), x);
  if (error != std::errc() || end != v.data() + v.size()) return v + " is too large";
  return {};
}
}  // namespace detail

// A whole number written in decimal digits (see detail::decimal_digits).
// Add it with Option::transform, not check: CLI11 runs a check() on a copy,
// so the leading zeros would stay for its base-0 conversion.
inline CLI::Validator decimal_integer() {
  return CLI::Validator([](std::string& v) { return detail::decimal_digits(v); }, "N");
}

// A frame index: unsigned parsing would wrap "-1" to 18446744073709551615.
// Decimal digits only, as decimal_integer (and added the same way).
inline CLI::Validator frame_index() {
  return CLI::Validator(
      [](std::string& v) {
        if (!v.empty() && v.front() == '-') return v + " is negative: frames are numbered from 0";
        return detail::decimal_digits(v);
      },
      "K >= 0");
}

// Why the -o file `path` cannot be written ("" when it can), for the check
// `tissue x3d` and `tissue render` make before reading or collecting frames
// (a live collection runs up to an hour; an OUT in a missing directory was
// found only after it). Made by creating the temporary file
// util::PendingOutputFile writes through and dropping it at once: nothing
// is left behind, PATH is not touched, and no file is held while the frames
// are collected (a signal that kills the client then leaves nothing; the
// real PendingOutputFile is opened just before writing). An existing node
// that is neither a regular file nor a directory (a FIFO, a device) is not
// opened: opening a FIFO waits for its reader, and that reader would see the
// end of the stream when the check closed it.
inline std::string output_problem(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode)) return {};
  util::PendingOutputFile probe;
  return probe.open(path);  // abandoned by its destructor
}

// The first of `paths` that output_problem refuses, and why; nullopt when
// all can be written. For the many files of `tissue render --sequence`,
// checked before any frame is read: with %04d in a directory name each file
// has a directory of its own, and a file's name may be taken (by a
// directory), so the first file did not stand for the rest. A name with no
// node yet, or a regular file, is written through a temporary file in its
// directory and renamed: one probe per directory answers for all of them (an
// hour at 30 Hz is 108 000 names in one). Any other node (a directory, a
// link, a FIFO) is checked by its own name.
struct OutputProblem {
  std::string path, why;
};
inline std::optional<OutputProblem> first_output_problem(const std::vector<std::string>& paths) {
  std::set<std::string> probed_directories;
  for (const std::string& path : paths) {
    struct stat st {};
    if (::lstat(path.c_str(), &st) != 0 || S_ISREG(st.st_mode)) {
      if (!probed_directories.insert(std::filesystem::path(path).parent_path().string()).second) continue;
    }
    if (std::string why = output_problem(path); !why.empty()) return OutputProblem{path, std::move(why)};
  }
  return std::nullopt;
}

}  // namespace tissue::cli
