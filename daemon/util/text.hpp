// Whether a name a user gave (a scene's name, a session file's name) is text
// every consumer takes: JSON reports and control replies need valid UTF-8,
// HDF5 event strings are declared UTF-8, and a terminal line or a log must not
// carry escape sequences or line breaks.
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace tissue::util {

// "" when `text` is valid UTF-8 (no overlong forms, no surrogates, nothing
// above U+10FFFF) with no control character (C0, DEL, C1) nor line or
// paragraph separator (U+2028, U+2029); else why not, e.g. "byte 3 (0xff) is
// not UTF-8" or "character 5 is a control character (U+001B)".
std::string why_not_clean_text(std::string_view text);

// The whole of `text` as a number, or nullopt: "20abc", "", " 1" and "1 "
// are not numbers; "nan" and "inf" are (the caller refuses non-finite values
// with its own words). The one number reader of the command lines (tissued,
// tissue, tissue trade): locale-independent (std::from_chars).
std::optional<double> whole_number(std::string_view text);

}  // namespace tissue::util
