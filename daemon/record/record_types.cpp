#include "record/record_types.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <system_error>

namespace tissue::record {

Event Event::make(double time_s, EventKind kind, std::string_view text) noexcept {
  Event e;
  e.time_s = time_s;
  e.kind = kind;
  std::size_t n = std::min(text.size(), kEventMessageBytes - 1);
  // Cut before a UTF-8 continuation byte so the stored text stays valid UTF-8.
  if (n < text.size())
    while (n > 0 && (static_cast<unsigned char>(text[n]) & 0xC0u) == 0x80u) --n;
  std::memcpy(e.message, text.data(), n);
  e.message[n] = '\0';
  return e;
}

namespace {

// "%.9f": session times are the loop's nanosecond ticks in seconds.
std::string seconds_text(double t_s) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.9f", t_s);
  return buffer;
}

// A cursor over an event's text: each step consumes what it expects or fails.
struct Reader {
  std::string_view rest;
  bool literal(std::string_view word) {
    if (rest.substr(0, word.size()) != word) return false;
    rest.remove_prefix(word.size());
    return true;
  }
  bool number(std::uint64_t* out) {
    // from_chars takes no sign for unsigned, so "-5" is refused, not wrapped.
    const auto [end, ec] = std::from_chars(rest.data(), rest.data() + rest.size(), *out);
    if (ec != std::errc() || end == rest.data()) return false;
    rest.remove_prefix(static_cast<std::size_t>(end - rest.data()));
    return true;
  }
  bool seconds(double* out) {
    const auto [end, ec] = std::from_chars(rest.data(), rest.data() + rest.size(), *out, std::chars_format::fixed);
    if (ec != std::errc() || end == rest.data() || !std::isfinite(*out)) return false;
    rest.remove_prefix(static_cast<std::size_t>(end - rest.data()));
    return true;
  }
};

}  // namespace

std::string haptic_hole_message(const HapticHole& hole) {
  std::string text = std::string(kHapticHolePrefix) + std::to_string(hole.ticks_lost) + " ticks ";
  if (hole.has_row_before() && hole.has_row_after())
    return text + "between /haptic rows " + std::to_string(hole.row_after - 1) + " (" +
           seconds_text(hole.time_before_s) + " s) and " + std::to_string(hole.row_after) + " (" +
           seconds_text(hole.time_after_s) + " s)";
  if (hole.has_row_before())
    return text + "after /haptic row " + std::to_string(hole.row_after - 1) + " (" + seconds_text(hole.time_before_s) +
           " s), the last recorded";
  if (hole.has_row_after())
    return text + "before /haptic row " + std::to_string(hole.row_after) + " (" + seconds_text(hole.time_after_s) +
           " s), the first recorded";
  return text + "before any /haptic row was recorded";
}

bool parse_haptic_hole(std::string_view message, HapticHole* hole) {
  Reader r{message};
  HapticHole h;
  if (!r.literal(kHapticHolePrefix) || !r.number(&h.ticks_lost) || h.ticks_lost == 0 || !r.literal(" ticks "))
    return false;
  std::uint64_t before = 0;
  if (r.literal("between /haptic rows ")) {
    // No row follows the largest row number (before + 1 would wrap to 0).
    if (!r.number(&before) || before == UINT64_MAX || !r.literal(" (") || !r.seconds(&h.time_before_s) ||
        !r.literal(" s) and ") || !r.number(&h.row_after) || h.row_after != before + 1 || !r.literal(" (") ||
        !r.seconds(&h.time_after_s) || !r.literal(" s)"))
      return false;
  } else if (r.literal("after /haptic row ")) {
    if (!r.number(&before) || before == UINT64_MAX || !r.literal(" (") || !r.seconds(&h.time_before_s) ||
        !r.literal(" s), the last recorded"))
      return false;
    h.row_after = before + 1;
  } else if (r.literal("before /haptic row ")) {
    if (!r.number(&h.row_after) || h.row_after != 0 || !r.literal(" (") || !r.seconds(&h.time_after_s) ||
        !r.literal(" s), the first recorded"))
      return false;
  } else if (!r.literal("before any /haptic row was recorded")) {
    return false;
  }
  if (!r.rest.empty()) return false;
  *hole = h;
  return true;
}

}  // namespace tissue::record
