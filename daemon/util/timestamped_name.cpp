#include "util/timestamped_name.hpp"

#include <algorithm>
#include <charconv>
#include <filesystem>
#include <system_error>

namespace tissue::util {
namespace {

constexpr std::size_t kTimeChars = 15;  // YYYYmmdd-HHMMSS
constexpr int kMaxSuffix = 1000;        // past it the name is taken as is: create says "already exists"

bool all_digits(std::string_view s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

}  // namespace

std::string free_timestamped_name(const std::string& dir, std::string_view prefix, std::string_view extension,
                                  std::time_t now) {
  std::tm utc{};
  gmtime_r(&now, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", &utc);
  std::string stem(prefix);
  stem += stamp;
  std::string name = stem;
  name += extension;
  std::error_code ec;
  for (int k = 2; k < kMaxSuffix && std::filesystem::exists(std::filesystem::path(dir) / name, ec); ++k) {
    name = stem;
    name += '-';
    name += std::to_string(k);
    name += extension;
  }
  return name;
}

std::optional<NameStamp> read_name_stamp(std::string_view stem) {
  if (stem.size() < kTimeChars || stem[8] != '-' || !all_digits(stem.substr(0, 8)) || !all_digits(stem.substr(9, 6)))
    return std::nullopt;
  NameStamp out{std::string(stem.substr(0, kTimeChars)), 1};
  if (stem.size() == kTimeChars) return out;
  const std::string_view suffix = stem.substr(kTimeChars + 1);
  // "-K" with K in [2, kMaxSuffix) written plainly: what the maker writes and
  // nothing else ("-0", "-1", "-02" are a client's names).
  if (stem[kTimeChars] != '-' || !all_digits(suffix) || suffix.size() > 3 || suffix[0] == '0') return std::nullopt;
  std::from_chars(suffix.data(), suffix.data() + suffix.size(), out.k);
  if (out.k < 2) return std::nullopt;
  return out;
}

}  // namespace tissue::util
