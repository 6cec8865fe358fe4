#include "util/text.hpp"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

namespace tissue::util {

std::string number_text(double v) {
  if (std::isnan(v)) return "nan";
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

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

std::optional<Utf8Char> decode_utf8(std::string_view text, std::size_t at, std::size_t* bad_byte) {
  if (bad_byte != nullptr) *bad_byte = at;
  if (at >= text.size()) return std::nullopt;
  const auto lead = static_cast<unsigned char>(text[at]);
  Utf8Char c;
  if (lead < 0x80) {
    c = {lead, 1};
  } else if (lead >= 0xc2 && lead <= 0xdf) {
    c = {lead & 0x1fu, 2};
  } else if (lead >= 0xe0 && lead <= 0xef) {
    c = {lead & 0x0fu, 3};
  } else if (lead >= 0xf0 && lead <= 0xf4) {
    c = {lead & 0x07u, 4};
  } else {
    return std::nullopt;
  }
  if (at + c.length > text.size()) return std::nullopt;
  for (std::size_t k = 1; k < c.length; ++k) {
    const auto next = static_cast<unsigned char>(text[at + k]);
    if ((next & 0xc0u) != 0x80u) {
      if (bad_byte != nullptr) *bad_byte = at + k;
      return std::nullopt;
    }
    c.code = (c.code << 6) | (next & 0x3fu);
  }
  // Overlong forms, UTF-16 surrogates and code points beyond U+10FFFF.
  if ((c.length == 3 && c.code < 0x800) || (c.length == 4 && (c.code < 0x10000 || c.code > 0x10ffff)) ||
      (c.code >= 0xd800 && c.code <= 0xdfff))
    return std::nullopt;
  return c;
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
    std::size_t bad = i;
    const std::optional<Utf8Char> c = decode_utf8(text, i, &bad);
    if (!c) return byte_error(bad);
    ++character;
    if (c->code < 0x20 || (c->code >= 0x7f && c->code <= 0x9f) || c->code == 0x2028 || c->code == 0x2029) {
      char buf[80];
      std::snprintf(buf, sizeof buf, "character %zu is a control character (U+%04X)", character,
                    static_cast<unsigned>(c->code));
      return buf;
    }
    i += c->length;
  }
  return {};
}

}  // namespace tissue::util
