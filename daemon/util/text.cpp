#include "util/text.hpp"

#include <charconv>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

namespace tissue::util {

std::optional<double> whole_number(std::string_view text) {
  double v = 0.0;
  const char* end = text.data() + text.size();
  // from_chars takes no '+'; people type one: allow it (not "+-5").
  const char* begin = !text.empty() && text.front() == '+' ? text.data() + 1 : text.data();
  if (begin == end || (begin != text.data() && *begin == '-')) return std::nullopt;
  const auto r = std::from_chars(begin, end, v);
  if (r.ptr != end) return std::nullopt;
  // Out of range (1e999, 1e-999): a number all the same, as strtod reads it
  // (±inf, or 0 / subnormal), so "1e999" is refused as not finite.
  if (r.ec == std::errc::result_out_of_range) return std::strtod(std::string(begin, end).c_str(), nullptr);
  if (r.ec != std::errc()) return std::nullopt;
  return v;
}

std::string why_not_clean_text(std::string_view text) {
  const auto byte_error = [&](std::size_t at) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "byte %zu (0x%02x) is not UTF-8", at + 1,
                  static_cast<unsigned>(static_cast<unsigned char>(text[at])));
    return std::string(buf);
  };
  std::size_t character = 0;
  for (std::size_t i = 0; i < text.size();) {
    const auto lead = static_cast<unsigned char>(text[i]);
    std::uint32_t code = 0;
    std::size_t length = 0;
    if (lead < 0x80) {
      code = lead;
      length = 1;
    } else if (lead >= 0xc2 && lead <= 0xdf) {
      code = lead & 0x1fu;
      length = 2;
    } else if (lead >= 0xe0 && lead <= 0xef) {
      code = lead & 0x0fu;
      length = 3;
    } else if (lead >= 0xf0 && lead <= 0xf4) {
      code = lead & 0x07u;
      length = 4;
    } else {
      return byte_error(i);
    }
    if (i + length > text.size()) return byte_error(i);
    for (std::size_t k = 1; k < length; ++k) {
      const auto next = static_cast<unsigned char>(text[i + k]);
      if ((next & 0xc0u) != 0x80u) return byte_error(i + k);
      code = (code << 6) | (next & 0x3fu);
    }
    // Overlong forms, UTF-16 surrogates and code points beyond U+10FFFF.
    if ((length == 3 && code < 0x800) || (length == 4 && (code < 0x10000 || code > 0x10ffff)) ||
        (code >= 0xd800 && code <= 0xdfff))
      return byte_error(i);
    ++character;
    if (code < 0x20 || (code >= 0x7f && code <= 0x9f) || code == 0x2028 || code == 0x2029) {
      char buf[80];
      std::snprintf(buf, sizeof buf, "character %zu is a control character (U+%04X)", character,
                    static_cast<unsigned>(code));
      return buf;
    }
    i += length;
  }
  return {};
}

}  // namespace tissue::util
