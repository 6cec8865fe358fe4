// Whether a name a user gave (a scene's name, a session file's name) is text
// every consumer takes: JSON reports and control replies need valid UTF-8,
// HDF5 event strings are declared UTF-8, and a terminal line or a log must not
// carry escape sequences or line breaks.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace tissue::util {

// One character of UTF-8 text: its code point and how many bytes it takes.
struct Utf8Char {
  std::uint32_t code = 0;
  std::size_t length = 0;
};

// The character that starts at byte `at` of `text`, or nullopt when the
// bytes there are not UTF-8 (a stray continuation byte, a sequence cut
// short, an overlong form, a UTF-16 surrogate, beyond U+10FFFF); then
// *bad_byte (when given) is the byte to blame: the first that does not
// continue the sequence, else `at`. The one UTF-8 reader of the checks
// below and of XML escaping (util/xml.hpp).
std::optional<Utf8Char> decode_utf8(std::string_view text, std::size_t at, std::size_t* bad_byte = nullptr);

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

// The shortest text that reads back as the same double ("0.1", "1e-07",
// "1e+300", not "0.10000000000000001" nor %f's "0.000000" or 301 digits);
// "nan", "inf", "-inf" for the others (a NaN's sign is not shown). The one
// number writer of messages that quote a number as given.
std::string number_text(double v);

}  // namespace tissue::util
