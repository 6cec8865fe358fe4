#include "util/text.hpp"

#include <cstdint>
#include <cstdio>

namespace tissue::util {

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
