// XML text and attribute escaping, shared by the X3D export and the XDMF
// sidecar writer. Header-only: both libraries use it without linking the
// simulation library.
#pragma once

#include <string>
#include <string_view>

namespace tissue::util {

// `s` with & < > ' " replaced by their entities: safe in element text and
// in attributes quoted with either quote.
inline std::string escape_xml(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (const char c : s) {
    switch (c) {
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
      default:
        out += c;
    }
  }
  return out;
}

}  // namespace tissue::util
