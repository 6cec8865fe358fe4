#include "util/xml.hpp"

#include <optional>

#include "util/text.hpp"

namespace tissue::util {

std::string escape_xml(std::string_view s) {
  constexpr std::string_view kReplacement = "\xef\xbf\xbd";  // U+FFFD
  std::string out;
  out.reserve(s.size());
  for (std::size_t i = 0; i < s.size();) {
    const std::optional<Utf8Char> c = decode_utf8(s, i);
    if (!c) {
      out += kReplacement;
      ++i;
      continue;
    }
    switch (c->code) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '\'':
        out += "&apos;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\t':
        out += "&#9;";
        break;
      case '\n':
        out += "&#10;";
        break;
      case '\r':
        out += "&#13;";
        break;
      default:
        if (c->code < 0x20 || c->code == 0xfffe || c->code == 0xffff)
          out += kReplacement;
        else
          out.append(s.substr(i, c->length));
    }
    i += c->length;
  }
  return out;
}

}  // namespace tissue::util
