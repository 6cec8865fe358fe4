#include "record/record_types.hpp"

#include <algorithm>
#include <cstring>

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

}  // namespace tissue::record
