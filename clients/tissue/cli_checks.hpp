// Option checks the `tissue` subcommands share.
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <optional>
#include <string>

#include "util/lcm_url.hpp"
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
// a udpm:// one needs a multicast group, a port and a ttl in range.
inline CLI::Validator lcm_url() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        if (const std::string why = util::udpm_url_problem(v); !why.empty()) return "'" + v + "': " + why;
        return {};
      },
      "URL");
}

// A frame index: unsigned parsing would wrap "-1" to 18446744073709551615.
inline CLI::Validator frame_index() {
  return CLI::Validator(
      [](std::string& v) {
        return !v.empty() && v.front() == '-' ? v + " is negative: frames are numbered from 0" : std::string();
      },
      "K >= 0");
}

}  // namespace tissue::cli
