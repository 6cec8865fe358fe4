#pragma once
// File names the daemon makes up when a command gives none (record_start,
// export_x3d, the automatic recordings): PREFIX + YYYYmmdd-HHMMSS (UTC)
// [+ "-K"] + EXTENSION. The maker and the reader of that format live together
// here so that they cannot drift apart: the service's recording budget
// (record.keep_gb) removes the oldest automatic files by reading back the
// time and K that the maker wrote.
#include <ctime>
#include <optional>
#include <string>
#include <string_view>

namespace tissue::util {

// PREFIX + the UTC time `now` as YYYYmmdd-HHMMSS + EXTENSION, or with "-2",
// "-3", ... before the extension while a file of that name is in `dir`: two
// nameless requests within one second must not fail with "already exists" on
// a name the user never gave.
std::string free_timestamped_name(const std::string& dir, std::string_view prefix, std::string_view extension,
                                  std::time_t now);

// What free_timestamped_name put between the prefix and the extension.
struct NameStamp {
  std::string time;  // "YYYYmmdd-HHMMSS"
  long k = 1;        // the "-K" suffix; 1 when there is none
};

// Reads `stem` (a name without its prefix and extension) as
// "YYYYmmdd-HHMMSS[-K]"; nullopt when it is not of that form.
std::optional<NameStamp> read_name_stamp(std::string_view stem);

}  // namespace tissue::util
